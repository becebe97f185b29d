#include "cloudcast/stereo/evaluation.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"

namespace cloudcast::stereo {

absl::Status DisparityScore::Add(const DisparityMap16& map, const DisparityView& truth,
                                 std::uint32_t x_from) {
  if (truth.encoding != DisparityEncoding::kU8 || truth.width != map.width ||
      truth.height != map.height) {
    return absl::InvalidArgumentError(absl::StrCat(
        "truth is ", truth.width, "x", truth.height, " ", std::string(Name(truth.encoding)),
        "; the map is ", map.width, "x", map.height, " and the truth must be u8 of its size"));
  }
  for (std::uint32_t y = 0; y < map.height; ++y) {
    const std::uint8_t* t = truth.row(y);
    for (std::uint32_t x = x_from; x < map.width; ++x) {
      if (t[x] == 0) continue;
      ++known_;
      const int d = map.at(x, y);
      if (d == 0) continue;
      ++matched_;
      const int e = std::clamp(d - 16 * t[x], -kRange, kRange);
      ++errors_[e + kRange];
    }
  }
  return absl::OkStatus();
}

double DisparityScore::Density() const {
  return known_ == 0 ? 0.0 : static_cast<double>(matched_) / static_cast<double>(known_);
}

std::uint64_t DisparityScore::Over(double threshold, int offset) const {
  // |e - 16 * offset| > 16 * threshold, e in 1/16 px.
  const double limit = 16.0 * threshold;
  std::uint64_t n = 0;
  for (int i = 0; i <= 2 * kRange; ++i) {
    if (errors_[i] != 0 && std::fabs(static_cast<double>(i - kRange - 16 * offset)) > limit) {
      n += errors_[i];
    }
  }
  return n;
}

double DisparityScore::Bad(double threshold, int offset) const {
  if (matched_ == 0) return 0.0;
  return 100.0 * static_cast<double>(Over(threshold, offset)) / static_cast<double>(matched_);
}

double DisparityScore::BadCountingMisses(double threshold, int offset) const {
  if (known_ == 0) return 0.0;
  return 100.0 * static_cast<double>(Over(threshold, offset) + known_ - matched_) /
         static_cast<double>(known_);
}

double DisparityScore::MedianError() const {
  if (matched_ == 0) return 0.0;
  std::uint64_t seen = 0;
  for (int i = 0; i <= 2 * kRange; ++i) {
    seen += errors_[i];
    if (2 * seen >= matched_) return (i - kRange) / 16.0;
  }
  return 0.0;
}

}  // namespace cloudcast::stereo
