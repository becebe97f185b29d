// Internal building blocks shared by the stand-alone stages and the fused pipeline: the depth
// arithmetic (in PCL's float order), colour packing, and the voxel accumulator.
#pragma once

#if !defined(__SSE2__)
#error "cloudcast's kernels use SSE2, which every x86-64 CPU has"
#endif
#include <emmintrin.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

#include "absl/status/status.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/core/filters.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/point.h"

namespace cloudcast::internal {

inline bool IsFinite(float v) {
  std::uint32_t bits;
  std::memcpy(&bits, &v, sizeof bits);
  return (bits & 0x7F800000u) != 0x7F800000u;
}
inline bool IsFinite(const Point& p) { return IsFinite(p.x) && IsFinite(p.y) && IsFinite(p.z); }

inline Point NanPoint() {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  return Point{nan, nan, nan, 0u};  // PCL sets rgb = 0.0f on bad points
}

// The camera model reduced to the float constants the per-pixel arithmetic uses. Every pixel
// becomes ((u - cx, v - cy, 1) * m) * (sx, sy, sz), m a function of its raw value:
//   disparity maps  m = z = fx * baseline / (d * scale + offset), (sx, sy, sz) = (1/fx, 1/fy, 1),
//                   PCL's order (fl_const = 1.0f / focal), so results match PCL bit for bit;
//   depth images    m = D, the raw depth, (sx, sy, sz) = (s/fx, s/fy, s) for the depth scale s,
//                   depth_image_proc's order, so results match it bit for bit.
struct DepthConstants {
  bool depth_image = false;  // m is the raw depth (else z from a disparity)
  float fxb = 0;             // fx * baseline: the numerator of z
  float scale = 1;           // disparity scale
  float offset = 0;          // disparity offset
  float inv_fx = 0;          // sx: 1.0f / fx, or the depth's s / fx
  float inv_fy = 0;          // sy
  float sz = 1;              // 1, or the depth scale
  float cx = 0;
  float cy = 0;
  float invalid[16] = {};
  int invalid_count = 0;

  // A disparity map's constants.
  explicit DepthConstants(const CameraModel& camera);
  // A depth image's.
  static DepthConstants ForDepth(const CameraModel& camera, DepthEncoding encoding);

  // m for a raw value, or false if the pixel has no valid point.
  bool Depth(float raw, float* m) const {
    if (!IsFinite(raw)) return false;
    if (depth_image) {
      // A measurement is a distance in front of the camera: z = raw * sz positive and a normal
      // float. 0 is REP 118's "no measurement"; a negative depth is behind the camera (as a
      // negative disparity, never a point); a subnormal one is no distance (and is flushed to
      // zero by SIMD and GPU code). depth_image_proc checks only isfinite: for the depths a
      // camera sends (0 or positive) the points are the same, bit for bit.
      if (!(raw * sz >= std::numeric_limits<float>::min())) return false;
      *m = raw;
      return true;
    }
    for (int i = 0; i < invalid_count; ++i) {
      if (raw == invalid[i]) return false;
    }
    const float denominator = raw * scale + offset;
    if (!(denominator > 0.0f)) return false;
    const float depth = fxb / denominator;
    if (!IsFinite(depth)) return false;
    *m = depth;
    return true;
  }
  // x = ((u - cx) * m) * sx: PCL's (and depth_image_proc's) order of operations.
  float X(std::uint32_t u, float m) const { return ((static_cast<float>(u) - cx) * m) * inv_fx; }
  float Y(std::uint32_t v, float m) const { return ((static_cast<float>(v) - cy) * m) * inv_fy; }
  // z = (1 * m) * sz, as the vector kernels compute it (exactly m for disparities).
  float Z(float m) const { return m * sz; }

  bool SameAs(const DepthConstants& o) const;
};

// m per raw value of an 8- or 16-bit disparity or depth (DepthConstants): a table look-up replaces
// a division per pixel. `valid[d]` is 0 for invalid values; z (holding m) is NaN there.
struct DepthTable {
  std::vector<float> z;
  std::vector<std::uint8_t> valid;
  DepthConstants constants{CameraModel{}};
  int bits = 0;

