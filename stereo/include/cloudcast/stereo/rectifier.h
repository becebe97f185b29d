// Rectification of a calibrated stereo pair: OpenCV's cv::stereoRectify and
// cv::initUndistortRectifyMap, with the maps built once per calibration and cv::remap per frame.
// The matchers need rectified images (matching pixels on the same row); a robot whose images are
// not rectified sends its calibration once per stream.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/stereo.h"
#include "cloudcast/io/image_io.h"

namespace cloudcast::stereo {

// The calibration is core's StereoCalibration (cloudcast/core/stereo.h), which the protocol's
// StreamConfig.stereo.calibration fills.

struct RectifierOptions {
  // cv::stereoRectify's alpha: 0 zooms so that every rectified pixel is a valid one, 1 keeps every
  // source pixel (black borders); -1 is OpenCV's own choice. In [-1, 1] (-1 exactly, or [0, 1]).
  double alpha = 0.0;
  absl::Status Validate(std::string_view field = "rectifier") const;
};

// The rectified left camera, which the disparity map's pixels belong to.
struct RectifiedCamera {
  double fx = 0, fy = 0, cx = 0, cy = 0;
  double baseline = 0;  // |T| after rectification, in T's unit
  // As core's camera model reading the matchers' output (disparity_scale 1/16, invalid {0}).
  CameraModel ToCameraModel() const;
};

// Maps built once per calibration; Rectify then costs two cv::remap calls per frame. Copyable
// (the maps are shared, read-only) and safe to use from several threads at once.
class Rectifier {
 public:
  static absl::StatusOr<Rectifier> Make(const StereoCalibration& calibration,
                                        const RectifierOptions& options = {});

  // Remaps both images (same size as the calibration's, same encoding: grey or colour) into
  // rectified ones (same encoding), bilinear. Errors name "left" or "right".
  absl::Status Rectify(const ColorView& left, const ColorView& right, OwnedColor* left_out,
                       OwnedColor* right_out) const;

  const RectifiedCamera& camera() const { return camera_; }
  std::uint32_t width() const { return width_; }
  std::uint32_t height() const { return height_; }

 private:
  struct Maps;
  Rectifier() = default;
  std::shared_ptr<const Maps> maps_;
  RectifiedCamera camera_;
  std::uint32_t width_ = 0, height_ = 0;
};

}  // namespace cloudcast::stereo
