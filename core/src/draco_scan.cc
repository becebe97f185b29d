// ScanForDraco in plain C++: the extent EncodeDraco's cap and libdraco's quantization start from,
// on architectures without the SSE2 scan (draco_sequential_encoder.cc). Its comparisons are that
// scan's, so that the same points give the same extent bit for bit (draco_test holds them equal).
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <limits>

#include "draco_sequential_encoder.h"

namespace cloudcast::internal {

DracoCloudExtent ScanForDracoPortable(const Point* points, std::size_t n) {
  DracoCloudExtent e;
  const float inf = std::numeric_limits<float>::infinity();
  for (int c = 0; c < 3; ++c) {
    e.lo[c] = inf;
    e.hi[c] = -inf;
  }
  if (n == 0) return e;
  constexpr std::uint32_t kExponent = 0x7F800000;  // all ones: inf or NaN
  for (std::size_t i = 0; i < n; ++i) {
    const Point& p = points[i];
    const float v[3] = {p.x, p.y, p.z};
    bool finite = true;
    for (float f : v) {
      std::uint32_t bits;
      std::memcpy(&bits, &f, sizeof bits);
      finite = finite && (bits & kExponent) != kExponent;
    }
    if (!finite) continue;
    for (int c = 0; c < 3; ++c) {
      // Draco's "if (min > v) min = v": an equal value (0.0 after -0.0) never replaces the first.
      if (v[c] < e.lo[c]) e.lo[c] = v[c];
      if (v[c] > e.hi[c]) e.hi[c] = v[c];
    }
    const std::uint8_t channels[3] = {static_cast<std::uint8_t>(p.rgba & 0xFF),
                                      static_cast<std::uint8_t>((p.rgba >> 8) & 0xFF),
                                      static_cast<std::uint8_t>((p.rgba >> 16) & 0xFF)};
    e.color_lo = std::min({e.color_lo, channels[0], channels[1], channels[2]});
    e.color_hi = std::max({e.color_hi, channels[0], channels[1], channels[2]});
    ++e.finite;
  }
  return e;
}

#if !defined(__x86_64__) || !defined(__SSE2__)
DracoCloudExtent ScanForDraco(const Point* points, std::size_t n) {
  return ScanForDracoPortable(points, n);
}
#endif

}  // namespace cloudcast::internal
