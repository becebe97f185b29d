#include "cloudcast/stereo/grey.h"

#include <cstring>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "cloudcast/core/limits.h"

namespace cloudcast::stereo {
namespace {

int TypeOf(ColorEncoding e) {
  switch (e) {
    case ColorEncoding::kBGR8:
    case ColorEncoding::kRGB8:
      return CV_8UC3;
    case ColorEncoding::kRGBA8:
      return CV_8UC4;
    case ColorEncoding::kMono8:
      break;
  }
  return CV_8UC1;
}

int CodeOf(ColorEncoding e) {
  switch (e) {
    case ColorEncoding::kBGR8:
      return cv::COLOR_BGR2GRAY;
    case ColorEncoding::kRGB8:
      return cv::COLOR_RGB2GRAY;
    case ColorEncoding::kRGBA8:
      return cv::COLOR_RGBA2GRAY;
    case ColorEncoding::kMono8:
      break;
  }
  return -1;
}

}  // namespace

absl::Status ToGrey(const ColorView& colour, GreyImage* out, std::string_view field) {
  if (absl::Status s = ValidateView(colour, Limits{}, field); !s.ok()) return s;
  const int w = static_cast<int>(colour.width), h = static_cast<int>(colour.height);
  out->width = colour.width;
  out->height = colour.height;
  out->encoding = ColorEncoding::kMono8;
  out->pixels.resize(static_cast<std::size_t>(w) * h);
  if (colour.encoding == ColorEncoding::kMono8) {
    for (int y = 0; y < h; ++y) std::memcpy(out->pixels.data() + y * w, colour.row(y), w);
    return absl::OkStatus();
  }
  const int type = TypeOf(colour.encoding), code = CodeOf(colour.encoding);
  if (colour.rows == nullptr) {
    const cv::Mat src(h, w, type, const_cast<void*>(colour.data), colour.stride_bytes);
    cv::Mat dst(h, w, CV_8UC1, out->pixels.data());
    cv::cvtColor(src, dst, code);
  } else {
    // Rows in pieces (as the server receives them): one row at a time.
    for (int y = 0; y < h; ++y) {
      const cv::Mat src(1, w, type, const_cast<std::uint8_t*>(colour.row(y)));
      cv::Mat dst(1, w, CV_8UC1, out->pixels.data() + static_cast<std::size_t>(y) * w);
      cv::cvtColor(src, dst, code);
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<GreyImage> ToGrey(const ColorView& colour, std::string_view field) {
  GreyImage out;
  if (absl::Status s = ToGrey(colour, &out, field); !s.ok()) return s;
  return out;
}

}  // namespace cloudcast::stereo
