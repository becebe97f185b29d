#include "cloudcast/stereo/rectifier.h"

#include <cmath>
#include <cstring>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/checks.h"
#include "cloudcast/core/limits.h"
#include "cloudcast/stereo/matcher.h"

namespace cloudcast::stereo {
namespace {

cv::Mat Mat3(const std::array<double, 9>& m) {
  return cv::Mat(3, 3, CV_64F, const_cast<double*>(m.data())).clone();
}

cv::Mat Coefficients(const std::vector<double>& d) {
  if (d.empty()) return cv::Mat::zeros(1, 5, CV_64F);
  return cv::Mat(1, static_cast<int>(d.size()), CV_64F, const_cast<double*>(d.data())).clone();
}

cv::Mat MatOf(const ColorView& v, cv::Mat* copy) {
  const int type = CV_8UC(static_cast<int>(BytesPerPixel(v.encoding)));
  if (v.rows == nullptr) {
    return cv::Mat(static_cast<int>(v.height), static_cast<int>(v.width), type,
                   const_cast<void*>(v.data), v.stride_bytes);
  }
  copy->create(static_cast<int>(v.height), static_cast<int>(v.width), type);
  for (std::uint32_t y = 0; y < v.height; ++y) {
    std::memcpy(copy->ptr(y), v.row(y), v.width * BytesPerPixel(v.encoding));
  }
  return *copy;
}

}  // namespace

absl::Status RectifierOptions::Validate(std::string_view field) const {
  if (!(alpha == -1.0 || (alpha >= 0.0 && alpha <= 1.0))) {
    return absl::InvalidArgumentError(
        absl::StrCat(std::string(field), ".alpha is ", alpha, "; it must be -1 or in [0, 1]"));
  }
  return absl::OkStatus();
}

CameraModel RectifiedCamera::ToCameraModel() const {
  CameraModel c;
  c.fx = fx;
  c.fy = fy;
  c.cx = cx;
  c.cy = cy;
  c.baseline = baseline;
  return ForMatcherOutput(c);
}

struct Rectifier::Maps {
  cv::Mat left1, left2, right1, right2;  // cv::initUndistortRectifyMap's CV_16SC2 + CV_16UC1
};

absl::StatusOr<Rectifier> Rectifier::Make(const StereoCalibration& c,
                                          const RectifierOptions& options) {
  if (absl::Status s = c.Validate(); !s.ok()) return s;
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  const cv::Size size(static_cast<int>(c.width), static_cast<int>(c.height));
  const cv::Mat k1 = Mat3(c.left_k), k2 = Mat3(c.right_k), d1 = Coefficients(c.left_d),
                d2 = Coefficients(c.right_d), r = Mat3(c.r);
  const cv::Mat t = cv::Mat(3, 1, CV_64F, const_cast<double*>(c.t.data())).clone();
  cv::Mat r1, r2, p1, p2, q;
  try {
    // CALIB_ZERO_DISPARITY: both principal points at the same place, so z = f * B / d.
    cv::stereoRectify(k1, d1, k2, d2, size, r, t, r1, r2, p1, p2, q, cv::CALIB_ZERO_DISPARITY,
                      options.alpha, size);
  } catch (const cv::Exception& e) {
    return absl::InvalidArgumentError(
        absl::StrCat("calibration: cv::stereoRectify refused it: ", e.what()));
  }
  // A horizontal pair gives P2 = [f 0 cx Tx*f; 0 f cy 0; 0 0 1 0], Tx < 0 when the right camera
  // is to the right of the left one (OpenCV's convention). Matching needs exactly that.
  const double tx = p2.at<double>(0, 3), ty = p2.at<double>(1, 3);
  if (std::fabs(ty) > std::fabs(tx)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "calibration.t is (", c.t[0], ", ", c.t[1], ", ", c.t[2],
        "): the cameras are one above the other; the matchers need a side-by-side pair"));
  }
  if (tx > 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "calibration.t is (", c.t[0], ", ", c.t[1], ", ", c.t[2],
        "): the right camera is to the left of the left one (expected t[0] < 0); swap them"));
  }
  auto maps = std::make_shared<Maps>();
  cv::initUndistortRectifyMap(k1, d1, r1, p1, size, CV_16SC2, maps->left1, maps->left2);
  cv::initUndistortRectifyMap(k2, d2, r2, p2, size, CV_16SC2, maps->right1, maps->right2);
  Rectifier rect;
  rect.maps_ = std::move(maps);
  rect.width_ = c.width;
  rect.height_ = c.height;
  rect.camera_.fx = p1.at<double>(0, 0);
  rect.camera_.fy = p1.at<double>(1, 1);
  rect.camera_.cx = p1.at<double>(0, 2);
  rect.camera_.cy = p1.at<double>(1, 2);
  rect.camera_.baseline = -tx / p2.at<double>(0, 0);
  return rect;
}

absl::Status Rectifier::Rectify(const ColorView& left, const ColorView& right, OwnedColor* left_out,
                                OwnedColor* right_out) const {
  for (auto [view, name] : {std::pair{&left, "left"}, std::pair{&right, "right"}}) {
    if (absl::Status s = ValidateView(*view, Limits{}, name); !s.ok()) return s;
    if (view->width != width_ || view->height != height_) {
      return absl::InvalidArgumentError(absl::StrCat(name, " is ", view->width, "x", view->height,
                                                     "; the calibration is for ", width_, "x",
                                                     height_));
    }
  }
  if (left.encoding != right.encoding) {
    return absl::InvalidArgumentError(absl::StrCat(
        "right.encoding is ", std::string(Name(right.encoding)), " but left.encoding is ",
        std::string(Name(left.encoding)), "; they must be the same"));
  }
  cv::Mat copy;
  const std::pair<const ColorView*, OwnedColor*> sides[] = {{&left, left_out}, {&right, right_out}};
  for (int i = 0; i < 2; ++i) {
    const ColorView& v = *sides[i].first;
    OwnedColor* out = sides[i].second;
    out->width = v.width;
    out->height = v.height;
    out->encoding = v.encoding;
    out->pixels.resize(static_cast<std::size_t>(v.width) * v.height * BytesPerPixel(v.encoding));
    const cv::Mat src = MatOf(v, &copy);
    cv::Mat dst(static_cast<int>(v.height), static_cast<int>(v.width), src.type(),
                out->pixels.data());
    const cv::Mat& m1 = i == 0 ? maps_->left1 : maps_->right1;
    const cv::Mat& m2 = i == 0 ? maps_->left2 : maps_->right2;
    cv::remap(src, dst, m1, m2, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
  }
  return absl::OkStatus();
}

}  // namespace cloudcast::stereo
