// The SIMD kernels, written once over a vector policy and instantiated by sgm_avx2.cc (32-byte
// vectors) and sgm_avx512.cc (64-byte vectors). Each computes exactly what sgm_scalar.cc does
// (sgm_kernels.h has the formulas).
//
// The vector policy V (of bytes) provides:
//   T, kLanes, Zero, Set1, Load, Store, StoreStream (past the caches) and StreamFence;
//   AddSat, SubSat, Min, Max, Add8, Xor, Or, HalveUp ((a + 1) >> 1);
//   kPlaneBits and the census cost: 4, nibble planes, Lookup (pshufb with a 16-byte table in each
//   128-bit lane) in NibbleCounts; 8, byte planes, PopCount;
//   PushBit (acc * 2 + (a > b) per signed byte), HMin (the smallest byte);
//   ShiftInBelow(a, b) (b moved up one lane, a's last lane in lane 0), ShiftInAbove(a, b) (a moved
//   down one lane, b's lane 0 in the last), FirstLane255 and LastLane255 (255 in that lane only);
//   EqMask(a, b) and LessEqMask(a, b) (unsigned a <= b): one bit per lane, lane 0 lowest;
//   UnpackLo8 and UnpackHi8 (bytes interleaved into 16-bit lanes, as punpcklbw / punpckhbw),
//   Min16 and HMin16 (unsigned 16-bit);
//   RowMinima(vectors, n, minima): minima[x] = the smallest byte of vector x (kLanes bytes at
//   vectors + x * kLanes) for x in [0, RoundUp(n, kLanes)).
//
// Include only from a file compiled with the matching instruction-set flags. Everything here has
// internal linkage (the anonymous namespace), so no AVX code is shared with other files (see
// sgm_kernels.h).
#pragma once

#include <cstddef>
#include <cstdint>

#include "sgm_kernels.h"

