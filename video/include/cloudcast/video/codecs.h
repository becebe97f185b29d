// The video codecs measured against the uplink's H.264 (issue 27: "HEVC, AV1 or VP9 where measured
// better"), each through libavcodec at low-latency settings comparable to video::Encoder's x264:
// one thread, no lookahead, no B-frames, one picture in and its bytes out at once.
//
//   codec  encoder      preset (what it means)            rate: crf scale    decoder
//   h264   libx264      x264 preset (ultrafast...)        crf 1..51, qp 0    h264 (libavcodec's)
//   hevc   libx265      x265 preset, tune zerolatency     crf 1..51, lossless hevc (libavcodec's)
//   vp9    libvpx-vp9   cpu-used 5..8, deadline realtime  crf 1..63, lossless vp9  (libavcodec's)
//   av1    libaom-av1   cpu-used 7..10, usage realtime    crf 1..63          libdav1d
//
// For measurement (cloudcast-video-bench) and tests only: the contract carries H.264, and the
// server decodes with video::Decoder (H.264, its bitstream checked and charged before libavcodec
// sees it), which this does not change. A CodecStream's decoder has none of those checks; it
// must not decode what a client sent.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/core/image.h"
#include "cloudcast/video/encoder.h"

namespace cloudcast::video {

enum class Codec : std::uint8_t { kH264, kHevc, kVp9, kAv1 };

struct CodecInfo {
  Codec codec;
  const char* key;          // "h264", "hevc", "vp9", "av1"
  const char* label;        // "H.264", "HEVC", "VP9", "AV1"
  const char* encoder;      // libavcodec's name of the encoder
  const char* decoder;      // and of the decoder
  const char* preset_rule;  // what EncoderOptions::preset means for it
  double max_crf;           // EncoderOptions::crf in (0, max_crf]
  bool lossless;            // has a lossless mode (EncoderOptions::qp = 0)
  bool grey;                // codes grey as 4:0:0; otherwise as 4:2:0 with flat (128) chroma
  bool colour444;           // codes PictureKind::kColour444
};

// Every codec, H.264 first.
const std::vector<CodecInfo>& Codecs();
// nullptr when `key` names none.
const CodecInfo* FindCodec(std::string_view key);
const CodecInfo& Info(Codec codec);
// Whether this libavcodec has the codec's encoder and decoder (Debian 12's FFmpeg 5.1 has all).
bool Available(Codec codec);

// One stream's encoder and its decoder, kept across pictures. The options are video::Encoder's
// (kind, size, preset, qp / crf / bitrate_bps with a one-frame VBV, fps, keyframe_interval,
// threads, refs; x264_params and intra_refresh are H.264's only). H.264 is video::Encoder and
// video::Decoder as they are. Not thread-safe.
class CodecStream {
 public:
  // Checks the options against the codec (errors name "options.<member>") and opens both sides;
  // FAILED_PRECONDITION when this libavcodec lacks the encoder or the decoder. `decoded` is what
  // Decode writes: kMono8 (the luma plane), kBGR8 or kRGB8.
  static absl::StatusOr<std::unique_ptr<CodecStream>> Open(Codec codec,
                                                           const EncoderOptions& options,
                                                           ColorEncoding decoded);
  virtual ~CodecStream() = default;

  // One picture (the stream's size; grey: kMono8; colour: kBGR8, kRGB8, kRGBA8 or kMono8) to
  // its bytes, at once: an encoder that holds a picture back is an error. Errors name `field`.
  virtual absl::Status Encode(const ColorView& image, std::string_view field,
                              std::string* bytes) = 0;
  // Those bytes back to one picture; `out` points into the stream's buffer until the next call.
  virtual absl::Status Decode(std::string_view bytes, std::string_view field, ColorView* out) = 0;

  // What the encoder is (e.g. "libx265 ultrafast").
  virtual std::string Describe() const = 0;
};

}  // namespace cloudcast::video
