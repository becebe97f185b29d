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
  // Largest width x height x num_disparities of a stereo pair the server matches: the matchers'
  // cost volume (ours keeps a byte per entry, OpenCV's MODE_HH two). 2^27 takes 1280x720 with 128
  // disparities (640x480: 39 million) and bounds a worker's matcher to 128 MiB.
  std::uint64_t max_stereo_volume = std::uint64_t{1} << 27;
};

}  // namespace cloudcast
