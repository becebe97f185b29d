#include "frame_conversions.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <utility>

#include "absl/strings/str_cat.h"

namespace cloudcast::ros_bridge {
namespace {

namespace enc = encodings;

absl::Status Invalid(const std::string& message) { return absl::InvalidArgumentError(message); }

bool FinitePositive(double v) { return std::isfinite(v) && v > 0; }

// Equal up to the rounding of a calibration file's decimal digits.
bool Same(double a, double b) { return std::fabs(a - b) <= 1e-9 * std::max(1.0, std::fabs(a)); }

// How every input's conversion ends: the image the points take their colour from is checked to
// be of the size of `geometry` (the disparity, depth or other image of the set) and viewed, then
// the frame gets the camera, the images `make_images` builds around the colour view, and the
// header of the set's first message.
template <typename MakeImages>
absl::Status FinishFrame(CameraModel camera, const ImageMsg& geometry,
                         const std::string& geometry_name, const ImageMsg& colour,
                         const std::string& colour_name, const MessageHeader& header,
                         MakeImages make_images, OutgoingFrame* frame) {
  if (absl::Status s = CheckSameSize(geometry, geometry_name, colour, colour_name); !s.ok()) {
    return s;
  }
  auto view = ColourFromImage(colour, colour_name);
  if (!view.ok()) return view.status();
  frame->camera = std::move(camera);
  frame->images = make_images(*view);
  frame->header = header;
  return absl::OkStatus();
}

}  // namespace

// ---- ~input disparity

absl::StatusOr<CameraModel> CameraFromDisparity(const DisparityImageMsg& disparity,
                                                const CameraInfoMsg& info) {
  if (!FinitePositive(disparity.f)) {
    return Invalid(absl::StrCat("disparity.f is ", disparity.f, "; must be finite and > 0"));
  }
  if (!FinitePositive(disparity.T)) {
    return Invalid(absl::StrCat("disparity.T is ", disparity.T,
                                "; must be finite and > 0 (the stereo baseline)"));
  }
  const ImageMsg& image = disparity.image;
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

absl::StatusOr<DisparityView> MaskedDisparity(const DisparityImageMsg& disparity,
                                              std::vector<float>* buffer) {
  const ImageMsg& image = disparity.image;
  if (image.encoding != enc::k32FC1) {
    return Invalid(absl::StrCat("disparity.image.encoding is '", std::string(image.encoding),
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

absl::Status ToFrame(const DisparityImageMsg& disparity, const ImageMsg& colour,
                     const CameraInfoMsg& info, std::vector<float>* buffer,
                     OutgoingFrame* frame) {
  auto camera = CameraFromDisparity(disparity, info);
  if (!camera.ok()) return camera.status();
  auto masked = MaskedDisparity(disparity, buffer);
  if (!masked.ok()) return masked.status();
  return FinishFrame(
      *std::move(camera), disparity.image, "disparity.image", colour, kDisparityColourTopic,
      disparity.header,
      [&](const client::ColorInput& c) { return client::DisparityFrame{*masked, c}; }, frame);
}

// ---- ~input depth

absl::StatusOr<CameraModel> CameraFromDepth(const ImageMsg& depth,
                                            const CameraInfoMsg& info,
                                            std::optional<double> depth_scale) {
  auto pinhole = PinholeFromInfo(info, kDepthInfoTopic, depth.width, depth.height, kDepthTopic,
                                 IntrinsicsFrom::kPOrK);
  if (!pinhole.ok()) return pinhole.status();
  CameraModel camera;
  camera.fx = pinhole->fx;
  camera.fy = pinhole->fy;
  camera.cx = pinhole->cx;
  camera.cy = pinhole->cy;
  // The disparity members do not apply to depth images; an empty invalid list keeps the stream
  // config free of PCL's disparity values.
  camera.invalid_disparities = {};
  camera.depth_scale = depth_scale;
  if (absl::Status s = camera.Validate("depth camera"); !s.ok()) return s;
  return camera;
}

absl::StatusOr<DepthView> DepthFromImage(const ImageMsg& depth) {
  DepthEncoding encoding;
  if (depth.encoding == enc::k16UC1) {
    encoding = DepthEncoding::kU16;
  } else if (depth.encoding == enc::k32FC1) {
    encoding = DepthEncoding::kF32;
  } else {
    return Invalid(absl::StrCat(kDepthTopic, ".encoding is '", std::string(depth.encoding),
                                "'; must be 16UC1 (millimetres) or 32FC1 (metres), REP 118"));
  }
  if (depth.is_bigendian) {
    return Invalid(
        absl::StrCat(kDepthTopic, ".is_bigendian is 1; the bridge takes little-endian pixels"));
  }
  if (absl::Status s = CheckLayout(depth, BytesPerPixel(encoding), kDepthTopic); !s.ok()) return s;
  DepthView view;
  view.data = depth.data.data();
  view.size_bytes = depth.data.size();
  view.width = depth.width;
  view.height = depth.height;
  view.stride_bytes = depth.step;
  view.encoding = encoding;
  return view;
}

absl::Status ToDepthFrame(const ImageMsg& depth, const ImageMsg& colour,
                          const CameraInfoMsg& info, std::optional<double> depth_scale,
                          OutgoingFrame* frame) {
  auto camera = CameraFromDepth(depth, info, depth_scale);
  if (!camera.ok()) return camera.status();
  auto view = DepthFromImage(depth);
  if (!view.ok()) return view.status();
  // A depth image registered to the colour camera is in that camera's frame; another frame_id
  // means the colours would land on the wrong points.
  if (depth.header.frame_id != colour.header.frame_id) {
    return Invalid(absl::StrCat(kDepthColourTopic, ".header.frame_id is '", colour.header.frame_id,
                                "' but ", kDepthTopic, "'s is '", depth.header.frame_id,
                                "'; the depth image must be registered to the colour camera"));
  }
  return FinishFrame(
      *std::move(camera), depth, kDepthTopic, colour, kDepthColourTopic, depth.header,
      [&](const client::ColorInput& c) { return client::DepthFrame{*view, c}; }, frame);
}

// ---- ~input stereo

absl::StatusOr<CameraModel> CameraFromStereo(const CameraInfoMsg& left_info,
                                             const CameraInfoMsg& right_info,
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

absl::Status ToStereoFrame(const ImageMsg& left, const ImageMsg& right,
                           const CameraInfoMsg& left_info,
                           const CameraInfoMsg& right_info, OutgoingFrame* frame) {
  // Before the camera, whose checks take the left image's size for both CameraInfos.
  if (absl::Status s = CheckSameSize(left, kLeftTopic, right, kRightTopic); !s.ok()) return s;
  auto camera = CameraFromStereo(left_info, right_info, left.width, left.height);
  if (!camera.ok()) return camera.status();
  auto left_view = ColourFromImage(left, kLeftTopic);
  if (!left_view.ok()) return left_view.status();
  // The right image is the one matched against the left: the "colour" here is its grey or colour.
  return FinishFrame(
      *std::move(camera), left, kLeftTopic, right, kRightTopic, left.header,
      [&](const client::ColorInput& r) { return client::StereoFrame{*left_view, r}; }, frame);
}

}  // namespace cloudcast::ros_bridge
