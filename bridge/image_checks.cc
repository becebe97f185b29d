#include "image_checks.h"

#include <cmath>

#include "absl/strings/str_cat.h"

namespace cloudcast::ros_bridge {
namespace {

namespace enc = encodings;

absl::Status Invalid(const std::string& message) { return absl::InvalidArgumentError(message); }

bool FinitePositive(double v) { return std::isfinite(v) && v > 0; }

}  // namespace

absl::Status CheckLayout(const ImageMsg& image, std::size_t bytes_per_pixel,
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

absl::StatusOr<client::ColorInput> ColourFromImage(const ImageMsg& image,
                                                   const std::string& topic) {
  ColorEncoding encoding;
  bool bgra = false;
  if (image.encoding == enc::kRgb8) {
    encoding = ColorEncoding::kRGB8;
  } else if (image.encoding == enc::kBgr8) {
    encoding = ColorEncoding::kBGR8;
  } else if (image.encoding == enc::kRgba8) {
    encoding = ColorEncoding::kRGBA8;
  } else if (image.encoding == enc::kMono8) {
    encoding = ColorEncoding::kMono8;
  } else if (image.encoding == enc::kBgra8) {
    encoding = ColorEncoding::kRGBA8;  // four bytes a pixel, for the layout check only
    bgra = true;
  } else {
    return Invalid(absl::StrCat(topic, ".encoding is '", std::string(image.encoding),
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

absl::Status CheckSameSize(const ImageMsg& first, const std::string& first_topic,
                           const ImageMsg& second, const std::string& second_topic) {
  if (first.width == second.width && first.height == second.height) return absl::OkStatus();
  return Invalid(absl::StrCat(second_topic, " is ", second.width, "x", second.height, " but ",
                              first_topic, " is ", first.width, "x", first.height,
                              "; they must be the same size"));
}

absl::StatusOr<Pinhole> PinholeFromInfo(const CameraInfoMsg& info,
                                        const std::string& topic, std::uint32_t width,
                                        std::uint32_t height, const std::string& image_topic,
                                        IntrinsicsFrom from) {
  const auto& P = info.P;
  const auto& K = info.K;
  Pinhole p;
  std::string matrix = "P";
  if (P[0] != 0 || P[5] != 0) {
    p = {P[0], P[5], P[2], P[6]};
  } else if (from == IntrinsicsFrom::kPOrK && (K[0] != 0 || K[4] != 0)) {
    p = {K[0], K[4], K[2], K[5]};
    matrix = "K";
  } else {
    return Invalid(absl::StrCat(topic, ".P", from == IntrinsicsFrom::kPOrK ? " and K are" : " is",
                                " all zero: the camera is not calibrated"));
  }
  if (!FinitePositive(p.fx) || !FinitePositive(p.fy)) {
    return Invalid(absl::StrCat(topic, ".", matrix, " has fx = ", p.fx, ", fy = ", p.fy,
                                "; both must be finite and > 0"));
  }
  if (!std::isfinite(p.cx) || !std::isfinite(p.cy)) {
    return Invalid(absl::StrCat(topic, ".", matrix, " has cx = ", p.cx, ", cy = ", p.cy,
                                "; both must be finite"));
  }
  // A binned or cropped CameraInfo describes another pixel grid than the image's.
  if (info.binning_x > 1 || info.binning_y > 1 || info.roi.width != 0 || info.roi.height != 0) {
    return Invalid(absl::StrCat(topic, " has binning ", info.binning_x, "x", info.binning_y,
                                " and roi ", info.roi.width, "x", info.roi.height,
                                "; binning and regions of interest are not supported"));
  }
  if (info.width != 0 && (info.width != width || info.height != height)) {
    return Invalid(absl::StrCat(topic, " is ", info.width, "x", info.height, " but ", image_topic,
                                " is ", width, "x", height,
                                "; they must describe the same pixels"));
  }
  return p;
}

}  // namespace cloudcast::ros_bridge