  // Rebuilds only when the camera or the sample width changed.
  void Prepare(const DepthConstants& c, int sample_bits);
};

template <typename Sample>
inline Sample LoadSample(const std::uint8_t* row, std::uint32_t u) {
  Sample s;
  std::memcpy(&s, row + static_cast<std::size_t>(u) * sizeof(Sample), sizeof s);
  return s;
}

template <ColorEncoding C>
inline std::uint32_t PackPixel(const std::uint8_t* row, std::uint32_t u) {
  if constexpr (C == ColorEncoding::kBGR8) {
    const std::uint8_t* p = row + 3 * static_cast<std::size_t>(u);
    return PackRgba(p[2], p[1], p[0]);
  } else if constexpr (C == ColorEncoding::kRGB8) {
    const std::uint8_t* p = row + 3 * static_cast<std::size_t>(u);
    return PackRgba(p[0], p[1], p[2]);
  } else if constexpr (C == ColorEncoding::kRGBA8) {
    const std::uint8_t* p = row + 4 * static_cast<std::size_t>(u);
    return PackRgba(p[0], p[1], p[2]);
  } else {
    const std::uint8_t g = row[u];
    return PackRgba(g, g, g);
  }
}

// Calls f.template operator()<Sample, C>() with the types of a frame's encodings.
template <typename S, typename F>
decltype(auto) DispatchColour(ColorEncoding c, F&& f) {
  switch (c) {
    case ColorEncoding::kBGR8:
      return f.template operator()<S, ColorEncoding::kBGR8>();
    case ColorEncoding::kRGB8:
      return f.template operator()<S, ColorEncoding::kRGB8>();
    case ColorEncoding::kRGBA8:
      return f.template operator()<S, ColorEncoding::kRGBA8>();
    case ColorEncoding::kMono8:
      break;
  }
  return f.template operator()<S, ColorEncoding::kMono8>();
}
template <typename F>
decltype(auto) DispatchEncodings(DisparityEncoding d, ColorEncoding c, F&& f) {
  switch (d) {
    case DisparityEncoding::kU8:
      return DispatchColour<std::uint8_t>(c, f);
    case DisparityEncoding::kU16:
      return DispatchColour<std::uint16_t>(c, f);
    case DisparityEncoding::kF32:
      break;
  }
  return DispatchColour<float>(c, f);
}
template <typename F>
decltype(auto) DispatchEncodings(DepthEncoding d, ColorEncoding c, F&& f) {
  if (d == DepthEncoding::kU16) return DispatchColour<std::uint16_t>(c, f);
  return DispatchColour<float>(c, f);
}

// True when p passes the passthrough (non-finite points never pass).
inline bool Passes(const Point& p, const PassThroughParams& params) {
  if (!IsFinite(p)) return false;
  if (!params.enabled) return true;
  const float v = params.axis == Axis::kX ? p.x : params.axis == Axis::kY ? p.y : p.z;
  const bool inside = v >= params.min && v <= params.max;
  return inside != params.negative;
}

// The bounding box of a set of finite points, kept in SSE registers (lane 3 unused).
struct Bounds {
  __m128 lo = _mm_set1_ps(std::numeric_limits<float>::max());
  __m128 hi = _mm_set1_ps(-std::numeric_limits<float>::max());
  void Add(__m128 p) {
    lo = _mm_min_ps(lo, p);
    hi = _mm_max_ps(hi, p);
  }
  bool empty() const { return _mm_movemask_ps(_mm_cmpgt_ps(lo, hi)) & 7; }
};

// The voxel grid engine. Voxel i along x holds the points with floor(x * (1/leaf_x)) == i,
// computed in float as PCL does. Knowing the cloud's bounding box first, it numbers voxels
// relative to the box's corner, so a key needs only as many bits as the extent: 32 bits for
// ordinary frames, 64 for huge extents or fine leaves (where PCL's 32-bit indices give up).
//
// Points are summed into a hash table (open addressing). Consecutive points in one voxel
// (neighbouring pixels of a row: 1.9 points a run on the Tsukuba frames) are summed in registers
// first, so a run costs one look-up; the look-up itself reads its slot once, and "voxel seen
// before" versus "new voxel" is a select, not a jump. Scratch memory is reused from cloud to
// cloud. Not thread-safe.
class VoxelAccumulator {
 public:
  // Downsamples points[0, n) into `out` (appended; first-seen order, or PCL's with
  // params.key_order). Non-finite points are skipped. `bounds`, if given, must contain every
  // point, and all points must be finite.
  absl::Status Run(const Point* points, std::size_t n, const VoxelGridParams& params,
                   PointVector* out, const Bounds* bounds = nullptr);

  // The same in batches, for a caller that knows a box holding every point before it has the
  // points (the box need not be tight: it only numbers the voxels). BeginNarrow returns false,
  // having started nothing, unless 32-bit keys fit the box; then AddNarrow takes batches of
  // finite points inside it (at most max_points in all), and Finish writes the voxels as Run
  // does. A run of one voxel's points across two batches costs one more look-up, nothing else.
  bool BeginNarrow(const Bounds& box, const VoxelGridParams& params, std::size_t max_points);
  void AddNarrow(const Point* points, std::size_t n);
  void Finish(const VoxelGridParams& params, PointVector* out);
  // The last cloud's voxels written again into `out` (replacing what it held), keeping those of
  // at least `min_points` points, in the order `params` asks: what Run or Finish would have
  // written with that minimum, without adding the points again.
  void EmitAgain(const VoxelGridParams& params, std::uint32_t min_points, PointVector* out);

