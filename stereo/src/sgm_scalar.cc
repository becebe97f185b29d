// The scalar kernels: the reference the SIMD ones must equal bit for bit, and the fallback for a
// CPU without AVX2. Written to read like the formulas in sgm_kernels.h.
#include <algorithm>
#include <cstdlib>
#include <cstring>

#include "sgm_kernels.h"

namespace cloudcast::stereo::sgm {
namespace {

inline std::uint8_t AddSat(int a, int b) { return static_cast<std::uint8_t>(std::min(a + b, 255)); }

void Census(const CensusArgs& a) {
  const int r = a.radius;
  const int bits = CensusBits(r);
  const int planes = (bits + a.plane_bits - 1) / a.plane_bits;
  const std::uint32_t mask = (1u << a.plane_bits) - 1;
  const std::ptrdiff_t stride = static_cast<std::ptrdiff_t>(a.stride);
  for (int y = 0; y < a.height; ++y) {
    for (int x = 0; x < a.width; ++x) {
      const std::int8_t* c = a.padded + (y + r) * stride + x + r;
      std::uint32_t code = 0;
      for (int dy = -r; dy <= 0; ++dy) {
        for (int dx = -r; dx <= r; ++dx) {
          if (dy == 0 && dx >= 0) break;
          const int e = a.mirrored ? -dx : dx;
          code = (code << 1) | (c[dy * stride + e] > c[-dy * stride - e] ? 1u : 0u);
        }
      }
      for (int j = 0; j < planes; ++j) {
        a.planes[j][static_cast<std::size_t>(y) * a.plane_stride + x] =
            static_cast<std::uint8_t>((code >> (a.plane_bits * j)) & mask);
      }
    }
  }
}

// Pixel x's costs C(x, k) for k in [0, dp), floors applied.
void Costs(const RowArgs& a, int x, std::uint8_t* c) {
  const Shape& s = *a.shape;
  const int base = s.width - 1 - x + s.dmin;
  const PixelFloors f = FloorsFor(s, a.floors, x);
  // Bits set in a nibble: the baseline x86-64 this file is compiled for has no popcnt.
  static constexpr std::uint8_t kBits[16] = {0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4};
  for (int k = 0; k < s.dp; ++k) {
    int v = 0;
    for (int j = 0; j < s.planes; ++j) v += kBits[(a.left[j][x] ^ a.right[j][base + k]) & 15];
    if (s.census_bits > 12) v = (v + 1) >> 1;  // 24 bits: halved, rounding up
    if (a.floors.pad != nullptr) v = std::max<int>(v, a.floors.pad[k]);
    if (f.left != nullptr) v = std::max<int>(v, f.left[k]);
    if (f.right != nullptr) v = std::max<int>(v, f.right[k]);
    c[k] = static_cast<std::uint8_t>(v);
  }
}

// One path step: costs `c` of this pixel, its predecessor's path costs `pred` with minimum
// `pred_min`, into `out`; returns out's minimum. Index -1 and dp count as 255 (no neighbour).
std::uint8_t PathStep(const std::uint8_t* c, const std::uint8_t* pred, std::uint8_t pred_min,
                      int dp, int p1, int p2, std::uint8_t* out) {
  const int jump = AddSat(pred_min, p2);
  // The predecessor between guards, so the loop has no tests (and the compiler vectorizes it).
  std::uint8_t g[kMaxDp + 2];
  g[0] = g[dp + 1] = 255;
  std::memcpy(g + 1, pred, dp);
  std::uint8_t m = 255;
  for (int k = 0; k < dp; ++k) {
    int v = std::min<int>(g[k + 1], AddSat(std::min(g[k], g[k + 2]), p1));
    v = std::min(v, jump);
    out[k] = AddSat(c[k], v - pred_min);
    m = std::min(m, out[k]);
  }
  return m;
}

// Path j at pixel x of a row (PathRow).
struct Paths {
  const RowArgs& a;
  std::uint8_t* costs(const PathRow& row, int x, int j) const {
    return row.costs + x * static_cast<std::ptrdiff_t>(a.shape->block) + j * a.shape->dp;
  }
  // One step of path j at pixel x, from its predecessor at column px of `from`, into this row.
  const std::uint8_t* Step(const std::uint8_t* c, const PathRow& from, int px, int j, int x) const {
    std::uint8_t* out = costs(a.cur, x, j);
    a.cur.minima[j][x] =
        PathStep(c, costs(from, px, j), from.minima[j][px], a.shape->dp, a.p1, a.p2, out);
    return out;
  }
};

// The paths of one pixel in a pass walking x in direction `step` (1 forward, -1 backward), their
// sum in `sum`.
void PixelPaths(const RowArgs& a, int x, int step, const std::uint8_t* c, std::uint8_t* sum) {
  const Shape& s = *a.shape;
  const Paths p{a};
  const std::uint8_t* h = p.Step(c, a.cur, x - step, 0, x);
  const std::uint8_t* v = p.Step(c, a.prev, x, 1, x);
  if (a.paths == 4) {
    const std::uint8_t* d1 = p.Step(c, a.prev, x - step, 2, x);
    const std::uint8_t* d2 = p.Step(c, a.prev, x + step, 3, x);
    for (int k = 0; k < s.dp; ++k) sum[k] = AddSat(AddSat(h[k], v[k]), AddSat(d1[k], d2[k]));
  } else {
    for (int k = 0; k < s.dp; ++k) sum[k] = AddSat(h[k], v[k]);
  }
}

void ForwardRow(const RowArgs& a) {
  const Shape& s = *a.shape;
  std::uint8_t c[kMaxDp];
  for (int x = 0; x < s.width; ++x) {
    Costs(a, x, c);
    PixelPaths(a, x, 1, c, a.s1 + static_cast<std::size_t>(x) * s.dp);
  }
}

// The winner of pixel x's totals t (Choice).
void ChooseAt(const RowArgs& a, int x, std::uint8_t* t) {
  const Shape& s = *a.shape;
  const PixelFloors f = FloorsFor(s, a.floors, x);
  for (int k = 0; k < s.d; ++k) {
    if (f.left != nullptr) t[k] = std::max(t[k], f.left[k + a.floors.total_offset]);
    if (f.right != nullptr) t[k] = std::max(t[k], f.right[k + a.floors.total_offset]);
  }
  int best = 0;
  int m = t[0];
  for (int k = 1; k < s.d; ++k) {
    if (t[k] < m) {
      m = t[k];
      best = k;
    }
  }
  const int limit = a.choice.limits[m];
  bool unique = true;
  for (int k = 0; k < s.d && unique; ++k) {
    if (std::abs(k - best) > 1 && t[k] <= limit) unique = false;
  }
  Choose(s, a.choice, x, t, m, best, unique);
}

void BackwardRow(const RowArgs& a) {
  const Shape& s = *a.shape;
  std::uint8_t c[kMaxDp], sum[kMaxDp];
  for (int x = s.width - 1; x >= 0; --x) {
    Costs(a, x, c);
    PixelPaths(a, x, -1, c, sum);
    const std::uint8_t* s1 = a.s1 + static_cast<std::size_t>(x) * s.dp;
    std::uint8_t* t = a.totals + static_cast<std::size_t>(x) * s.dp;
    for (int k = 0; k < s.dp; ++k) t[k] = AddSat(sum[k], s1[k]);
    ChooseAt(a, x, t);
  }
}

void CheckRow(const CheckArgs& a) {
  for (int x = 0; x < a.width; ++x) a.out[x] = CheckPixel(a, x);
}

}  // namespace

const Kernels& ScalarKernels() {
  static const Kernels k{"scalar", 32, 4, Census, ForwardRow, BackwardRow, CheckRow};
  return k;
}

}  // namespace cloudcast::stereo::sgm
