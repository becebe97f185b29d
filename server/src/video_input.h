// The video pictures of a stream's frames (proto VideoPicture), decoded when each frame is read:
// one video::Decoder per bitstream (Frame.color's, and Frame.right's own unless it is interleaved
// into the colour one), kept from frame to frame for the stream's life. Decoding must follow the
// order the client sent the pictures in and must not skip any (the later pictures reference the
// earlier ones), so it happens on the reading path rather than on a worker: in DELIVERY_LATEST a
// frame replaced before a worker took it was still decoded, only its processing is skipped; in
// DELIVERY_ALL frames processed side by side were decoded one after the other.
//
// Memory: each decoder's is charged from its sequence header (video::DecoderMemoryBytes) before
// the decoder is opened for it, through `charge`, and given back through `release` when the
// stream goes. A frame's decoded pictures (kept until its worker is done) are part of the frame's
// own charge (EstimateFrameMemory counts them).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/limits.h"
#include "cloudcast/io/image_io.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace cloudcast::video {
class Decoder;
}

namespace cloudcast::server {

// A frame's decoded pictures, owned (a decoder's output buffer is reused by its next picture).
struct DecodedVideo {
  bool has_colour = false;  // Frame.color was a VideoPicture, decoded into `colour`
  bool has_right = false;
  OwnedColor colour, right;
  // The bitstreams that need an IDR once this frame's pictures were decoded (the reply's
  // keyframe_needed), whether the frame decoded or not.
  std::vector<v1::VideoBitstream> keyframe_needed;
  double decode_seconds = 0;  // wall time decoding this frame's pictures

  void Clear();
  // The views PrepareFrameImages reads (nullptr when the frame has no picture of that role).
  const OwnedColor* colour_picture() const { return has_colour ? &colour : nullptr; }
  const OwnedColor* right_picture() const { return has_right ? &right : nullptr; }
};

// Codecs this server decodes (ServerInfo.video_codecs).
std::vector<v1::VideoCodec> DecodedVideoCodecs();

// One stream's decoders. Not thread-safe: the stream's reads are one at a time.
class VideoDecoders {
 public:
  using Charge = std::function<absl::Status(std::uint64_t bytes)>;
  using Release = std::function<void(std::uint64_t bytes)>;
  // `charge` / `release`: the server's memory budget (see the file comment); unset: not charged.
  VideoDecoders(const Limits& limits, Charge charge, Release release);
  ~VideoDecoders();
  VideoDecoders(const VideoDecoders&) = delete;
  VideoDecoders& operator=(const VideoDecoders&) = delete;

  // Whether `frame` holds a VideoPicture (in color or right): only those need Decode.
  static bool HasVideo(const v1::Frame& frame);

  // Decodes the frame's pictures into `out`, colour (left) first: each bitstream that has a
  // picture in the frame is fed it, even when another's failed, so that one bad picture costs
  // only its own bitstream an IDR. The first error is returned, naming the field
  // ("frame.color.video.access_unit...", "frame.right.video.picture_index"); `out` then holds no
  // picture, but keyframe_needed is always filled.
  absl::Status Decode(const v1::Frame& frame, DecodedVideo* out);

  // The bitstreams that cannot be decoded until an IDR (appended to `out`).
  void KeyframeNeeded(std::vector<v1::VideoBitstream>* out) const;

 private:
  struct Bitstream;
  absl::Status DecodePicture(const v1::VideoPicture& picture, const std::string& field,
                             Bitstream* bitstream, OwnedColor* out);

  const Limits limits_;
  const Charge charge_;
  const Release release_;
  std::unique_ptr<Bitstream> colour_, right_;
};

}  // namespace cloudcast::server
