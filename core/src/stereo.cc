#include "cloudcast/core/stereo.h"

#include <cmath>
#include <string>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/checks.h"

namespace cloudcast {

std::string_view Name(StereoMatcher matcher) {
  switch (matcher) {
    case StereoMatcher::kSgm:
      return "sgm";
    case StereoMatcher::kOpenCvSgbm:
      return "sgbm";
    case StereoMatcher::kOpenCvSgbm3Way:
      return "sgbm-3way";
    case StereoMatcher::kOpenCvHH:
      return "hh";
    case StereoMatcher::kOpenCvBm:
      return "bm";
  }
  return "?";
}

const std::vector<StereoMatcher>& AllStereoMatchers() {
  static const std::vector<StereoMatcher> all = {
      StereoMatcher::kSgm, StereoMatcher::kOpenCvSgbm, StereoMatcher::kOpenCvSgbm3Way,
      StereoMatcher::kOpenCvHH, StereoMatcher::kOpenCvBm};
  return all;
}

bool ParseStereoMatcher(std::string_view name, StereoMatcher* out) {
  for (StereoMatcher m : AllStereoMatchers()) {
    if (Name(m) == name) {
      *out = m;
      return true;
    }
  }
  return false;
}

namespace {

std::string Member(std::string_view field, std::string_view member) {
  return absl::StrCat(std::string(field), ".", std::string(member));
}

absl::Status FiniteValues(std::string_view field, const double* values, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(values[i])) {
      return absl::InvalidArgumentError(
          absl::StrCat(std::string(field), "[", i, "] must be finite, got ", values[i]));
    }
  }
  return absl::OkStatus();
}

absl::Status Intrinsics(std::string_view field, const std::array<double, 9>& k) {
  if (auto s = FiniteValues(field, k.data(), k.size()); !s.ok()) return s;
  if (!(k[0] > 0 && k[4] > 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat(std::string(field), " must have positive focal lengths at [0] and [4], got ",
                     k[0], " and ", k[4]));
  }
  if (k[6] != 0 || k[7] != 0 || k[8] != 1) {
    return absl::InvalidArgumentError(
        absl::StrCat(std::string(field), " must end in the row 0, 0, 1 (a camera matrix), got ",
                     k[6], ", ", k[7], ", ", k[8]));
  }
  return absl::OkStatus();
}

absl::Status Distortion(std::string_view field, const std::vector<double>& d) {
  const std::size_t n = d.size();
  if (n != 0 && n != 4 && n != 5 && n != 8 && n != 12 && n != 14) {
    return absl::InvalidArgumentError(absl::StrCat(
        std::string(field), " has ", n, " coefficients; OpenCV takes 0, 4, 5, 8, 12 or 14"));
  }
  return FiniteValues(field, d.data(), n);
}

}  // namespace

absl::Status StereoCalibration::Validate(std::string_view field) const {
  if (width == 0 || height == 0) {
    return absl::InvalidArgumentError(absl::StrCat(std::string(field), " is for a ", width, "x",
                                                   height,
                                                   " image; width and height must be >= 1"));
  }
  for (absl::Status s :
       {Intrinsics(Member(field, "left_k"), left_k), Distortion(Member(field, "left_d"), left_d),
        Intrinsics(Member(field, "right_k"), right_k),
        Distortion(Member(field, "right_d"), right_d),
        FiniteValues(Member(field, "r"), r.data(), r.size()),
        FiniteValues(Member(field, "t"), t.data(), t.size())}) {
    if (!s.ok()) return s;
  }
  // R must be a rotation: R * R^T = I and det R = 1.
  double worst = 0;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      double dot = 0;
      for (int k = 0; k < 3; ++k) dot += r[3 * i + k] * r[3 * j + k];
      worst = std::max(worst, std::fabs(dot - (i == j ? 1.0 : 0.0)));
    }
  }
  const double det = r[0] * (r[4] * r[8] - r[5] * r[7]) - r[1] * (r[3] * r[8] - r[5] * r[6]) +
                     r[2] * (r[3] * r[7] - r[4] * r[6]);
  if (worst > 1e-6 || std::fabs(det - 1) > 1e-6) {
    return absl::InvalidArgumentError(
        absl::StrCat(Member(field, "r"), " is not a rotation matrix (R R^T differs from I by ",
                     worst, ", det R = ", det, ")"));
  }
  if (t[0] == 0 && t[1] == 0 && t[2] == 0) {
    return absl::InvalidArgumentError(
        absl::StrCat(Member(field, "t"), " is 0: the two cameras need a baseline"));
  }
  return absl::OkStatus();
}

bool StereoCalibration::operator==(const StereoCalibration& o) const {
  return width == o.width && height == o.height && left_k == o.left_k && left_d == o.left_d &&
         right_k == o.right_k && right_d == o.right_d && r == o.r && t == o.t;
}

absl::Status StereoParams::Validate(std::string_view field) const {
  auto in = [&](std::string_view member, int value, int lo, int hi) {
    return check::InRange(Member(field, member), value, lo, hi);
  };
  if (Name(matcher) == "?") {
    return absl::InvalidArgumentError(absl::StrCat(Member(field, "matcher"), " is ",
                                                   static_cast<int>(matcher), ", not a matcher"));
  }
  // 512 disparities bound the cost volume our matcher keeps (width x height x 512 bytes).
  if (num_disparities <= 0 || num_disparities % 16 != 0 || num_disparities > 512) {
    return absl::InvalidArgumentError(
        absl::StrCat(Member(field, "num_disparities"), " is ", num_disparities,
                     "; it must be a positive multiple of 16, at most 512"));
  }
  const int min_block = matcher == StereoMatcher::kOpenCvBm ? 5 : 1;
  if (block_size % 2 == 0 || block_size < min_block || block_size > 51) {
    return absl::InvalidArgumentError(
        absl::StrCat(Member(field, "block_size"), " is ", block_size, "; it must be odd, in [",
                     min_block, ", 51]", matcher == StereoMatcher::kOpenCvBm ? " for bm" : ""));
  }
  for (absl::Status s : {in("min_disparity", min_disparity, -4096, 4096), in("p1", p1, 0, 1 << 20),
                         in("p2", p2, 0, 1 << 20), in("uniqueness_ratio", uniqueness_ratio, 0, 100),
                         in("speckle_window_size", speckle_window_size, 0, 10000),
                         in("speckle_range", speckle_range, 0, 4096),
                         in("disp12_max_diff", disp12_max_diff, -1, 4096)}) {
    if (!s.ok()) return s;
  }
  if (p1 != 0 && p2 != 0 && p2 <= p1) {
    return absl::InvalidArgumentError(
        absl::StrCat(Member(field, "p2"), " is ", p2, "; it must be greater than p1 (", p1, ")"));
  }
  if (paths != 4 && paths != 8) {
    return absl::InvalidArgumentError(
        absl::StrCat(Member(field, "paths"), " is ", paths, "; it must be 4 or 8"));
  }
  if (has_calibration) return calibration.Validate(Member(field, "calibration"));
  return absl::OkStatus();
}

}  // namespace cloudcast
