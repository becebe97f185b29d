// Our packed 8-bit images (BGR8, RGB8, RGBA8, Mono8) to a video picture's planar YUV and back:
// what the encoders do before coding a colour image and the decoders after.
//
// The decoders' way (YUV to packed RGB) is libyuv's. swscale has SIMD only from 4:2:0: its 4:4:4
// path took 0.7 ms a 640x480 picture on this machine (4 ms on noise) against libyuv's 0.08, a
// third of what decoding a 4:4:4 colour picture cost in all, and it wraps some out-of-gamut blues
// (a bright luma with the most blue chroma, which lossy coding makes at saturated edges) to 0.
// The encoders' way to 4:2:0 is libyuv's too, 0.05 ms against 0.4, and closer to the image: a
// New Tsukuba frame to 4:2:0 and back keeps 44.5 to 48 dB where swscale's kept 39 to 40 (its
// chroma downsampling and upsampling do not invert each other). To 4:4:4 it is ours: libyuv
// splits each row into planes and an SSE2 loop (elsewhere a plain one the compiler vectorizes)
// converts them with 15-bit fractions, the exact colours (swscale's result within a level) in
// 0.38 of swscale's time (0.44 against 1.17 ms a 640x480 picture on a slow x86-64 host, where
// swscale's was a fifth of a 4:4:4 encode); libyuv's own
// 4:4:4 conversion has 8-bit coefficients (48.8 dB there and back against 53), a quarter of a
// decibel off a picture coded at 38 dB. All BT.601, limited range, as
// swscale's defaults (and the pictures coded before) were; a full-range ('yuvj') picture decodes
// as such. video_yuv_test checks every path against the exact colours and swscale.
#pragma once

#include <cstdint>
#include <vector>

#include "absl/status/status.h"
#include "cloudcast/core/image.h"

namespace cloudcast::video::internal {

// A planar picture's three planes (a grey picture: y only).
struct YuvPlanes {
  enum class Layout : std::uint8_t { kGrey, k420, k444 };
  Layout layout = Layout::k420;
  // 'yuvj' (JPEG's levels); grey is always full range, as swscale reads it.
  bool full_range = false;
  std::uint8_t* y = nullptr;
  std::uint8_t* u = nullptr;
  std::uint8_t* v = nullptr;
  int y_stride = 0, u_stride = 0, v_stride = 0;
};

// Packed images (BGR8, RGB8, RGBA8 or Mono8) into limited-range 4:2:0 or 4:4:4 pictures: one per
// encoder, which keeps its scratch rows between pictures.
class PackedToYuv {
 public:
  PackedToYuv() = default;
  PackedToYuv(const PackedToYuv&) = delete;
  PackedToYuv& operator=(const PackedToYuv&) = delete;
  ~PackedToYuv() = default;

  absl::Status Convert(const std::uint8_t* src, int src_stride, ColorEncoding from, int width,
                       int height, const YuvPlanes& dst);

 private:
  // A row's planes (to 4:4:4), or the whole image as libyuv's ARGB (grey to 4:2:0).
  std::vector<std::uint8_t> scratch_;
};

// A decoded picture (grey, 4:2:0 or 4:4:4) into a packed image (`to`: BGR8, RGB8, RGBA8 with
// alpha 255, or Mono8: the luma as it is).
absl::Status YuvToPacked(const YuvPlanes& src, int width, int height, ColorEncoding to,
                         std::uint8_t* dst, int dst_stride);

}  // namespace cloudcast::video::internal
