#include "stereo_stage.h"

#include <utility>

#include "absl/strings/str_cat.h"
#include "cloudcast/stereo/budget.h"

namespace cloudcast::server {
namespace {

using Clock = std::chrono::steady_clock;

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

// The members that make a matcher (calibration and return_disparity do not).
bool SameMatcher(const StereoParams& a, const StereoParams& b) {
  return a.matcher == b.matcher && a.min_disparity == b.min_disparity &&
         a.num_disparities == b.num_disparities && a.block_size == b.block_size && a.p1 == b.p1 &&
         a.p2 == b.p2 && a.uniqueness_ratio == b.uniqueness_ratio &&
         a.speckle_window_size == b.speckle_window_size && a.speckle_range == b.speckle_range &&
         a.disp12_max_diff == b.disp12_max_diff && a.paths == b.paths;
}

}  // namespace

absl::StatusOr<std::shared_ptr<const stereo::Rectifier>> RectifierCache::Get(
    const StereoCalibration& calibration) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (auto it = entries_.begin(); it != entries_.end(); ++it) {
      if (it->calibration == calibration) {
        entries_.splice(entries_.begin(), entries_, it);
        return entries_.front().rectifier;
      }
    }
  }
  // Built outside the lock: another worker may build the same maps meanwhile, and the second to
  // finish keeps the first's (a rare double build beats every worker waiting on one).
  absl::StatusOr<stereo::Rectifier> made = stereo::Rectifier::Make(calibration);
  if (!made.ok()) return made.status();
  auto rectifier = std::make_shared<const stereo::Rectifier>(*std::move(made));
  std::lock_guard<std::mutex> lock(mu_);
  for (const Entry& e : entries_) {
    if (e.calibration == calibration) return e.rectifier;
  }
  entries_.push_front(Entry{calibration, rectifier});
  if (entries_.size() > capacity_) entries_.pop_back();
  return rectifier;
}

std::size_t RectifierCache::size() const {
  std::lock_guard<std::mutex> lock(mu_);
  return entries_.size();
}

absl::Status StereoStage::Match(const ColorView& left, const ColorView& right,
                                const FrameSettings& settings, const CameraModel& camera,
                                std::uint64_t max_volume, MatchedPair* out) {
  const StereoParams& params = settings.stereo;
  if (auto s = stereo::CheckMatchable(params, left.width, left.height, "config.stereo"); !s.ok()) {
    return s;
  }
  const std::uint64_t volume = stereo::MatchVolume(params, left.width, left.height);
  if (volume > max_volume) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "frame.right: a ", left.width, "x", left.height, " stereo pair with ",
        params.num_disparities, " disparities (config.stereo.num_disparities) and block_size ",
        params.block_size, " is a matching volume of ", volume,
        " (width x (height + 8 x block_size) x num_disparities); this server's limit is ",
        max_volume,
        " (ServerLimits.max_stereo_volume): send smaller images, fewer disparities or a smaller "
        "block"));
  }
  const Clock::time_point t0 = Clock::now();
  ColorView l = left, r = right;
  CameraModel matched_camera = camera;
  if (params.has_calibration) {
    const StereoCalibration& k = params.calibration;
    if (left.width != k.width || left.height != k.height) {
      return absl::InvalidArgumentError(absl::StrCat(
          "frame.color is ", left.width, "x", left.height, " but config.stereo.calibration is for ",
          k.width, "x", k.height, " images"));
    }
    absl::StatusOr<std::shared_ptr<const stereo::Rectifier>> rectifier = rectifiers_->Get(k);
    if (!rectifier.ok()) return rectifier.status();
    if (auto s = (*rectifier)->Rectify(left, right, &rectified_left_, &rectified_right_); !s.ok()) {
      return s;
    }
    l = rectified_left_.view();
    r = rectified_right_.view();
    const stereo::RectifiedCamera& rc = (*rectifier)->camera();
    matched_camera.fx = rc.fx;
    matched_camera.fy = rc.fy;
    matched_camera.cx = rc.cx;
    matched_camera.cy = rc.cy;
    matched_camera.baseline = rc.baseline;
  }
  const Clock::time_point t1 = Clock::now();
  if (auto s = stereo::ToGrey(l, &grey_left_, "frame.color"); !s.ok()) return s;
  if (auto s = stereo::ToGrey(r, &grey_right_, "frame.right"); !s.ok()) return s;
  if (matcher_ == nullptr || !SameMatcher(matcher_params_, params)) {
    absl::StatusOr<std::unique_ptr<stereo::Matcher>> m = stereo::MakeMatcher(params);
    if (!m.ok()) return m.status();
    matcher_ = *std::move(m);
    matcher_params_ = params;
  }
  if (auto s = matcher_->Compute(grey_left_.view(), grey_right_.view(), &disparity_); !s.ok()) {
    return s;
  }
  const Clock::time_point t2 = Clock::now();
  out->disparity = disparity_.view();
  out->colour = l;
  out->camera = stereo::ForMatcherOutput(matched_camera);
  out->rectify_seconds = params.has_calibration ? Seconds(t1 - t0) : 0.0;
  out->match_seconds = Seconds(t2 - t1);
  return absl::OkStatus();
}

}  // namespace cloudcast::server
