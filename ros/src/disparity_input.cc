#include "disparity_input.h"

#include <sensor_msgs/image_encodings.h>

#include <cmath>
#include <cstring>
#include <limits>

#include "absl/strings/str_cat.h"
#include "image_messages.h"

namespace cloudcast::ros_bridge {
namespace {

namespace enc = sensor_msgs::image_encodings;

absl::Status Invalid(const std::string& message) { return absl::InvalidArgumentError(message); }

bool FinitePositive(double v) { return std::isfinite(v) && v > 0; }

}  // namespace

absl::StatusOr<CameraModel> CameraFromDisparity(const stereo_msgs::DisparityImage& disparity,
                                                const sensor_msgs::CameraInfo& info) {
  if (!FinitePositive(disparity.f)) {
    return Invalid(absl::StrCat("disparity.f is ", disparity.f, "; must be finite and > 0"));
  }
  if (!FinitePositive(disparity.T)) {
    return Invalid(absl::StrCat("disparity.T is ", disparity.T,
                                "; must be finite and > 0 (the stereo baseline)"));
  }
  const sensor_msgs::Image& image = disparity.image;
  auto pinhole =
      PinholeFromInfo(info, "left/camera_info", image.width, image.height, "disparity.image");
  if (!pinhole.ok()) return pinhole.status();
  CameraModel camera;
  camera.fx = pinhole->fx;
  camera.fy = pinhole->fy;
  camera.cx = pinhole->cx;
  camera.cy = pinhole->cy;
  // z = fx * baseline / d must be the message's f T / d (f is the right camera's fx in
  // stereo_image_proc, equal to the left one's after rectification, but not necessarily).
  camera.baseline = static_cast<double>(disparity.f) * disparity.T / camera.fx;
  camera.disparity_scale = 1.0;
  camera.disparity_offset = 0.0;
  camera.invalid_disparities = {};  // MaskedDisparity has made them NaN
  if (absl::Status s = camera.Validate("disparity camera"); !s.ok()) return s;
  return camera;
}

absl::StatusOr<DisparityView> MaskedDisparity(const stereo_msgs::DisparityImage& disparity,
                                              std::vector<float>* buffer) {
  const sensor_msgs::Image& image = disparity.image;
  if (image.encoding != enc::TYPE_32FC1) {
    return Invalid(absl::StrCat("disparity.image.encoding is '", image.encoding,
                                "'; must be 32FC1 (stereo_msgs/DisparityImage)"));
  }
  if (image.is_bigendian) {
    return Invalid("disparity.image.is_bigendian is 1; the bridge takes little-endian floats");
  }
  if (absl::Status s = CheckLayout(image, sizeof(float), "disparity.image"); !s.ok()) return s;
  if (std::isnan(disparity.min_disparity)) {
    return Invalid("disparity.min_disparity is nan; must be a number (or -inf for no bound)");
  }
  const std::size_t w = image.width, h = image.height;
  buffer->resize(w * h);
  const float min = disparity.min_disparity;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float max_finite = std::numeric_limits<float>::max();
  for (std::size_t v = 0; v < h; ++v) {
    float* row = buffer->data() + v * w;
    // The rows of a ROS message need not be 4-byte aligned: copied, then tested in place.
    std::memcpy(row, image.data.data() + v * image.step, w * sizeof(float));
    for (std::size_t u = 0; u < w; ++u) {
      const float d = row[u];
      row[u] = (d >= min && d <= max_finite) ? d : nan;  // NaN fails both tests
    }
  }
  DisparityView view;
  view.data = buffer->data();
  view.size_bytes = w * h * sizeof(float);
  view.width = image.width;
  view.height = image.height;
  view.stride_bytes = w * sizeof(float);
  view.encoding = DisparityEncoding::kF32;
  return view;
}

absl::Status ToFrame(const stereo_msgs::DisparityImage& disparity, const sensor_msgs::Image& colour,
                     const sensor_msgs::CameraInfo& info, std::vector<float>* buffer,
                     OutgoingFrame* frame) {
  auto camera = CameraFromDisparity(disparity, info);
  if (!camera.ok()) return camera.status();
  auto masked = MaskedDisparity(disparity, buffer);
  if (!masked.ok()) return masked.status();
  if (absl::Status s =
          CheckSameSize(disparity.image, "disparity.image", colour, "left/image_rect_color");
      !s.ok()) {
    return s;
  }
  auto view = ColourFromImage(colour, "left/image_rect_color");
  if (!view.ok()) return view.status();
  frame->camera = *std::move(camera);
  frame->images = client::DisparityFrame{*masked, *view};
  frame->header = disparity.header;
  return absl::OkStatus();
}

DisparityInput::DisparityInput(ros::NodeHandle& nh, const SyncOptions& sync, Sink sink,
                               ErrorSink error_sink)
    : sink_(std::move(sink)),
      error_sink_(std::move(error_sink)),
      sync_(nh, {"disparity", "left/image_rect_color", "left/camera_info"}, sync,
            [this](const auto& d, const auto& c, const auto& i) { OnMessages(d, c, i); }) {}

void DisparityInput::OnMessages(const stereo_msgs::DisparityImage::ConstPtr& disparity,
                                const sensor_msgs::Image::ConstPtr& colour,
                                const sensor_msgs::CameraInfo::ConstPtr& info) {
  OutgoingFrame frame;
  if (absl::Status s = ToFrame(*disparity, *colour, *info, &masked_, &frame); !s.ok()) {
    error_sink_(s);
    return;
  }
  sink_(frame);
}

}  // namespace cloudcast::ros_bridge
