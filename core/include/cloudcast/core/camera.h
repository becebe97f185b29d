// The one camera model of cloudcast: a rectified stereo pair seen through its left camera, or a
// depth camera.
//
// Disparity maps:
//   denominator d' = d * disparity_scale + disparity_offset     (d: the raw disparity value)
//   z = fx * baseline / d'
//   x = (u - cx) * z / fx          (u: column, computed as ((u - cx) * z) * (1 / fx) in float)
//   y = (v - cy) * z / fy          (v: row)
//
// A pixel is invalid (NaN point) when d is one of `invalid_disparities`, is not finite, or d' <= 0.
// All arithmetic is in float, in the order PCL's OrganizedConversion uses, so the PCL-compatible
// preset reproduces PCL bit for bit.
//
// Depth images (ROS REP 118), with D the raw depth value and s = depth_scale:
//   z = D * float(s)
//   x = ((u - cx) * D) * kx,   y = ((v - cy) * D) * ky,   kx = float(float(s) / fx) (the division
//                                                          in double), ky likewise with fy
// in float, in the order of ROS depth_image_proc (depth_conversions.h), so that the points equal
// its point_cloud_xyzrgb's bit for bit. D = 0, and non-finite D, mean no measurement (for float
// depth, depth_image_proc keeps D = 0 as a point at the camera centre; we drop it, as REP 118
// means no reading there). The invalid_disparities, baseline, scale and offset do not apply.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "cloudcast/core/image.h"

namespace cloudcast {

// Invalid values are tested per pixel, so their number is bounded.
inline constexpr std::size_t kMaxInvalidDisparities = 16;

struct CameraModel {
  double fx = 615.0;  // focal length in pixels, horizontal
  double fy = 615.0;  // focal length in pixels, vertical
  double cx = 320.0;  // principal point, pixels
  double cy = 240.0;
  double baseline = 1.0;          // z unit: z = fx * baseline / d'. 1 reproduces PCL (z = f / d)
  double disparity_scale = 1.0;   // e.g. 1/16 for 16-bit fixed point disparities
  double disparity_offset = 0.0;  // added after scaling
  // Raw disparity values that mean "no measurement". PCL treats 0 and 0x7FF (2047) as invalid.
  std::vector<double> invalid_disparities = {0.0, 2047.0};
  // Depth images: the unit of a raw depth value (metres per unit, or whatever unit the cloud is
  // in). Unset: REP 118's, 0.001 for 16-bit millimetres and 1 for float metres.
  std::optional<double> depth_scale;

  // depth_scale, or REP 118's unit for `encoding`.
  double DepthScale(DepthEncoding encoding) const;

  // PCL's `OrganizedConversion<PointXYZRGBA>::convert`: fy = fx = focal, baseline 1, principal
  // point at (width/2, height/2) in integer division, 0 and 0x7FF invalid.
  static CameraModel PclCompatible(std::uint32_t width, std::uint32_t height, double focal = 615.0);

  // Finite positive focal lengths and baseline, finite principal point, finite non-zero scale,
  // finite offset, finite invalid values (at most kMaxInvalidDisparities of them), a positive
  // depth scale when set. Errors name
  // the member under `field` (e.g. "camera.fx").
  absl::Status Validate(std::string_view field = "camera") const;

  std::string ToString() const;
};

}  // namespace cloudcast
