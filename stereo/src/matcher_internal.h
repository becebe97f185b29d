// What the matchers share inside cloudcast_stereo: the checks of a pair of views, and the
// factories MakeMatcher dispatches to.
#pragma once

#include <cstdint>
#include <memory>
#include <string_view>

#include "absl/status/status.h"
#include "cloudcast/stereo/matcher.h"

namespace cloudcast::stereo {

// Both views valid (Limits{}), kMono8, and the same size. Errors name "left" or "right".
absl::Status CheckPair(const GreyView& left, const GreyView& right);

// RESOURCE_EXHAUSTED when a frame of width x height would need more than kMaxCostVolumeBytes
// for `bytes_per_cost` bytes per pixel and disparity (`who` names the matcher in the message).
absl::Status CheckVolume(std::uint32_t width, std::uint32_t height, int disparities,
                         int bytes_per_cost, std::string_view who);

// Census radius of our matcher for a block size (3, 5, 7 -> 1, 2, 3).
inline int CensusRadius(int block_size) { return block_size / 2; }
// Its largest cost: the census bits (4, 12), halved for the 24 of a 7x7 window (sgm_kernels.h).
int MaxCensusCost(int block_size);

std::unique_ptr<Matcher> MakeSgmMatcher(const StereoParams& params, SimdLevel level);
std::unique_ptr<Matcher> MakeOpenCvMatcher(const StereoParams& params);

}  // namespace cloudcast::stereo
