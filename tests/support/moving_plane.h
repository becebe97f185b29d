// A disparity map and colour image of a tilted, textured plane that moves a little each frame (so
// that a video encoder's P pictures have motion to code): disparities 20 to 40, 8-bit, for the
// video tests that need consecutive frames of a known scene.
#pragma once

#include <cmath>
#include <cstdint>

#include "cloudcast/io/image_io.h"

namespace cloudcast::testing {

struct MovingPlaneFrame {
  OwnedDisparity disparity;
  OwnedColor colour;
};

// Frame `t` (0, 1, ...) at `w` x `h`.
inline MovingPlaneFrame MovingPlane(std::uint32_t w, std::uint32_t h, int t) {
  MovingPlaneFrame f;
  f.disparity.width = f.colour.width = w;
  f.disparity.height = f.colour.height = h;
  f.disparity.encoding = DisparityEncoding::kU8;
  f.colour.encoding = ColorEncoding::kBGR8;
  f.disparity.pixels.resize(std::size_t{w} * h);
  f.colour.pixels.resize(std::size_t{w} * h * 3);
  for (std::uint32_t v = 0; v < h; ++v) {
    for (std::uint32_t u = 0; u < w; ++u) {
      f.disparity.pixels[v * w + u] = static_cast<std::uint8_t>(20 + 20 * v / h);
      const double x = u + 2.0 * t;
      std::uint8_t* p = &f.colour.pixels[(std::size_t{v} * w + u) * 3];
      p[0] = static_cast<std::uint8_t>(128 + 100 * std::sin(x * 0.05) * std::cos(v * 0.04));
      p[1] = static_cast<std::uint8_t>(128 + 90 * std::cos(x * 0.031 + v * 0.017));
      p[2] = static_cast<std::uint8_t>(((u / 16 + v / 16 + t / 4) % 2) ? 200 : 60);
    }
  }
  return f;
}

}  // namespace cloudcast::testing
