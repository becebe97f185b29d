// The server's side of the video uplink: one decoder per stream and role (colour or left, right),
// kept across frames, on libavcodec's own H.264 decoder. Before libavcodec sees an access unit
// the decoder parses it (h264_bitstream.h): the sequence header's picture size is checked against
// the limits and the stream's size, and the memory it implies is charged (Options::charge) before
// any decoder exists for it. Every bad input is a per-frame error naming the field; the stream
// goes on:
//   not H.264 Annex B, a bad NAL header, an SPS out of range  INVALID_ARGUMENT;
//   an SPS over the limits, or a charge refused               RESOURCE_EXHAUSTED;
//   a picture before the first IDR, or after an error (its references are gone): refused without
//   decoding, FAILED_PRECONDITION, and needs_keyframe() says to ask the client for an IDR;
//   a new picture size mid-stream                             INVALID_ARGUMENT (new size: new
//                                                             stream);
//   a corrupt or truncated picture (libavcodec's error, or a picture it concealed)
//                                                             INVALID_ARGUMENT, then
//                                                             needs_keyframe.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/limits.h"
#include "cloudcast/video/h264_bitstream.h"

namespace cloudcast::video {

// What a stream of this sequence header costs the decoder at most: its reference pictures plus the
// picture being decoded and the one being output, each padded as libavcodec pads them (32-pixel
// edges, 64-byte aligned rows), its per-macroblock tables, and the converted output image.
std::uint64_t DecoderMemoryBytes(const SequenceHeader& sps, ColorEncoding output);

class Decoder {
 public:
  struct Options {
    Limits limits;
    // What Decode writes: kMono8 (the luma plane as it is: for the matchers), or kBGR8 / kRGB8.
    ColorEncoding output = ColorEncoding::kMono8;
    // The size the stream must have (0: whatever its first sequence header says).
    std::uint32_t width = 0;
    std::uint32_t height = 0;
    // Called with the bytes a new sequence header needs (DecoderMemoryBytes) before the decoder is
    // opened or grown for it; a refusal (its status is returned, e.g. RESOURCE_EXHAUSTED naming a
    // budget) leaves the stream as it was. Unset: nothing is charged.
    std::function<absl::Status(std::uint64_t bytes)> charge;
    // Called once, when the decoder is destroyed, with everything `charge` accepted (if any):
    // the stream's memory goes back to the budget.
    std::function<void(std::uint64_t bytes)> release;
  };

  explicit Decoder(Options options);
  ~Decoder();
  Decoder(const Decoder&) = delete;
  Decoder& operator=(const Decoder&) = delete;

  // Decodes one access unit (one picture) into `out`, which points into a buffer the decoder
  // owns until the next call (packed rows, options.output). Errors name `field`, e.g.
  // "frame.video.left.access_unit".
  absl::Status Decode(std::string_view access_unit, std::string_view field, ColorView* out);

  // True when the next picture must be an IDR: before the first, after a decode error, after
  // RequireKeyframe. The server's reply asks the client for one.
  bool needs_keyframe() const;
  // A gap in the stream (a frame lost or skipped unseen): pictures are refused until an IDR.
  void RequireKeyframe();

  std::uint64_t charged_bytes() const;  // what options.charge has accepted so far
  bool opened() const;                  // whether libavcodec's decoder exists yet
  std::uint32_t width() const;          // the stream's size (0 before its first SPS)
  std::uint32_t height() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace cloudcast::video
