#include "cloudcast/core/camera.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"

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

absl::Status CameraModel::Validate() const {
  auto positive = [](const char* name, double v) -> absl::Status {
    if (!std::isfinite(v) || v <= 0.0 || v > 1e9) {
      return absl::InvalidArgumentError(
          absl::StrCat("camera.", name, " must be finite and in (0, 1e9], got ", v));
    }
    return absl::OkStatus();
  };
  auto finite = [](const char* name, double v) -> absl::Status {
    if (!std::isfinite(v) || std::fabs(v) > 1e9) {
      return absl::InvalidArgumentError(
          absl::StrCat("camera.", name, " must be finite and within +-1e9, got ", v));
    }
    return absl::OkStatus();
  };
  for (auto s : {positive("fx", fx), positive("fy", fy), positive("baseline", baseline),
                 finite("cx", cx), finite("cy", cy), finite("disparity_offset", disparity_offset),
                 finite("disparity_scale", disparity_scale)}) {
    if (!s.ok()) return s;
  }
  if (disparity_scale == 0.0) {
    return absl::InvalidArgumentError("camera.disparity_scale must not be 0");
  }
  if (invalid_disparities.size() > 16) {
    return absl::InvalidArgumentError(absl::StrCat(
        "camera.invalid_disparities holds ", invalid_disparities.size(), " values; at most 16"));
  }
  for (double v : invalid_disparities) {
    if (!std::isfinite(v)) {
      return absl::InvalidArgumentError("camera.invalid_disparities must be finite");
    }
  }
  return absl::OkStatus();
}

std::string CameraModel::ToString() const {
  return absl::StrCat("fx=", fx, " fy=", fy, " cx=", cx, " cy=", cy, " baseline=", baseline,
                      " disparity_scale=", disparity_scale,
                      " disparity_offset=", disparity_offset, " invalid={",
                      absl::StrJoin(invalid_disparities, ","), "}");
}

}  // namespace cloudcast
