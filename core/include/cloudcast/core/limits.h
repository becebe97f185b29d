// The one set of size limits. Every frame is checked against them before it is touched.
#pragma once

#include <cstdint>

namespace cloudcast {

struct Limits {
  // Largest accepted image side, in pixels.
  std::uint32_t max_side = 16384;
  // Largest accepted width x height. 2^24 pixels (e.g. 4096x4096) keeps per-voxel colour sums
  // exact in 32 bits and one organized cloud under 256 MiB.
  std::uint64_t max_pixels = std::uint64_t{1} << 24;
  // Largest matching work of a stereo pair the server matches, width x (height + 8 x block_size)
  // x num_disparities (stereo::MatchVolume: the cost cells a matcher visits, which bounds its
  // time; its memory is charged apart, stereo::MatchWorkBytes). 2^27 takes 1280x720 with 128
  // disparities and block 5 (640x480: 43 million).
  std::uint64_t max_stereo_volume = std::uint64_t{1} << 27;
};

}  // namespace cloudcast
