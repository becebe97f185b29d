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

constexpr SimdLevel kLevels[] = {SimdLevel::kAuto, SimdLevel::kScalar, SimdLevel::kAvx2,
                                 SimdLevel::kAvx512};

}  // namespace

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

int MaxCensusCost(int block_size) {
  const int bits = sgm::CensusBits(CensusRadius(block_size));
  return bits > 12 ? (bits + 1) / 2 : bits;
}

// Core's bound on p2 is the kernels' own.
static_assert(sgm::kMaxPathCost == kSgmMaxPathCost);

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

absl::StatusOr<std::unique_ptr<Matcher>> MakeMatcher(const StereoParams& params, SimdLevel simd) {
  if (absl::Status s = params.Validate(); !s.ok()) return s;
  if (Name(simd) == "?") {
    return absl::InvalidArgumentError(
        absl::StrCat("simd is not a known level (", static_cast<int>(simd), ")"));
  }
  if (!CpuSupports(simd)) {
    return absl::FailedPreconditionError(
        absl::StrCat("simd is ", S(Name(simd)), "; this CPU (or build) lacks it"));
  }
  if (MaxCensusCost(params.block_size) != SgmMaxCensusCost(params.block_size)) {
    return absl::InternalError("stereo: core's SgmMaxCensusCost disagrees with the kernels");
  }
  if (params.matcher == StereoMatcher::kSgm) return MakeSgmMatcher(params, simd);
  return MakeOpenCvMatcher(params);
}

}  // namespace cloudcast::stereo
