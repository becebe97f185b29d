#include "cloudcast/stereo/matcher.h"

#include <string>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/checks.h"
#include "cloudcast/core/limits.h"
#include "matcher_internal.h"
#include "sgm_kernels.h"

namespace cloudcast::stereo {
namespace {

// Debian's Abseil has its own string_view, which StrCat takes; std::string converts to both.
std::string S(std::string_view v) { return std::string(v); }

constexpr MatcherKind kKinds[] = {MatcherKind::kSgm, MatcherKind::kOpenCvSgbm,
                                  MatcherKind::kOpenCvSgbm3Way, MatcherKind::kOpenCvHH,
                                  MatcherKind::kOpenCvBm};
constexpr SimdLevel kLevels[] = {SimdLevel::kAuto, SimdLevel::kScalar, SimdLevel::kAvx2,
                                 SimdLevel::kAvx512};

}  // namespace

std::string_view Name(MatcherKind kind) {
  switch (kind) {
    case MatcherKind::kSgm:
      return "sgm";
    case MatcherKind::kOpenCvSgbm:
      return "sgbm";
    case MatcherKind::kOpenCvSgbm3Way:
      return "sgbm-3way";
    case MatcherKind::kOpenCvHH:
      return "hh";
    case MatcherKind::kOpenCvBm:
      return "bm";
  }
  return "?";
}

bool ParseMatcherKind(std::string_view name, MatcherKind* out) {
  for (MatcherKind k : kKinds) {
    if (Name(k) == name) {
      *out = k;
      return true;
    }
  }
  return false;
}

std::string_view Name(SimdLevel level) {
  switch (level) {
    case SimdLevel::kAuto:
      return "auto";
    case SimdLevel::kScalar:
      return "scalar";
    case SimdLevel::kAvx2:
      return "avx2";
    case SimdLevel::kAvx512:
      return "avx512";
  }
  return "?";
}

bool ParseSimdLevel(std::string_view name, SimdLevel* out) {
  for (SimdLevel l : kLevels) {
    if (Name(l) == name) {
      *out = l;
      return true;
    }
  }
  return false;
}

bool CpuSupports(SimdLevel level) {
  switch (level) {
    case SimdLevel::kAuto:
    case SimdLevel::kScalar:
      return true;
    case SimdLevel::kAvx2:
      return sgm::Avx2Kernels() != nullptr && __builtin_cpu_supports("avx2") &&
             __builtin_cpu_supports("bmi2") && __builtin_cpu_supports("popcnt");
    case SimdLevel::kAvx512:
      return sgm::Avx512Kernels() != nullptr && __builtin_cpu_supports("avx512f") &&
             __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512vl") &&
             __builtin_cpu_supports("avx512vbmi") && __builtin_cpu_supports("avx512bitalg") &&
             __builtin_cpu_supports("bmi2") && __builtin_cpu_supports("popcnt");
  }
  return false;
}

SimdLevel BestSimdLevel() {
  static const SimdLevel best = CpuSupports(SimdLevel::kAvx512) ? SimdLevel::kAvx512
                                : CpuSupports(SimdLevel::kAvx2) ? SimdLevel::kAvx2
                                                                : SimdLevel::kScalar;
  return best;
}

absl::Status MatcherParams::Validate(std::string_view field) const {
  const std::string f(field);
  if (Name(kind) == "?") {
    return absl::InvalidArgumentError(
        absl::StrCat(f, ".kind is not a known matcher (", static_cast<int>(kind), ")"));
  }
  if (num_disparities <= 0 || num_disparities % 16 != 0) {
    return absl::InvalidArgumentError(absl::StrCat(f, ".num_disparities is ", num_disparities,
                                                   "; it must be a positive multiple of 16"));
  }
  if (absl::Status s = check::InRange(f + ".num_disparities", num_disparities, 16, kMaxDisparity);
      !s.ok()) {
    return s;
  }
  if (absl::Status s = check::InRange(f + ".min_disparity", min_disparity, -kMaxDisparity,
                                      kMaxDisparity - num_disparities);
      !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat(
        s.message(), " (min_disparity + num_disparities must not exceed ", kMaxDisparity, ")"));
  }
  if (block_size < 1 || block_size % 2 == 0 || block_size > 255) {
    return absl::InvalidArgumentError(
        absl::StrCat(f, ".block_size is ", block_size, "; it must be odd and in [1, 255]"));
  }
  if (kind == MatcherKind::kSgm && block_size != 3 && block_size != 5 && block_size != 7) {
    return absl::InvalidArgumentError(
        absl::StrCat(f, ".block_size is ", block_size,
                     "; the sgm matcher's census window is 3, 5 or 7 pixels square"));
  }
  if (kind == MatcherKind::kOpenCvBm && block_size < 5) {
    return absl::InvalidArgumentError(
        absl::StrCat(f, ".block_size is ", block_size, "; OpenCV's StereoBM (bm) needs >= 5"));
  }
  if (kind == MatcherKind::kSgm) {
    const int max_p2 = sgm::kMaxPathCost - MaxCensusCost(block_size);
    if (p1 != 0) {
      if (absl::Status s = check::InRange(f + ".p1", p1, 1, max_p2 - 1); !s.ok()) return s;
    }
    if (p2 != 0) {
      if (absl::Status s = check::InRange(f + ".p2", p2, EffectiveP1() + 1, max_p2); !s.ok()) {
        return absl::InvalidArgumentError(
            absl::StrCat(s.message(), " (the sgm matcher: above p1, and at most ",
                         sgm::kMaxPathCost, " minus its largest cost ", MaxCensusCost(block_size),
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
  }
  if (absl::Status s = check::InRange(f + ".uniqueness_ratio", uniqueness_ratio, 0, 99); !s.ok()) {
    return s;
  }
  if (absl::Status s = check::InRange(f + ".speckle_window_size", speckle_window_size, 0,
                                      static_cast<std::int64_t>(Limits{}.max_pixels));
      !s.ok()) {
    return s;
  }
  if (absl::Status s = check::InRange(f + ".speckle_range", speckle_range, 0, kMaxDisparity);
      !s.ok()) {
    return s;
  }
  if (disp12_max_diff > kMaxDisparity) {
    return absl::InvalidArgumentError(absl::StrCat(f, ".disp12_max_diff is ", disp12_max_diff,
                                                   "; it must be at most ", kMaxDisparity,
                                                   " (< 0 turns the check off)"));
  }
  if (paths != 4 && paths != 8) {
    return absl::InvalidArgumentError(absl::StrCat(f, ".paths is ", paths, "; it must be 4 or 8"));
  }
  if (Name(simd) == "?") {
    return absl::InvalidArgumentError(
        absl::StrCat(f, ".simd is not a known level (", static_cast<int>(simd), ")"));
  }
  if (!CpuSupports(simd)) {
    return absl::FailedPreconditionError(
        absl::StrCat(f, ".simd is ", S(Name(simd)), "; this CPU (or build) lacks it"));
  }
  return absl::OkStatus();
}

// Ours: chosen on New Tsukuba and Aloe (docs/stereo.md, "Choosing the defaults").
int MatcherParams::EffectiveP1() const {
  if (p1 != 0) return p1;
  if (kind != MatcherKind::kSgm) return 8 * block_size * block_size;
  return block_size == 3 ? 3 : block_size == 5 ? 5 : 4;
}

int MatcherParams::EffectiveP2() const {
  if (p2 != 0) return p2;
  if (kind != MatcherKind::kSgm) return 32 * block_size * block_size;
  return block_size == 3 ? 16 : 19;
}

int MaxCensusCost(int block_size) {
  const int bits = sgm::CensusBits(CensusRadius(block_size));
  return bits > 12 ? (bits + 1) / 2 : bits;
}

DisparityView DisparityMap16::view() const {
  DisparityView v;
  v.data = values.data();
  v.size_bytes = values.size() * sizeof(std::uint16_t);
  v.width = width;
  v.height = height;
  v.stride_bytes = static_cast<std::size_t>(width) * sizeof(std::uint16_t);
  v.encoding = DisparityEncoding::kU16;
  return v;
}

CameraModel ForMatcherOutput(CameraModel camera) {
  camera.disparity_scale = kDisparityScale;
  camera.disparity_offset = 0.0;
  camera.invalid_disparities = {0.0};
  return camera;
}

Matcher::~Matcher() = default;

absl::Status CheckPair(const GreyView& left, const GreyView& right) {
  for (auto [view, name] : {std::pair{&left, "left"}, std::pair{&right, "right"}}) {
    if (absl::Status s = ValidateView(*view, Limits{}, name); !s.ok()) return s;
    if (view->encoding != ColorEncoding::kMono8) {
      return absl::InvalidArgumentError(
          absl::StrCat(name, ".encoding is ", S(Name(view->encoding)),
                       "; the matchers take mono8 (stereo::ToGrey converts)"));
    }
  }
  if (left.width != right.width || left.height != right.height) {
    return absl::InvalidArgumentError(absl::StrCat("right is ", right.width, "x", right.height,
                                                   " but left is ", left.width, "x", left.height,
                                                   "; they must be the same size"));
  }
  return absl::OkStatus();
}

absl::Status CheckVolume(std::uint32_t width, std::uint32_t height, int disparities,
                         int bytes_per_cost, std::string_view who) {
  const std::uint64_t bytes = std::uint64_t{width} * height * disparities * bytes_per_cost;
  if (bytes > kMaxCostVolumeBytes) {
    return absl::ResourceExhaustedError(
        absl::StrCat("left is ", width, "x", height, ": with ", disparities, " disparities ",
                     S(who), " would need ", bytes >> 20, " MiB of costs, over its limit of ",
                     kMaxCostVolumeBytes >> 20, " MiB"));
  }
  return absl::OkStatus();
}

absl::StatusOr<std::unique_ptr<Matcher>> MakeMatcher(const MatcherParams& params) {
  if (absl::Status s = params.Validate(); !s.ok()) return s;
  if (params.kind == MatcherKind::kSgm) return MakeSgmMatcher(params, params.simd);
  return MakeOpenCvMatcher(params);
}

}  // namespace cloudcast::stereo
