// The hot loops of our semi-global matcher, behind one table of function pointers per instruction
// set (scalar, AVX2, AVX-512BW). This header and the kernel files include no OpenCV, PCL or Eigen
// header: the SIMD files are compiled with AVX flags (see stereo/CMakeLists.txt).
//
// The algorithm (Hirschmueller's SGM, in the form of fixstars' libSGM and OpenCV's StereoSGBM):
//   cost      C(x, y, k): the Hamming distance of the centre-symmetric census codes of left pixel
//             (x, y) and right pixel (x - dmin - k, y), halved (rounding up) for the 24-bit codes
//             of a 7x7 window, so C <= max_cost <= 12; a right pixel outside the image costs
//             max_cost;
//   paths     L_r(p, k) = C(p, k) + min(L_r(p-r, k), L_r(p-r, k+-1) + P1, min_j L_r(p-r, j) + P2)
//                        - min_j L_r(p-r, j), in bytes;
//   passes    forward (rows top to bottom): left-to-right and down, with 8 paths also both down
//             diagonals; their sum S1 is kept for the frame. Backward (rows bottom to top):
//             right-to-left and up (and both up diagonals), summed with S1 into one row of totals;
//   choice    per pixel the smallest total (the lowest k of equal ones), refused when another k
//             more than 1 away costs less than (100 + uniqueness) % of it; then OpenCV's parabola
//             for the sub-pixel part, its left-right check and cv::filterSpeckles (sgm_matcher.cc).
//
// Everything stays in bytes, exactly: L <= C + P2 <= max_cost + P2 <= 31 (StereoParams bounds
// P2 so), hence a sum of 8 paths <= 248. The adds saturate only for the padding indices, which
// hold 255 throughout and never win.
//
// Every kernel computes exactly this, so all instruction sets give the same output bit for bit
// (tests/stereo_test.cc checks it).
//
// The inline helpers here are `static`, and use no std:: templates: a file compiled with AVX
// flags must not emit a shared (COMDAT) copy of a function that the linker could then hand to
// code running on a CPU without AVX.
#pragma once

#include <climits>
#include <cstddef>
#include <cstdint>

