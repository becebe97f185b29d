#include "cloudcast/core/stereo.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/checks.h"
#include "cloudcast/core/limits.h"

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

int SgmMaxCensusCost(int block_size) {
  const int radius = block_size / 2;
  const int bits = 2 * radius * (radius + 1);  // a centre-symmetric census window's comparisons
  return bits > 12 ? (bits + 1) / 2 : bits;
}

namespace {

// Debian's Abseil has its own string_view, which StrCat takes; std::string converts to both.
std::string S(std::string_view v) { return std::string(v); }

std::string Member(std::string_view field, std::string_view member) {
  return absl::StrCat(S(field), ".", S(member));
}

absl::Status CameraMatrix(const std::string& field, const std::array<double, 9>& k) {
  for (int i = 0; i < 9; ++i) {
    if (absl::Status s = check::Finite(absl::StrCat(field, "[", i, "]"), k[i]); !s.ok()) return s;
  }
  if (absl::Status s = check::Positive(field + "[0] (fx)", k[0]); !s.ok()) return s;
  if (absl::Status s = check::Positive(field + "[4] (fy)", k[4]); !s.ok()) return s;
  if (k[3] != 0 || k[6] != 0 || k[7] != 0 || k[8] != 1) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, " must be a camera matrix: [3], [6], [7] = 0 and [8] = 1; got ", k[3],
                     ", ", k[6], ", ", k[7], " and ", k[8]));
  }
  return absl::OkStatus();
}

absl::Status Distortion(const std::string& field, const std::vector<double>& d) {
  const std::size_t n = d.size();
  if (n != 0 && n != 4 && n != 5 && n != 8 && n != 12 && n != 14) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, " holds ", n, " coefficients; OpenCV takes 0, 4, 5, 8, 12 or 14"));
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (absl::Status s = check::Finite(absl::StrCat(field, "[", i, "]"), d[i]); !s.ok()) return s;
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status StereoCalibration::Validate(std::string_view field) const {
  const std::string f(field);
  for (absl::Status s :
       {CameraMatrix(f + ".left_k", left_k), Distortion(f + ".left_d", left_d),
        CameraMatrix(f + ".right_k", right_k), Distortion(f + ".right_d", right_d)}) {
    if (!s.ok()) return s;
  }
  for (int i = 0; i < 9; ++i) {
    if (absl::Status s = check::Finite(absl::StrCat(f, ".r[", i, "]"), r[i]); !s.ok()) return s;
  }
  // R^T R = I and det R = +1: a rotation, not a reflection or a scaled matrix.
  double worst = 0;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      double dot = 0;
      for (int k = 0; k < 3; ++k) dot += r[3 * k + i] * r[3 * k + j];
      worst = std::max(worst, std::fabs(dot - (i == j ? 1.0 : 0.0)));
    }
  }
  const double det = r[0] * (r[4] * r[8] - r[5] * r[7]) - r[1] * (r[3] * r[8] - r[5] * r[6]) +
                     r[2] * (r[3] * r[7] - r[4] * r[6]);
  if (worst > 1e-6 || det < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat(f, ".r is not a rotation: |R^T R - I| reaches ", worst, ", det R is ", det));
  }
  for (int i = 0; i < 3; ++i) {
    if (absl::Status s = check::Finite(absl::StrCat(f, ".t[", i, "]"), t[i]); !s.ok()) return s;
  }
  if (t[0] == 0 && t[1] == 0 && t[2] == 0) {
    return absl::InvalidArgumentError(absl::StrCat(f, ".t is 0; the cameras need a baseline"));
  }
  return check::ImageSize(f, width, height, Limits{});
}

bool StereoCalibration::operator==(const StereoCalibration& o) const {
  return width == o.width && height == o.height && left_k == o.left_k && left_d == o.left_d &&
         right_k == o.right_k && right_d == o.right_d && r == o.r && t == o.t;
}

