#include "stereo_input.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"

namespace cloudcast::ros_bridge {
namespace {

absl::Status Invalid(const std::string& message) { return absl::InvalidArgumentError(message); }

// Equal up to the rounding of a calibration file's decimal digits.
bool Same(double a, double b) { return std::fabs(a - b) <= 1e-9 * std::max(1.0, std::fabs(a)); }

}  // namespace

absl::StatusOr<CameraModel> CameraFromStereo(const sensor_msgs::CameraInfo& left_info,
                                             const sensor_msgs::CameraInfo& right_info,
                                             std::uint32_t width, std::uint32_t height) {
  auto left = PinholeFromInfo(left_info, kLeftInfoTopic, width, height, kLeftTopic);
  if (!left.ok()) return left.status();
  auto right = PinholeFromInfo(right_info, kRightInfoTopic, width, height, kRightTopic);
  if (!right.ok()) return right.status();
  const std::pair<const char*, std::pair<double, double>> members[] = {
      {"fx", {left->fx, right->fx}},
      {"fy", {left->fy, right->fy}},
      {"cx", {left->cx, right->cx}},
      {"cy", {left->cy, right->cy}}};
  for (const auto& [name, values] : members) {
    if (!Same(values.first, values.second)) {
      return Invalid(
          absl::StrCat(kRightInfoTopic, ".P has ", name, " = ", values.second, " but ",
                       kLeftInfoTopic, ".P has ", values.first,
                       "; the server matches rectified pairs whose cameras share fx, fy, cx and cy "
                       "(stereoRectify with CALIB_ZERO_DISPARITY)"));
    }
  }
  const double tx = right_info.P[3];
  const double baseline = -tx / right->fx;
  if (!(std::isfinite(baseline) && baseline > 0)) {
    return Invalid(absl::StrCat(kRightInfoTopic, ".P[3] (Tx = -fx * baseline) is ", tx,
                                "; must be finite and < 0 (the right camera of the pair)"));
  }
  CameraModel camera;
  camera.fx = left->fx;
  camera.fy = left->fy;
  camera.cx = left->cx;
  camera.cy = left->cy;
  camera.baseline = baseline;
  // The server's matcher gives 1/16 pixels with 0 as no match; the camera's own disparity
  // members do not apply to stereo pairs (proto: "Stereo pairs").
  camera.invalid_disparities = {};
  if (absl::Status s = camera.Validate("stereo camera"); !s.ok()) return s;
  return camera;
}

absl::Status ToStereoFrame(const sensor_msgs::Image& left, const sensor_msgs::Image& right,
                           const sensor_msgs::CameraInfo& left_info,
                           const sensor_msgs::CameraInfo& right_info, OutgoingFrame* frame) {
  if (absl::Status s = CheckSameSize(left, kLeftTopic, right, kRightTopic); !s.ok()) return s;
  auto camera = CameraFromStereo(left_info, right_info, left.width, left.height);
  if (!camera.ok()) return camera.status();
  auto left_view = ColourFromImage(left, kLeftTopic);
  if (!left_view.ok()) return left_view.status();
  auto right_view = ColourFromImage(right, kRightTopic);
  if (!right_view.ok()) return right_view.status();
  frame->camera = *std::move(camera);
  frame->images = client::StereoFrame{*left_view, *right_view};
  frame->header = left.header;
  return absl::OkStatus();
}

StereoInput::StereoInput(ros::NodeHandle& nh, const SyncOptions& sync, Sink sink,
                         ErrorSink error_sink)
    : sink_(std::move(sink)),
      error_sink_(std::move(error_sink)),
      sync_(nh, {kLeftTopic, kRightTopic, kLeftInfoTopic, kRightInfoTopic}, sync,
            [this](const auto& l, const auto& r, const auto& li, const auto& ri) {
              OnMessages(l, r, li, ri);
            }) {}

void StereoInput::OnMessages(const sensor_msgs::Image::ConstPtr& left,
                             const sensor_msgs::Image::ConstPtr& right,
                             const sensor_msgs::CameraInfo::ConstPtr& left_info,
                             const sensor_msgs::CameraInfo::ConstPtr& right_info) {
  OutgoingFrame frame;
  if (absl::Status s = ToStereoFrame(*left, *right, *left_info, *right_info, &frame); !s.ok()) {
    error_sink_(s);
    return;
  }
  sink_(frame);
}

}  // namespace cloudcast::ros_bridge