  // Sums of one or more points: (x, y), (z, count) in double, colour (b, g, r, a) in 32 bits.
  struct Sums {
    __m128d xy;
    __m128d zn;
    __m128i bgra;
  };

 private:
  struct Voxel {
    // Sums in double: exact for float inputs, so the centroid does not depend on the order of
    // the points (PCL's float sums do, slightly). 48 bytes; the key lives in the table only.
    __m128d sum_xy;
    __m128d sum_z_n;  // lane 0: z, lane 1: the point count
    // 32-bit colour sums (b, g, r, a) are exact: a voxel holds at most Limits::max_pixels (2^24)
    // points of at most 255.
    __m128i sum_bgra;
  };
  template <typename KeyPolicy>
  void Accumulate(const Point* points, std::size_t n, const KeyPolicy& keys);
  template <bool kKeys, typename KeyPolicy>
  void AccumulateFiniteNarrow(const Point* points, std::size_t n, const KeyPolicy& keys);
  // The hot state, copied into locals while points are added: through members every store to
  // the table (uint64_t) could alias them, and the compiler would reload them for every point.
  struct Cursor {
    std::uint64_t* table;
    Voxel* voxels;
    std::uint32_t* keys;  // per voxel, kept for key order (32-bit keys)
    std::uint64_t tag;    // this cloud's tag, where a slot holds it
    std::uint64_t mask;
    int shift;
    std::size_t count;
    std::size_t grow_at;  // count at which the table is more than half full
  };
  // Numbers voxels from `bounds` (corner, key fields, key width); errors for extents that keys
  // cannot hold.
  absl::Status Layout(const Bounds& bounds, const VoxelGridParams& params);
  // Empties the accumulator and sizes its table for clouds like the last ones (at most
  // max_points points).
  void StartCloud(std::size_t max_points);
  // Room for `voxels` voxels.
  void Reserve(std::size_t voxels);
  Cursor MakeCursor();
  void Grow(Cursor* cursor);
  // kKeys: also keep each voxel's key (32-bit keys), for key order.
  template <bool kWide, bool kKeys>
  static void AddSums(Cursor& c, std::uint64_t key, const Sums& s);
  template <bool kWide, bool kKeys>
  static void AddPoint(Cursor& c, std::uint64_t key, __m128 xyz, __m128i bgra32);
  // Writes the voxels' points in first-seen order, or in the order of `order` (voxel indices in
  // the low 25 bits).
  void Emit(std::uint32_t min_points, const std::uint64_t* order, PointVector* out) const;
  // The voxels in increasing key order, which is PCL's order: keys are numbered from the
  // bounding box's corner and packed x, then y, then z, as PCL numbers its voxels. Voxel indices
  // in the low 25 bits.
  const std::uint64_t* KeyOrder();
  template <int kPasses>
  const std::uint64_t* RadixSortKeys();
  void ResizeTable(std::size_t slots);

  std::vector<Voxel, DefaultInitAllocator<Voxel>> voxels_;
  std::vector<std::uint32_t, DefaultInitAllocator<std::uint32_t>> keys_;  // with keep_keys_
  bool keep_keys_ = false;
  std::size_t voxel_count_ = 0;
  // Slot: (key << 32 | tag << 25 | voxel + 1) for 32-bit keys; for 64-bit keys two words, key
  // and (tag << 32 | voxel + 1). A slot is this cloud's when it holds tag_: slots of earlier
  // clouds read as empty, and the table needs no clearing between clouds.
  std::vector<std::uint64_t> table_;
  std::uint32_t tag_ = 0;    // 1 to 127 while a cloud is accumulated
  bool table_wide_ = false;  // the layout of table_'s slots
  std::uint64_t mask_ = 0;
  int shift_ = 64;
  bool wide_ = false;  // 64-bit keys: table_ holds (key, voxel + 1) pairs
  int key_bits_ = 0;   // bits the keys of this cloud use
  // This cloud's voxel numbering (Layout): 1/leaf, the box's corner in voxels, key fields.
  float inv_[3] = {};
  std::int64_t corner_[3] = {};
  int shift_y_ = 0, shift_z_ = 0;
  bool int32_indices_ = true;
  std::vector<std::uint64_t> sort_a_, sort_b_;
  std::uint32_t sort_counts_[3 << 11];  // the radix sort's bucket counts, for up to 3 passes
  // Voxel counts of the last clouds: the table is sized for the largest, so that a stream whose
  // frames alternate between small and large ones does not regrow it every frame.
  std::size_t recent_voxels_[8] = {};
  std::size_t clouds_ = 0;
};

}  // namespace cloudcast::internal