absl::Status StereoParams::Validate(std::string_view field) const {
  const std::string f(field);
  if (Name(matcher) == "?") {
    return absl::InvalidArgumentError(
        absl::StrCat(f, ".matcher is not a known matcher (", static_cast<int>(matcher), ")"));
  }
  if (num_disparities <= 0 || num_disparities % 16 != 0) {
    return absl::InvalidArgumentError(absl::StrCat(f, ".num_disparities is ", num_disparities,
                                                   "; it must be a positive multiple of 16"));
  }
  if (absl::Status s =
          check::InRange(f + ".num_disparities", num_disparities, 16, kMaxStereoDisparity);
      !s.ok()) {
    return s;
  }
  if (absl::Status s = check::InRange(f + ".min_disparity", min_disparity, -kMaxStereoDisparity,
                                      kMaxStereoDisparity - num_disparities);
      !s.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat(s.message(), " (min_disparity + num_disparities must not exceed ",
                     kMaxStereoDisparity, ")"));
  }
  if (block_size < 1 || block_size % 2 == 0 || block_size > 255) {
    return absl::InvalidArgumentError(
        absl::StrCat(f, ".block_size is ", block_size, "; it must be odd and in [1, 255]"));
  }
  if (matcher == StereoMatcher::kSgm && block_size != 3 && block_size != 5 && block_size != 7) {
    return absl::InvalidArgumentError(
        absl::StrCat(f, ".block_size is ", block_size,
                     "; the sgm matcher's census window is 3, 5 or 7 pixels square"));
  }
  if (matcher == StereoMatcher::kOpenCvBm && block_size < 5) {
    return absl::InvalidArgumentError(
        absl::StrCat(f, ".block_size is ", block_size, "; OpenCV's StereoBM (bm) needs >= 5"));
  }
  if (matcher == StereoMatcher::kSgm) {
    const int max_p2 = kSgmMaxPathCost - SgmMaxCensusCost(block_size);
    if (p1 != 0) {
      if (absl::Status s = check::InRange(f + ".p1", p1, 1, max_p2 - 1); !s.ok()) return s;
    }
    if (p2 != 0) {
      if (absl::Status s = check::InRange(f + ".p2", p2, EffectiveP1() + 1, max_p2); !s.ok()) {
        return absl::InvalidArgumentError(
            absl::StrCat(s.message(), " (the sgm matcher: above p1, and at most ", kSgmMaxPathCost,
                         " minus its largest cost ", SgmMaxCensusCost(block_size),
                         ", so that 8 paths sum exactly in a byte)"));
      }
    } else if (EffectiveP2() <= EffectiveP1()) {
      return absl::InvalidArgumentError(absl::StrCat(f, ".p1 is ", p1, "; with p2 0 (the default ",
                                                     EffectiveP2(), ") it must be below ",
                                                     EffectiveP2()));
    }
  } else {
    for (auto [name, value] : {std::pair{".p1", p1}, std::pair{".p2", p2}}) {
      if (absl::Status s = check::InRange(f + name, value, 0, 1 << 20); !s.ok()) return s;
    }
    if (p1 != 0 && p2 != 0 && p2 <= p1) {
      return absl::InvalidArgumentError(
          absl::StrCat(f, ".p2 is ", p2, "; it must be greater than p1 (", p1, ")"));
    }
  }
  if (absl::Status s = check::InRange(f + ".uniqueness_ratio", uniqueness_ratio, 0, 99); !s.ok()) {
    return s;
  }
  if (absl::Status s = check::InRange(f + ".speckle_window_size", speckle_window_size, 0,
                                      static_cast<std::int64_t>(Limits{}.max_pixels));
      !s.ok()) {
    return s;
  }
  if (absl::Status s = check::InRange(f + ".speckle_range", speckle_range, 0, kMaxStereoDisparity);
      !s.ok()) {
    return s;
  }
  if (disp12_max_diff > kMaxStereoDisparity) {
    return absl::InvalidArgumentError(absl::StrCat(f, ".disp12_max_diff is ", disp12_max_diff,
                                                   "; it must be at most ", kMaxStereoDisparity,
                                                   " (< 0 turns the check off)"));
  }
  if (paths != 4 && paths != 8) {
    return absl::InvalidArgumentError(absl::StrCat(f, ".paths is ", paths, "; it must be 4 or 8"));
  }
  if (has_calibration) return calibration.Validate(Member(field, "calibration"));
  return absl::OkStatus();
}

// Ours: chosen on New Tsukuba and Aloe (docs/stereo.md, "Choosing the defaults").
int StereoParams::EffectiveP1() const {
  if (p1 != 0) return p1;
  if (matcher != StereoMatcher::kSgm) return 8 * block_size * block_size;
  return block_size == 3 ? 3 : block_size == 5 ? 5 : 4;
}

int StereoParams::EffectiveP2() const {
  if (p2 != 0) return p2;
  if (matcher != StereoMatcher::kSgm) return 32 * block_size * block_size;
  return block_size == 3 ? 16 : 19;
}

}  // namespace cloudcast
