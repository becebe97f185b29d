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
};

}  // namespace cloudcast
