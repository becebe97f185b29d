// OpenCV 4.6's matchers, called as they are: cv::StereoSGBM in its three modes and cv::StereoBM.
// Their int16 output ((minDisparity - 1) * 16 for "no match") becomes ours (0 for no match).
#include <cstring>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "absl/strings/str_cat.h"
#include "cloudcast/stereo/budget.h"
#include "matcher_internal.h"

namespace cloudcast::stereo {
namespace {

// A cv::Mat over a view's pixels; rows in pieces are gathered into `copy` first.
cv::Mat MatOf(const GreyView& v, cv::Mat* copy) {
  if (v.rows == nullptr) {
    return cv::Mat(static_cast<int>(v.height), static_cast<int>(v.width), CV_8UC1,
                   const_cast<void*>(v.data), v.stride_bytes);
  }
  copy->create(static_cast<int>(v.height), static_cast<int>(v.width), CV_8UC1);
  for (std::uint32_t y = 0; y < v.height; ++y) std::memcpy(copy->ptr(y), v.row(y), v.width);
  return *copy;
}

cv::Ptr<cv::StereoMatcher> Create(const StereoParams& p) {
  if (p.matcher == StereoMatcher::kOpenCvBm) {
    cv::Ptr<cv::StereoBM> bm = cv::StereoBM::create(p.num_disparities, p.block_size);
    bm->setMinDisparity(p.min_disparity);
    bm->setUniquenessRatio(p.uniqueness_ratio);
    bm->setSpeckleWindowSize(p.speckle_window_size);
    bm->setSpeckleRange(p.speckle_range);
    bm->setDisp12MaxDiff(p.disp12_max_diff);
    return bm;
  }
  const int mode = p.matcher == StereoMatcher::kOpenCvSgbm3Way ? cv::StereoSGBM::MODE_SGBM_3WAY
                   : p.matcher == StereoMatcher::kOpenCvHH     ? cv::StereoSGBM::MODE_HH
                                                               : cv::StereoSGBM::MODE_SGBM;
  return cv::StereoSGBM::create(p.min_disparity, p.num_disparities, p.block_size, p.EffectiveP1(),
                                p.EffectiveP2(), p.disp12_max_diff,
                                /*preFilterCap=*/0, p.uniqueness_ratio, p.speckle_window_size,
                                p.speckle_range, mode);
}

class OpenCvMatcher final : public Matcher {
 public:
  explicit OpenCvMatcher(const StereoParams& params) : params_(params), cv_(Create(params)) {}

  const StereoParams& params() const override { return params_; }

  absl::Status Compute(const GreyView& left, const GreyView& right, DisparityMap16* out) override {
    if (absl::Status s = CheckPair(left, right); !s.ok()) return s;
    // Below this OpenCV reads out of bounds or aborts from a destructor (budget.h).
    if (absl::Status s = CheckMatchable(params_, left.width, left.height, "stereo"); !s.ok()) {
      return s;
    }
    // MODE_HH keeps every pixel's 16-bit costs for the frame.
    if (params_.matcher == StereoMatcher::kOpenCvHH) {
      if (absl::Status s =
              CheckVolume(left.width, left.height, params_.num_disparities, 2, "OpenCV's MODE_HH");
          !s.ok()) {
        return s;
      }
    }
    try {
      cv_->compute(MatOf(left, &left_copy_), MatOf(right, &right_copy_), disparity_);
    } catch (const cv::Exception& e) {
      return absl::InvalidArgumentError(
          absl::StrCat("OpenCV's ", std::string(Name(params_.matcher)), " refused the ", left.width,
                       "x", left.height, " pair: ", e.what()));
    }
    out->width = left.width;
    out->height = left.height;
    out->values.resize(static_cast<std::size_t>(left.width) * left.height);
    const int invalid_below = params_.min_disparity * 16;
    for (int y = 0; y < disparity_.rows; ++y) {
      const std::int16_t* src = disparity_.ptr<std::int16_t>(y);
      std::uint16_t* dst = out->values.data() + static_cast<std::size_t>(y) * left.width;
      for (int x = 0; x < disparity_.cols; ++x) {
        const int v = src[x];
        dst[x] = static_cast<std::uint16_t>(v < invalid_below || v <= 0 ? 0 : v);
      }
    }
    return absl::OkStatus();
  }

 private:
  const StereoParams params_;
  cv::Ptr<cv::StereoMatcher> cv_;
  cv::Mat left_copy_, right_copy_, disparity_;
};

}  // namespace

void SetOpenCvThreads(int threads) { cv::setNumThreads(threads); }

std::unique_ptr<Matcher> MakeOpenCvMatcher(const StereoParams& params) {
  return std::make_unique<OpenCvMatcher>(params);
}

}  // namespace cloudcast::stereo
