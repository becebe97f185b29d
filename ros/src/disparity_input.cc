#include "disparity_input.h"

#include <sensor_msgs/image_encodings.h>

#include <cmath>
#include <cstring>
#include <limits>

#include "absl/strings/str_cat.h"

namespace cloudcast::ros_bridge {
namespace {

namespace enc = sensor_msgs::image_encodings;

absl::Status Invalid(const std::string& message) { return absl::InvalidArgumentError(message); }

bool FinitePositive(double v) { return std::isfinite(v) && v > 0; }

// Width, height, step and data size of a sensor_msgs/Image of `bytes_per_pixel`.
absl::Status CheckLayout(const sensor_msgs::Image& image, std::size_t bytes_per_pixel,
                         const std::string& field) {
  if (image.width == 0 || image.height == 0) {
    return Invalid(
        absl::StrCat(field, " is ", image.width, "x", image.height, "; must be at least 1x1"));
  }
  const std::size_t row = std::size_t{image.width} * bytes_per_pixel;
  if (image.step < row) {
    return Invalid(absl::StrCat(field, ".step is ", image.step, ", less than width x ",
                                bytes_per_pixel, " = ", row));
  }
  const std::size_t needed = std::size_t{image.step} * (image.height - 1) + row;
  if (image.data.size() < needed) {
    return Invalid(absl::StrCat(field, ".data holds ", image.data.size(), " bytes; ", image.width,
                                "x", image.height, " with step ", image.step, " needs ", needed));
  }
  return absl::OkStatus();
}

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
  const auto& P = info.P;
  if (P[0] == 0 && P[5] == 0) {
    return Invalid("left/camera_info.P is all zero: the camera is not calibrated");
  }
  if (!FinitePositive(P[0]) || !FinitePositive(P[5])) {
    return Invalid(absl::StrCat("left/camera_info.P has fx = ", P[0], ", fy = ", P[5],
                                "; both must be finite and > 0"));
  }
  if (!std::isfinite(P[2]) || !std::isfinite(P[6])) {
    return Invalid(absl::StrCat("left/camera_info.P has cx = ", P[2], ", cy = ", P[6],
                                "; both must be finite"));
  }
  // A binned or cropped CameraInfo describes another pixel grid than the disparity's.
  if (info.binning_x > 1 || info.binning_y > 1 || info.roi.width != 0 || info.roi.height != 0) {
    return Invalid(absl::StrCat("left/camera_info has binning ", info.binning_x, "x",
                                info.binning_y, " and roi ", info.roi.width, "x", info.roi.height,
                                "; binning and regions of interest are not supported"));
  }
  const sensor_msgs::Image& image = disparity.image;
  if (info.width != 0 && (info.width != image.width || info.height != image.height)) {
    return Invalid(absl::StrCat("left/camera_info is ", info.width, "x", info.height,
                                " but disparity.image is ", image.width, "x", image.height,
                                "; they must describe the same pixels"));
  }
  CameraModel camera;
  camera.fx = P[0];
  camera.fy = P[5];
  camera.cx = P[2];
  camera.cy = P[6];
  // z = fx * baseline / d must be the message's f T / d (f is the right camera's fx in
  // stereo_image_proc, equal to the left one's after rectification, but not necessarily).
  camera.baseline = static_cast<double>(disparity.f) * disparity.T / camera.fx;
  camera.disparity_scale = 1.0;
  camera.disparity_offset = 0.0;
  camera.invalid_disparities = {};  // MaskedDisparity has made them NaN
  if (absl::Status s = camera.Validate("disparity camera"); !s.ok()) return s;
  return camera;
}

absl::StatusOr<client::ColorInput> ColourFromImage(const sensor_msgs::Image& image,
                                                   const std::string& topic) {
  ColorEncoding encoding;
  bool bgra = false;
  if (image.encoding == enc::RGB8) {
    encoding = ColorEncoding::kRGB8;
  } else if (image.encoding == enc::BGR8) {
    encoding = ColorEncoding::kBGR8;
  } else if (image.encoding == enc::RGBA8) {
    encoding = ColorEncoding::kRGBA8;
  } else if (image.encoding == enc::MONO8) {
    encoding = ColorEncoding::kMono8;
  } else if (image.encoding == enc::BGRA8) {
    encoding = ColorEncoding::kRGBA8;  // four bytes a pixel, for the layout check only
    bgra = true;
  } else {
    return Invalid(absl::StrCat(topic, ".encoding is '", image.encoding,
                                "'; the bridge takes rgb8, bgr8, rgba8, bgra8 or mono8"));
  }
  if (absl::Status s = CheckLayout(image, BytesPerPixel(encoding), topic); !s.ok()) return s;
  if (bgra) {
    return client::ColorInput(client::BgraView{image.data.data(), image.data.size(), image.width,
                                               image.height, image.step});
  }
  ColorView view;
  view.data = image.data.data();
  view.size_bytes = image.data.size();
  view.width = image.width;
  view.height = image.height;
  view.stride_bytes = image.step;
  view.encoding = encoding;
  return client::ColorInput(view);
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
  if (colour.width != disparity.image.width || colour.height != disparity.image.height) {
    return Invalid(absl::StrCat("left/image_rect_color is ", colour.width, "x", colour.height,
                                " but disparity.image is ", disparity.image.width, "x",
                                disparity.image.height, "; they must be the same size"));
  }
  auto view = ColourFromImage(colour, "left/image_rect_color");
  if (!view.ok()) return view.status();
  frame->camera = *std::move(camera);
  frame->disparity = *masked;
  frame->colour = *view;
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
