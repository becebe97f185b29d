// Half resolution: the floor of a rate-controlled sender (AdaptiveJpegCoder, cloudcast-load's
// ladder). When the link cannot carry even the lowest-quality frame at the camera's resolution
// (a lossless 640x480 disparity map alone is about 14 KB), the frame goes at half its width and
// height: a quarter of the pixels, much the same cloud after the server's voxel grid.
//
// Pixel (u, v) of the half frame is pixel (2u, 2v) of the full one. Disparity and depth take
// every second pixel of every second row, their values unchanged: they are measurements, and
// averaging two surfaces' values would make points between them. Colour is averaged over each
// 2x2 block. The frame then carries its own camera (Frame.camera), HalfResolutionCamera of the
// stream's, so each point keeps its place and depth. One place for both, here; no OpenCV.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "absl/status/status.h"
#include "cloudcast/client/frame.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace cloudcast::client {

// The stream's camera (as its StreamConfig sends it) for frames at half resolution: the focal
// lengths halve, and so does a principal point that is set (unset, it is the image's centre
// either way). With `disparity` so does a disparity in pixels, d' = d * scale + offset: the scale
// (1 when unset) and an offset that is set. Other fields (baseline, depth scale) are unset: the
// stream's apply.
v1::CameraModel HalfResolutionCamera(const v1::CameraModel& stream, bool disparity);

// The half image's size: width / 2 by height / 2 (an odd last column or row is left out).
inline std::uint32_t HalfSize(std::uint32_t full) { return full / 2; }

// Every second pixel of every second row of `height` rows of `width` pixels of `pixel_bytes`
// bytes each, into dst (HalfSize(width) x HalfSize(height), rows dst_stride apart).
void SampleHalf(const std::uint8_t* src, std::size_t src_stride, std::uint32_t width,
                std::uint32_t height, std::size_t pixel_bytes, std::uint8_t* dst,
                std::size_t dst_stride);
// The mean of each 2x2 block, channel by channel (8-bit channels, `channels` a pixel), rounded to
// nearest.
void AverageHalf(const std::uint8_t* src, std::size_t src_stride, std::uint32_t width,
                 std::uint32_t height, int channels, std::uint8_t* dst, std::size_t dst_stride);

// A frame's raw images at half resolution, in buffers this object owns (reused from frame to
// frame). Takes disparity and depth frames whose images are raw views (DisparityView, DepthView,
// ColorView); anything else is an InvalidArgument error naming the image. Views with `rows`
// (pieces) are read row by row.
class HalfResolutionFrame {
 public:
  absl::Status Make(const FrameInput& full);
  // Views of the half images (valid until the next Make or the object's end).
  const DisparityView& disparity() const { return disparity_; }
  const DepthView& depth() const { return depth_; }
  const ColorView& colour() const { return colour_; }

 private:
  template <typename View>
  View Sample(const View& full, std::string* buffer);
  ColorView Average(const ColorView& full);

  std::string geometry_, colour_bytes_;
  DisparityView disparity_;
  DepthView depth_;
  ColorView colour_;
};

}  // namespace cloudcast::client