namespace cloudcast::stereo::sgm::simd {
namespace {  // NOLINT(google-build-namespaces): per instruction set, by design

// ---- census -------------------------------------------------------------------------------------

template <class V, int kRadius>
void CensusT(const CensusArgs& a) {
  using T = typename V::T;
  constexpr int kBits = CensusBits(kRadius);
  constexpr int kPlanes = (kBits + V::kPlaneBits - 1) / V::kPlaneBits;
  const std::ptrdiff_t stride = static_cast<std::ptrdiff_t>(a.stride);
  // The pixel pairs in the scalar kernel's order, as offsets from the centre.
  std::ptrdiff_t first[kBits], second[kBits];
  int n = 0;
  for (int dy = -kRadius; dy <= 0; ++dy) {
    for (int dx = -kRadius; dx <= kRadius; ++dx) {
      if (dy == 0 && dx >= 0) break;
      const int e = a.mirrored ? -dx : dx;
      first[n] = dy * stride + e;
      second[n] = -dy * stride - e;
      ++n;
    }
  }
  // Columns are computed a vector at a time, the last vector past the width: the padded image and
  // the planes have room for it (sgm_matcher.cc).
  for (int y = 0; y < a.height; ++y) {
    const std::int8_t* row = a.padded + (y + kRadius) * stride + kRadius;
    const std::size_t out = static_cast<std::size_t>(y) * a.plane_stride;
    for (int x = 0; x < a.width; x += V::kLanes) {
      const std::int8_t* c = row + x;
      T acc[kPlanes];
      for (int j = 0; j < kPlanes; ++j) acc[j] = V::Zero();
      for (int i = 0; i < kBits; ++i) {
        // Bit kBits - 1 - i of the code, pushed most significant first.
        const int plane = (kBits - 1 - i) / V::kPlaneBits;
        acc[plane] = V::PushBit(acc[plane], V::Load(c + first[i]), V::Load(c + second[i]));
      }
      for (int j = 0; j < kPlanes; ++j) V::Store(a.planes[j] + out + x, acc[j]);
    }
  }
}

// ---- aggregation --------------------------------------------------------------------------------

// A step from a predecessor stored long ago (the previous row): its neighbours come from loads at
// k - 1 and k + 1, which read the next block's first and the previous block's last cost at the
// ends; those lanes are made 255 (no neighbour there).
template <class V>
inline typename V::T Step(typename V::T c, const std::uint8_t* pred, int chunk, int chunks,
                          typename V::T p1, typename V::T pred_min, typename V::T jump,
                          std::uint8_t* out, typename V::T* min, std::ptrdiff_t offset) {
  using T = typename V::T;
  const std::ptrdiff_t k = chunk * V::kLanes + offset;
  const T here = V::Load(pred + k);
  T below = V::Load(pred + k - 1);
  T above = V::Load(pred + k + 1);
  if (chunk == 0) below = V::Or(below, V::FirstLane255());
  if (chunk + 1 == chunks) above = V::Or(above, V::LastLane255());
  T v = V::Min(here, V::AddSat(V::Min(below, above), p1));
  v = V::Min(v, jump);
  const T l = V::AddSat(c, V::SubSat(v, pred_min));
  V::Store(out + k, l);
  *min = V::Min(*min, l);
  return l;
}

// 0, 1, ..., 255: the indices of kPackedChoice.
alignas(64) constexpr std::uint8_t kIndices[256] = {
    0,   1,   2,   3,   4,   5,   6,   7,   8,   9,   10,  11,  12,  13,  14,  15,  16,  17,  18,
    19,  20,  21,  22,  23,  24,  25,  26,  27,  28,  29,  30,  31,  32,  33,  34,  35,  36,  37,
    38,  39,  40,  41,  42,  43,  44,  45,  46,  47,  48,  49,  50,  51,  52,  53,  54,  55,  56,
    57,  58,  59,  60,  61,  62,  63,  64,  65,  66,  67,  68,  69,  70,  71,  72,  73,  74,  75,
    76,  77,  78,  79,  80,  81,  82,  83,  84,  85,  86,  87,  88,  89,  90,  91,  92,  93,  94,
    95,  96,  97,  98,  99,  100, 101, 102, 103, 104, 105, 106, 107, 108, 109, 110, 111, 112, 113,
    114, 115, 116, 117, 118, 119, 120, 121, 122, 123, 124, 125, 126, 127, 128, 129, 130, 131, 132,
    133, 134, 135, 136, 137, 138, 139, 140, 141, 142, 143, 144, 145, 146, 147, 148, 149, 150, 151,
    152, 153, 154, 155, 156, 157, 158, 159, 160, 161, 162, 163, 164, 165, 166, 167, 168, 169, 170,
    171, 172, 173, 174, 175, 176, 177, 178, 179, 180, 181, 182, 183, 184, 185, 186, 187, 188, 189,
    190, 191, 192, 193, 194, 195, 196, 197, 198, 199, 200, 201, 202, 203, 204, 205, 206, 207, 208,
    209, 210, 211, 212, 213, 214, 215, 216, 217, 218, 219, 220, 221, 222, 223, 224, 225, 226, 227,
    228, 229, 230, 231, 232, 233, 234, 235, 236, 237, 238, 239, 240, 241, 242, 243, 244, 245, 246,
    247, 248, 249, 250, 251, 252, 253, 254, 255};

// How far ahead the backward pass asks for S1.
constexpr int kPrefetchPixels = 8;

// Per pixel, the vectors of its disparities: kChunks when the count is known at compile time (the
// loops then unroll and the edge tests vanish), else dp / kLanes.
template <class V, int kChunks>
inline int Chunks(const Shape& s) {
  return kChunks > 0 ? kChunks : s.dp / V::kLanes;
}

// The horizontal path's predecessor is the pixel just done, whose costs were stored a moment ago:
// loading them at k - 1 and k + 1 (unaligned) would wait for the stores to reach the cache (a
// blocked store forward, measured at a third of the forward pass). So its neighbours come from
// aligned loads of the whole vectors, shifted by one lane in registers.
template <class V>
inline typename V::T HorizontalStep(typename V::T c, const std::uint8_t* pred, int chunk,
                                    int chunks, typename V::T p1, typename V::T pred_min,
                                    typename V::T jump, std::uint8_t* out, typename V::T* min) {
  using T = typename V::T;
  const int k = chunk * V::kLanes;
  const T guard = V::Set1(255);
  const T here = V::Load(pred + k);
  const T before = chunk > 0 ? V::Load(pred + k - V::kLanes) : guard;
  const T after = chunk + 1 < chunks ? V::Load(pred + k + V::kLanes) : guard;
  const T below = V::ShiftInBelow(before, here);  // lane i: pred[k + i - 1]
  const T above = V::ShiftInAbove(here, after);   // lane i: pred[k + i + 1]
  T v = V::Min(here, V::AddSat(V::Min(below, above), p1));
  v = V::Min(v, jump);
  const T l = V::AddSat(c, V::SubSat(v, pred_min));
  V::Store(out + k, l);
  *min = V::Min(*min, l);
  return l;
}

// The winner of pixel x's totals t, whose minimum is m (Choice), with selects instead of branches
// on the data: where the minimum lies is a coin toss for the branch predictor. Over dp (its
// padding holds 255: never the minimum, never under a limit).
// The lowest index holding m in pixel x's totals t: the first chunk with a bit, scanned from the
// end.
template <class V, int kChunks>
inline int LowestIndexOf(const Shape& s, const std::uint8_t* t, int m) {
  using T = typename V::T;
  const int chunks = Chunks<V, kChunks>(s);
  const T mb = V::Set1(static_cast<std::uint8_t>(m));
  int best = 0;
  for (int c = chunks - 1; c >= 0; --c) {
    const std::uint64_t e = V::EqMask(V::Load(t + c * V::kLanes), mb);
    // (bit 63 set keeps ctz defined; it changes nothing where a lower bit is set)
    const int first = static_cast<int>(__builtin_ctzll(e | (std::uint64_t{1} << 63)));
    best = e != 0 ? c * V::kLanes + first : best;
  }
  return best;
}

// Where every index fits a byte (dp <= 256), the minimum and its lowest index come out of one
// reduction: each total becomes total * 256 + index in 16 bits (an unpack with the indices), and
// the smallest of those is the smallest total at its lowest index.
template <class V, int kChunks>
constexpr bool kPackedChoice = kChunks > 0 && kChunks* V::kLanes <= 256;

template <class V, int kChunks>
inline void ChoosePixel(const RowArgs& a, int x, const std::uint8_t* t, int m, int best) {
  using T = typename V::T;
  const int chunks = Chunks<V, kChunks>(*a.shape);
  const int limit = a.choice.limits[m];
  // Any total <= limit, the best and its two neighbours aside (limit < 0: none).
  const T lb = V::Set1(static_cast<std::uint8_t>(MaxInt(limit, 0)));
  std::uint64_t any = 0;
  for (int c = 0; c < chunks; ++c) {
    const std::uint64_t under = V::LessEqMask(V::Load(t + c * V::kLanes), lb);
    const int shift = best - 1 - c * V::kLanes;  // bit of best - 1 in this chunk
    const std::uint64_t exempt = shift >= 0 ? (shift < 64 ? std::uint64_t{7} << shift : 0)
                                            : (shift >= -2 ? std::uint64_t{7} >> -shift : 0);
    any |= under & ~exempt;
  }
  Choose(*a.shape, a.choice, x, t, m, best, limit < 0 || any == 0);
}

// What a row's loop needs, copied out of RowArgs into locals: a byte store may alias anything
// reached through a pointer, so the compiler would otherwise reload these after every store.
template <int kPlanes>
struct RowContext {
  const std::uint8_t* left[kPlanes];
  const std::uint8_t* right[kPlanes];
  const std::uint8_t* pad;
  Floors floors;
  const Shape* shape;
  int width, dmin, dp;
  std::ptrdiff_t block;
  const std::uint8_t* prev;
  std::uint8_t* cur;
  const std::uint8_t* prev_minima[4];
  std::uint8_t* cur_minima0;
  std::uint8_t* s1;
  std::uint8_t* totals;
  std::uint8_t* min_vectors;
  std::size_t min_vectors_stride;
  const RowArgs* args;
};

// One pixel, all its disparities, in a pass walking x in direction kStep: the costs, the paths
// (path j's predecessor at pixel x - kStep for the horizontal (this row) and the first diagonal,
// x for the vertical, x + kStep for the other diagonal, in the previous row), then forward S1 =
// their sum, backward the totals = S1 + their sum and the choice.
template <class V, int kPlanes, int kPaths, bool kForward, int kChunks>
inline void Pixel(const RowContext<kPlanes>& c, int x, typename V::T p1, typename V::T p2,
                  typename V::T counts) {
  using T = typename V::T;
  constexpr std::ptrdiff_t kStep = kForward ? 1 : -1;
  const int chunks = kChunks > 0 ? kChunks : c.dp / V::kLanes;
  const std::ptrdiff_t dp = chunks * V::kLanes;  // a constant when kChunks is
  const std::ptrdiff_t block = kChunks > 0 ? kPaths * dp : c.block;
  const PixelFloors f = FloorsFor(*c.shape, c.floors, x);
  const int base = c.width - 1 - x + c.dmin;
  std::uint8_t* out = c.cur + x * block;
  const std::uint8_t* prev = c.prev + x * block;
  // The blocks of the paths' predecessors; path i's costs are at + i * dp in them.
  const std::uint8_t* pred[4] = {out - kStep * block, prev, prev - kStep * block,
                                 prev + kStep * block};
  const std::uint8_t pred_min_bytes[4] = {c.cur_minima0[x - kStep], c.prev_minima[1][x],
                                          c.prev_minima[2][x - kStep], c.prev_minima[3][x + kStep]};
  T left[kPlanes];
  for (int j = 0; j < kPlanes; ++j) left[j] = V::Set1(c.left[j][x]);
  T pred_min[kPaths], jump[kPaths], min[kPaths];
  for (int i = 0; i < kPaths; ++i) {
    pred_min[i] = V::Set1(pred_min_bytes[i]);
    jump[i] = V::AddSat(pred_min[i], p2);
    min[i] = V::Set1(255);
  }
  std::uint8_t* s1 = c.s1 + x * dp;
  // The forward pass has no totals (c.totals is null): offsetting a null pointer is undefined.
  std::uint8_t* totals = kForward ? nullptr : c.totals + x * dp;
  T total_min = V::Set1(255);
  T packed_min = V::Set1(255);  // kPackedChoice: 16-bit total * 256 + index
  if constexpr (!kForward) {
    // S1 comes from memory (the frame's sums, 39 MB at 640x480 with 128 disparities), and the
    // loads missed: ask for it kPrefetchPixels ahead of the row walk (right to left).
    if (x >= kPrefetchPixels) {
      const std::uint8_t* ahead = s1 - kPrefetchPixels * dp;
      for (std::ptrdiff_t k = 0; k < dp; k += 64) __builtin_prefetch(ahead + k);
    }
  }
  for (int chunk = 0; chunk < chunks; ++chunk) {
    const int k = chunk * V::kLanes;
    T cost = V::Zero();
    for (int j = 0; j < kPlanes; ++j) {
      const T differ = V::Xor(V::Load(c.right[j] + base + k), left[j]);
      if constexpr (V::kPlaneBits == 8) {
        cost = V::Add8(cost, V::PopCount(differ));
      } else {
        cost = V::Add8(cost, V::Lookup(counts, differ));
      }
    }
    // 24 bits (3 bytes or 6 nibbles): (c + 1) >> 1
    if constexpr (kPlanes == (V::kPlaneBits == 8 ? 3 : 6)) cost = V::HalveUp(cost);
    if (c.pad != nullptr) cost = V::Max(cost, V::Load(c.pad + k));
    if (f.left != nullptr) cost = V::Max(cost, V::Load(f.left + k));
    if (f.right != nullptr) cost = V::Max(cost, V::Load(f.right + k));
    T l[kPaths];
    l[0] = HorizontalStep<V>(cost, pred[0], chunk, chunks, p1, pred_min[0], jump[0], out, &min[0]);
    for (int i = 1; i < kPaths; ++i) {
      l[i] = Step<V>(cost, pred[i], chunk, chunks, p1, pred_min[i], jump[i], out, &min[i], i * dp);
    }
    T sum = V::AddSat(l[0], l[1]);
    if constexpr (kPaths == 4) sum = V::AddSat(sum, V::AddSat(l[2], l[3]));
    if constexpr (kForward) {
      V::StoreStream(s1 + k, sum);
    } else {
      T total = V::AddSat(sum, V::Load(s1 + k));
      if (f.left != nullptr) total = V::Max(total, V::Load(f.left + c.floors.total_offset + k));
      if (f.right != nullptr) total = V::Max(total, V::Load(f.right + c.floors.total_offset + k));
      V::Store(totals + k, total);
      if constexpr (kPackedChoice<V, kChunks>) {
        const T index = V::Load(kIndices + k);
        packed_min =
            V::Min16(packed_min, V::Min16(V::UnpackLo8(index, total), V::UnpackHi8(index, total)));
      } else {
        total_min = V::Min(total_min, total);
      }
    }
  }
  // The horizontal path's minimum is needed by the next pixel; the others' by the next row, so
  // those are reduced a row at a time (RowMinima), far cheaper than one by one.
  c.cur_minima0[x] = V::HMin(min[0]);
  for (int i = 1; i < kPaths; ++i) {
    V::Store(c.min_vectors + (i - 1) * c.min_vectors_stride + x * V::kLanes, min[i]);
  }
  if constexpr (!kForward) {
    if constexpr (kPackedChoice<V, kChunks>) {
      const int packed = V::HMin16(packed_min);
      ChoosePixel<V, kChunks>(*c.args, x, totals, packed >> 8, packed & 255);
    } else {
      const int m = V::HMin(total_min);
      ChoosePixel<V, kChunks>(*c.args, x, totals, m,
                              LowestIndexOf<V, kChunks>(*c.shape, totals, m));
    }
  }
}

// A row in either direction; dp is a multiple of V's lanes.
template <class V, int kPlanes, int kPaths, bool kForward, int kChunks>
void RowT(const RowArgs& a) {
  RowContext<kPlanes> c;
  for (int j = 0; j < kPlanes; ++j) {
    c.left[j] = a.left[j];
    c.right[j] = a.right[j];
  }
  c.pad = a.floors.pad;
  c.floors = a.floors;
  c.shape = a.shape;
  c.width = a.shape->width;
  c.dmin = a.shape->dmin;
  c.dp = a.shape->dp;
  c.block = static_cast<std::ptrdiff_t>(a.shape->block);
  c.prev = a.prev.costs;
  c.cur = a.cur.costs;
  for (int j = 0; j < 4; ++j) c.prev_minima[j] = a.prev.minima[j];
  c.cur_minima0 = a.cur.minima[0];
  c.s1 = a.s1;
  c.totals = a.totals;
  c.min_vectors = a.min_vectors;
  c.min_vectors_stride = a.min_vectors_stride;
  c.args = &a;
  const typename V::T p1 = V::Set1(a.p1), p2 = V::Set1(a.p2), counts = V::NibbleCounts();
  for (int i = 0; i < c.width; ++i) {
    Pixel<V, kPlanes, kPaths, kForward, kChunks>(c, kForward ? i : c.width - 1 - i, p1, p2, counts);
  }
  for (int j = 1; j < kPaths; ++j) {
    V::RowMinima(a.min_vectors + (j - 1) * a.min_vectors_stride, c.width, a.cur.minima[j]);
    a.cur.minima[j][c.width] = 0;  // the zero predecessor's, overwritten by the rounding
  }
  if constexpr (kForward) V::StreamFence();
}

template <class V, int kPlanes, int kPaths, bool kForward>
void RowForChunks(const RowArgs& a) {
  // (kChunks > 0 makes dp, the block and every path's offset constants.)
  switch (a.shape->dp / V::kLanes) {
    case 1:
      return RowT<V, kPlanes, kPaths, kForward, 1>(a);
    case 2:
      return RowT<V, kPlanes, kPaths, kForward, 2>(a);
    case 3:
      return RowT<V, kPlanes, kPaths, kForward, 3>(a);
    case 4:
      return RowT<V, kPlanes, kPaths, kForward, 4>(a);
    default:
      return RowT<V, kPlanes, kPaths, kForward, 0>(a);
  }
}

template <class V, int kPlanes, bool kForward>
void RowForPaths(const RowArgs& a) {
  return a.paths == 4 ? RowForChunks<V, kPlanes, 4, kForward>(a)
                      : RowForChunks<V, kPlanes, 2, kForward>(a);
}

// Census planes per block size: nibbles 1, 3, 6; bytes 1, 2, 3.
template <class V, bool kForward>
void Row(const RowArgs& a) {
  constexpr bool kBytes = V::kPlaneBits == 8;
  switch (a.shape->census_bits) {
    case 4:
      return RowForPaths<V, 1, kForward>(a);
    case 12:
      return RowForPaths < V, kBytes ? 2 : 3, kForward > (a);
    default:
      return RowForPaths < V, kBytes ? 3 : 6, kForward > (a);
  }
}

template <class V>
void Census(const CensusArgs& a) {
  switch (a.radius) {
    case 1:
      return CensusT<V, 1>(a);
    case 2:
      return CensusT<V, 2>(a);
    default:
      return CensusT<V, 3>(a);
  }
}

}  // namespace
}  // namespace cloudcast::stereo::sgm::simd
