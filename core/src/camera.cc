#include "cloudcast/core/camera.h"

#include <cmath>
#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "cloudcast/core/checks.h"

namespace cloudcast {

CameraModel CameraModel::PclCompatible(std::uint32_t width, std::uint32_t height, double focal) {
  CameraModel c;
  c.fx = c.fy = focal;
  // PCL: centerX = static_cast<int>(width / 2), pixel x coordinate = column - centerX.
  c.cx = static_cast<double>(width / 2);
  c.cy = static_cast<double>(height / 2);
  c.baseline = 1.0;
  c.disparity_scale = 1.0;
  c.disparity_offset = 0.0;
  c.invalid_disparities = {0.0, 2047.0};
  return c;
}

absl::Status CameraModel::Validate(std::string_view field) const {
  const std::string f(field);
  for (absl::Status s : {check::Positive(f + ".fx", fx), check::Positive(f + ".fy", fy),
                         check::Finite(f + ".cx", cx), check::Finite(f + ".cy", cy),
                         check::Positive(f + ".baseline", baseline),
                         check::NonZero(f + ".disparity_scale", disparity_scale),
                         check::Finite(f + ".disparity_offset", disparity_offset),
                         check::AtMost(f + ".invalid_disparities", invalid_disparities.size(),
                                       kMaxInvalidDisparities)}) {
    if (!s.ok()) return s;
  }
  if (depth_scale.has_value()) {
    if (auto s = check::Positive(f + ".depth_scale", *depth_scale); !s.ok()) return s;
  }
  for (std::size_t i = 0; i < invalid_disparities.size(); ++i) {
    if (!std::isfinite(invalid_disparities[i])) {
      return absl::InvalidArgumentError(absl::StrCat(
          f, ".invalid_disparities must be finite; value ", i, " is ", invalid_disparities[i]));
    }
  }
  return absl::OkStatus();
}

double CameraModel::DepthScale(DepthEncoding encoding) const {
  if (depth_scale.has_value()) return *depth_scale;
  // REP 118: 16UC1 in millimetres, 32FC1 in metres. depth_image_proc's DepthTraits<uint16_t>
  // converts with 0.001f, a float: the same value as float(0.001).
  return encoding == DepthEncoding::kU16 ? 0.001 : 1.0;
}

std::string CameraModel::ToString() const {
  return absl::StrCat("fx=", fx, " fy=", fy, " cx=", cx, " cy=", cy, " baseline=", baseline,
                      " disparity_scale=", disparity_scale, " disparity_offset=", disparity_offset,
                      " invalid={", absl::StrJoin(invalid_disparities, ","), "}",
                      depth_scale ? absl::StrCat(" depth_scale=", *depth_scale) : "");
}

}  // namespace cloudcast
