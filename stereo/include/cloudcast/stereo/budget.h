// What matching one stereo pair costs, known from its size and parameters alone, before a pixel is
// read: whether the matcher can take the pair at all, the memory it allocates, and the work it
// does. The server charges a frame with these before it queues it (--work-memory-mb,
// ServerLimits.max_stereo_volume); one place, next to the matchers whose buffers it describes.
//
// The OpenCV figures come from OpenCV 4.6.0's sources (calib3d/src/stereosgbm.cpp and
// stereobm.cpp, one thread) and are upper bounds on what compute() requests; ours from
// sgm_matcher.cc's buffers. stereo_budget_test measures each matcher's peak and holds the
// estimates to it: never below, and not far above.
#pragma once

#include <cstdint>
#include <string_view>

#include "absl/status/status.h"
#include "cloudcast/core/stereo.h"

namespace cloudcast::stereo {

// OK when `params`' matcher can match a `width` x `height` pair. OpenCV's need some left pixel
// with its block and whole disparity range in the right image, width - num_disparities -
// |min_disparity| above block_size (below it its SGBM modes read out of bounds, crash, or abort
// from a destructor: no exception to catch), and StereoBM a block below the height. Ours takes
// any size.
// INVALID_ARGUMENT naming `field`'s member otherwise (e.g. "config.stereo.num_disparities").
absl::Status CheckMatchable(const StereoParams& params, std::uint32_t width, std::uint32_t height,
                            std::string_view field);

// The bytes the matcher allocates for one pair (its buffers, its output, the speckle filter), an
// upper bound. The grey images and the disparity map the server keeps are not in it.
std::uint64_t MatchWorkBytes(const StereoParams& params, std::uint32_t width,
                             std::uint32_t height);

// The matcher's work, in cost cells: width x (height + 8 x block_size) x num_disparities. OpenCV's
// SGBM modes sum a block's rows before each stripe, so a 255-pixel block over few rows costs 30
// times the plain volume (4096x16 with 2048 disparities: 0.34 s at block 5, 11.7 s at 255).
std::uint64_t MatchVolume(const StereoParams& params, std::uint32_t width, std::uint32_t height);

}  // namespace cloudcast::stereo
