// The robot's side of the video uplink: 8-bit images (grey or colour) in, one H.264 access unit
// (Annex B) out per image, at once. libavcodec with libx264, set up for latency rather than for
// bytes: tune zerolatency (no B-frames, no lookahead, no frame threads), a VBV of one frame
// (bitrate / fps) so that no frame waits behind a large one, sliced threads or one thread, an IDR
// every keyframe_interval frames or periodic intra refresh, an IDR whenever the caller asks (a
// late joiner, a decode error on the server), and a bitrate the caller may change every frame
// (a rate controller following the link).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/limits.h"

namespace cloudcast::video {

// What a stream's pictures are: grey is coded as luma only (H.264 4:0:0, no chroma bits: what the
// stereo matchers read); colour as 4:2:0 (BT.601, limited range), or 4:4:4 where colour detail
// matters more than bytes (High 4:4:4 Predictive: 4:2:0 alone caps the synthetic scene's colour at
// 28 dB PSNR and New Tsukuba's at 39 dB, before any coding; docs/video.md).
enum class PictureKind : std::uint8_t { kGrey, kColour, kColour444 };
std::string_view Name(PictureKind kind);  // "grey", "colour", "colour444"

struct EncoderOptions {
  PictureKind kind = PictureKind::kColour;
  std::uint32_t width = 0;  // even, within limits
  std::uint32_t height = 0;
  // x264's speed/size trade: ultrafast, superfast, veryfast, faster, fast, medium, ...
  // docs/video.md measures which one a robot core affords (ultrafast drops CABAC and deblocking).
  std::string preset = "veryfast";
  // Rate control, one of:
  //   qp >= 0          a constant quantiser (0: lossless);
  //   crf > 0          constant quality (x264's CRF, 1..51), capped by bitrate_bps when it is > 0;
  //   otherwise        bitrate_bps, which must then be > 0.
  int qp = -1;
  double crf = 0;
  // Bits per second; the VBV holds one frame of it (bitrate / fps), so a frame never waits for
  // the ones before it to drain. Changeable per frame (FrameControl).
  std::int64_t bitrate_bps = 4'000'000;
  int fps = 30;
  // Frames between IDRs (0: only the first, and those asked for).
  int keyframe_interval = 60;
  // Periodic intra refresh (a moving column of intra blocks) instead of periodic IDRs: no frame
  // is much larger than the others. The server still needs an IDR to start: ask for one.
  bool intra_refresh = false;
  // 1: one thread. More: x264's sliced threads (one slice per thread; no added latency).
  int threads = 1;
  // More x264 options, "key=value:key=value", after ours (e.g. "aq-mode=3:aq-strength=1.5":
  // adaptive quantisation gives flat regions, whose small gradients the matchers' census costs
  // read, more bits; docs/video.md measures it).
  std::string x264_params;
  // Reference frames (0: the preset's). Two lets an interleaved stereo stream (L, R, L, R, ...)
  // predict each view from the other and from itself one pair ago.
  int refs = 0;
  Limits limits;
};

// Per frame: what the caller changes.
struct FrameControl {
  bool keyframe = false;         // this frame is an IDR (with SPS and PPS before it)
  std::int64_t bitrate_bps = 0;  // > 0: the new bitrate (and VBV) from this frame on
};

// One access unit: the Annex B bytes of one picture, SPS and PPS first when it is an IDR.
struct EncodedPicture {
  std::string bytes;
  bool keyframe = false;
  std::int64_t index = 0;  // the picture's number in the stream, from 0
};

// One per stream and role. Not thread-safe.
class Encoder {
 public:
  // Checks the options (errors name "options.<member>") and opens libx264.
  static absl::StatusOr<std::unique_ptr<Encoder>> Make(const EncoderOptions& options);
  ~Encoder();
  Encoder(const Encoder&) = delete;
  Encoder& operator=(const Encoder&) = delete;

  // Encodes `image` (grey: kMono8; colour: kBGR8, kRGB8, kRGBA8 or kMono8; the stream's size)
  // into `out` (its buffer is reused). Errors name `field`.
  absl::Status Encode(const ColorView& image, const FrameControl& control, std::string_view field,
                      EncodedPicture* out);

  const EncoderOptions& options() const;

 private:
  struct Impl;
  explicit Encoder(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace cloudcast::video