namespace cloudcast::stereo::sgm {

// Census planes: the census code of a pixel in `plane_bits` (4 or 8) pieces, plane j holding bits
// plane_bits * j and up in the low bits of one byte. The scalar and AVX2 kernels take nibbles (a
// Hamming distance is then one table look-up per plane, pshufb); the AVX-512 ones bytes (one
// vpopcntb per plane).
inline constexpr int kMaxPlanes = 6;  // a 7x7 window: 24 bits in nibbles
inline constexpr int kMaxRadius = 3;
inline constexpr int kMaxDp = 2048;  // kMaxDisparity (matcher.h), a multiple of 32

// Census bits of a square window of side 2 * radius + 1: one per pair of pixels mirrored through
// the centre.
static constexpr int CensusBits(int radius) { return 2 * radius * (radius + 1); }

// The geometry of one frame's matching.
struct Shape {
  int width = 0;
  int height = 0;
  int d = 0;            // disparities searched
  int dp = 0;           // d rounded up to the kernels' lanes (32 or 64): each cost vector's length
  int dmin = 0;         // disparity of index k = 0
  int census_bits = 0;  // 4, 12 or 24; 24 are halved into costs (sgm_kernels.h, top)
  int plane_bits = 4;   // the kernels' census planes: nibbles or bytes
  int planes = 0;       // census_bits / plane_bits, rounded up
  std::uint8_t max_cost = 0;  // the largest cost: that of a right pixel outside the image
  int paths = 4;              // path vectors per pixel in a path row (PathRow)
  std::size_t block = 0;      // bytes per pixel in a path row: paths * dp
};

// Largest path cost the bytes hold exactly: max_cost + P2 must not exceed it (8 paths: 248).
inline constexpr int kMaxPathCost = 31;

// Floors raise the cost of indices a pixel must not match: pad[k] is 255 for k >= d (the padding
// up to dp: such indices then always carry 255 and never win or lower a neighbour; null when
// dp == d); left and right are tables of 2 * dp bytes that, offset per pixel (FloorsFor), give
// max_cost for the indices whose right pixel falls off the image's left or right edge. Their
// twins at + total_offset hold kMaskedTotal instead, for the totals: such indices must not win.
struct Floors {
  const std::uint8_t* pad = nullptr;
  const std::uint8_t* left = nullptr;   // left[i] = i >= dp ? max_cost : 0
  const std::uint8_t* right = nullptr;  // right[i] = i < dp ? max_cost : 0
  std::ptrdiff_t total_offset = 0;
};

static inline int MinInt(int a, int b) { return a < b ? a : b; }
static inline int MaxInt(int a, int b) { return a > b ? a : b; }

// Indices k in [lo, hi] have their right pixel x - dmin - k inside the image (none when lo > hi).
static inline void ValidRange(const Shape& s, int x, int* lo, int* hi) {
  const int shift = x - s.dmin;  // the k whose right pixel is column 0
  *hi = MinInt(s.d - 1, shift);
  *lo = MaxInt(0, shift - (s.width - 1));
}

// Per pixel: null when every index is inside the image; else the tables to max with.
struct PixelFloors {
  const std::uint8_t* left = nullptr;
  const std::uint8_t* right = nullptr;
};
static inline PixelFloors FloorsFor(const Shape& s, const Floors& f, int x) {
  int lo, hi;
  ValidRange(s, x, &lo, &hi);
  PixelFloors p;
  if (hi < s.d - 1) p.left = f.left + (s.dp - 1 - MaxInt(hi, -1));  // k > hi: max_cost
  if (lo > 0) p.right = f.right + (s.dp - MinInt(lo, s.dp));        // k < lo: max_cost
  return p;
}

// The census of a padded image (border pixels replicated, `radius` on each side) whose bytes are
// biased (value ^ 0x80, so a signed byte compare orders them as the unsigned pixels). Bits, most
// significant first: for dy = -radius..0, dx = -radius..radius while (dy, dx) < (0, 0), the bit
// P(y + dy, x + e) > P(y - dy, x - e) with e = dx, or e = -dx when `mirrored` (the image was
// flipped left to right: the codes then equal the unflipped image's, column for column mirrored).
struct CensusArgs {
  int plane_bits = 4;
  const std::int8_t* padded =
      nullptr;  // pixel (x, y) of the image at padded[(y + r) * stride + x + r]
  std::size_t stride = 0;
  int width = 0;
  int height = 0;
  int radius = 0;
  bool mirrored = false;
  std::uint8_t* planes[kMaxPlanes] =
      {};  // plane j, pixel (x, y) at planes[j][y * plane_stride + x]
  std::size_t plane_stride = 0;
};

// One row of aggregation paths: per pixel x in [-1, width] a block of `paths` vectors of dp costs
// (Shape::block bytes), path j at block + j * dp: 0 horizontal, 1 vertical, 2 the diagonal from
// x - 1 in the forward pass (x + 1 backward), 3 the other. One block per pixel keeps every path's
// address a constant offset from one pointer. Pixels -1 and width are the zero predecessors
// (0 for k < d, 255 above) the kernels never write, so a path enters the image with L = C. The
// 64 bytes before pixel -1 and after pixel width are readable. minima[j][x] (x in [-1, width]) is
// the minimum of path j's costs at pixel x.
struct PathRow {
  std::uint8_t* costs = nullptr;  // pixel 0's block
  std::uint8_t* minima[4] = {};
};

// A pixel's totals hold kMaskedTotal at the indices it must not match (right pixel off the image,
// padding): real totals never reach it (8 paths <= 248).
inline constexpr std::uint8_t kMaskedTotal = 255;

// The backward pass's choice, pixel by pixel as it walks each row from right to left (the order
// of OpenCV's StereoSGBM, which the right matches depend on): the lowest index k of the smallest
// total, unless uniqueness refuses it or no index is valid; then
//   disparity[x]        = k + dmin, else kNoMatch;
//   parabola[x]         = the totals at k - 1, k + 1 and k (bytes 0, 1, 2) and 1 in byte 3 where
//                         both neighbours of k are valid, else 0: the sub-pixel step (SubPixel)
//                         is left to the check, which does 16 at a time;
//   right_disparity[xr] = k + dmin and right_cost[xr] = the total, for the right pixel
//                         xr = x - dmin - k, when the total is below right_cost[xr] (the caller
//                         fills right_cost with INT32_MAX and right_disparity with kNoMatch).
inline constexpr std::int32_t kNoMatch = INT32_MIN;
struct Choice {
  const std::int16_t* limits = nullptr;  // UniquenessLimit(m, ratio) for m in [0, 255]
  std::int32_t* disparity = nullptr;
  std::uint32_t* parabola = nullptr;
  std::int32_t* right_disparity = nullptr;
  std::int32_t* right_cost = nullptr;
};

// The SIMD kernels reduce the minima of the vertical and diagonal paths a row at a time: their
// scratch holds kMinimaLanes bytes per pixel for RoundUp(width, kMinimaLanes) pixels, and they
// write minima up to that rounded width (so minima rows have room for it; pixel width's entry,
// a zero predecessor's 0, is restored).
inline constexpr int kMinimaLanes = 64;

struct RowArgs {
  const Shape* shape = nullptr;
  Floors floors;
  std::uint8_t p1 = 0;
  std::uint8_t p2 = 0;
  int paths = 4;  // per pass: 4 (8 in all) or 2 (4 in all)
  // Census planes of this row: left pixel x at left[j][x]; the right row reversed, right column
  // xr at right[j][width - 1 - xr] (readable, as zeros, for xr from -dp - dmin to width - dmin).
  const std::uint8_t* left[kMaxPlanes] = {};
  const std::uint8_t* right[kMaxPlanes] = {};
  // The previous row's paths (the zero row for the first), and this row's (written; its path 0,
  // the horizontal one, is also read: its predecessor is the pixel just done).
  PathRow prev;
  PathRow cur;
  std::uint8_t* s1 = nullptr;      // forward: written, backward: read; width * dp bytes
  std::uint8_t* totals = nullptr;  // backward: written, width * dp
  // Backward: the choice per pixel (Choose).
  Choice choice;
  // SIMD scratch: per pixel and vertical or diagonal path (1 to 3), the lane-wise minimum of its
  // costs (kMinimaLanes bytes), reduced to the minima a row at a time: path j's at
  // min_vectors + (j - 1) * min_vectors_stride.
  std::uint8_t* min_vectors = nullptr;
  std::size_t min_vectors_stride = 0;
};

// Uniqueness: another k more than 1 away with total * (100 - ratio) < best * 100 refuses the
// pixel. As a bound on totals: total <= UniquenessLimit(best, ratio) (-1: none can refuse; at
// most 254, so masked totals never count).
static inline int UniquenessLimit(int best_total, int ratio) {
  if (best_total <= 0) return -1;
  const int limit = (best_total * 100 - 1) / (100 - ratio);
  return MinInt(limit, static_cast<int>(kMaskedTotal) - 1);
}

// OpenCV's parabola through the smallest total `here` and its neighbours, in 1/16 px:
// ((before - after) * 16 + denom2) / (2 * denom2), truncated, denom2 = max(before + after -
// 2 * here, 1). Float division is exact for it: |quotient| <= 8.5 lies at least 1 / (2 * denom2)
// >= 2^-10 from any integer it is not, far beyond float's 2^-20 rounding error there.
static inline int SubPixel(int before, int here, int after) {
  const int denom2 = MaxInt(before + after - 2 * here, 1);
  return static_cast<int>(static_cast<float>((before - after) * 16 + denom2) /
                          static_cast<float>(2 * denom2));
}

// The choice at pixel x (Choice) from its totals t, their minimum m, its lowest index best and
// whether uniqueness keeps it: the part every kernel shares, in scalar code.
static inline void Choose(const Shape& s, const Choice& c, int x, const std::uint8_t* t, int m,
                          int best, bool unique) {
  if (!unique || m == kMaskedTotal) {
    c.disparity[x] = kNoMatch;
    return;
  }
  const int xr = x - s.dmin - best;
  if (c.right_cost[xr] > m) {
    c.right_cost[xr] = m;
    c.right_disparity[xr] = best + s.dmin;
  }
  const bool inner =
      best > 0 && best < s.d - 1 && t[best - 1] != kMaskedTotal && t[best + 1] != kMaskedTotal;
  c.disparity[x] = best + s.dmin;
  c.parabola[x] = inner ? t[best - 1] | t[best + 1] << 8 | static_cast<std::uint32_t>(m) << 16 |
                              std::uint32_t{1} << 24
                        : 0;
}

// The disparity of one row in 1/16 px with its sub-pixel step (Choice), then OpenCV's StereoSGBM
// left-right check: a match is dropped when the right pixel it lands on has a right match
// (Choice) more than `tolerance` px away; both roundings of the sub-pixel disparity get a chance.
// out[x] = the disparity (1/16 px, > 0) or 0.
struct CheckArgs {
  const std::int32_t* disparity = nullptr;        // width values (Choice)
  const std::uint32_t* parabola = nullptr;        // width values (Choice)
  const std::int32_t* right_disparity = nullptr;  // width + 1 values, [width] = kNoMatch
  int width = 0;
  int tolerance = 0;  // < 0: no check
  std::uint16_t* out = nullptr;
};
static inline std::uint16_t CheckPixel(const CheckArgs& a, int x) {
  const int d = a.disparity[x];
  if (d == kNoMatch) return 0;
  const std::uint32_t p = a.parabola[x];
  const int d1 = d * 16 + (p >> 24 != 0 ? SubPixel(p & 255, (p >> 16) & 255, (p >> 8) & 255) : 0);
  bool keep = d1 > 0;
  if (a.tolerance >= 0 && keep) {
    const int d_lo = d1 >> 4, d_hi = (d1 + 15) >> 4;
    const int x_lo = x - d_lo, x_hi = x - d_hi;  // < width: d1 > 0
    const int r_lo = a.right_disparity[x_lo >= 0 ? x_lo : a.width];
    const int r_hi = a.right_disparity[x_hi >= 0 ? x_hi : a.width];
    const bool bad_lo =
        r_lo != kNoMatch && (r_lo - d_lo > a.tolerance || d_lo - r_lo > a.tolerance);
    const bool bad_hi =
        r_hi != kNoMatch && (r_hi - d_hi > a.tolerance || d_hi - r_hi > a.tolerance);
    keep = !(bad_lo && bad_hi);
  }
  return static_cast<std::uint16_t>(keep ? d1 : 0);
}

struct Kernels {
  const char* name;
  int lanes;       // Shape::dp must be a multiple of this (32 or 64)
  int plane_bits;  // the census planes they read and write (4 or 8)
  void (*census)(const CensusArgs& args);
  void (*forward_row)(const RowArgs& args);
  void (*backward_row)(const RowArgs& args);  // with the choice
  void (*check_row)(const CheckArgs& args);
};

const Kernels& ScalarKernels();
// Null when the build has no such kernels (not x86-64 / no compiler support).
const Kernels* Avx2Kernels();
const Kernels* Avx512Kernels();

}  // namespace cloudcast::stereo::sgm
