#include "cloudcast/core/pipeline.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <type_traits>
#include <utility>

#include "absl/strings/str_cat.h"
#include "kernels.h"

namespace cloudcast {

namespace {

using internal::DepthConstants;
using internal::DepthTable;
using internal::VoxelAccumulator;

// Where the points that pass go: a buffer sized for the worst case (left uninitialised), with
// their bounding box when the voxel grid needs it. A point arrives as (x, y, z, 0) plus colour.
template <bool kTrack>
struct PointSink {
  static constexpr bool kTrackBounds = kTrack;
  static constexpr bool kBanded = false;
  Point* out;
  std::size_t count = 0;
  internal::Bounds bounds;
  void Add(__m128 xyz, std::uint32_t rgba) {
    Point& p = out[count++];
    _mm_storeu_ps(&p.x, xyz);
    p.rgba = rgba;
    if constexpr (kTrackBounds) bounds.Add(xyz);
  }
};

// Points that go to the voxel grid band by band: whenever a row ends with `band` points or more
// in the buffer, they are added to the accumulator and the buffer starts again, so it stays in
// cache between the scan writing it and the voxel grid reading it.
struct BandSink {
  static constexpr bool kTrackBounds = false;
  static constexpr bool kBanded = true;
  Point* out;  // room for band + one row of points
  std::size_t count = 0;
  internal::Bounds bounds;  // unused: the accumulator was given a box before the scan
  VoxelAccumulator* accumulator;
  std::size_t band;
};

// x and y finite (z is known to be).
inline bool XyFinite(__m128 p) {
  const float big = std::numeric_limits<float>::max();
  const __m128 ok =
      _mm_and_ps(_mm_cmple_ps(_mm_set1_ps(-big), p), _mm_cmple_ps(p, _mm_set1_ps(big)));
  return (_mm_movemask_ps(ok) & 3) == 3;
}

struct Tally {
  std::uint64_t valid = 0;
  std::uint64_t passed = 0;
};

// Flags per raw disparity value for the table-driven kernel.
constexpr std::uint8_t kValid = 1;
constexpr std::uint8_t kPasses = 2;

// What a scan can learn from the flag table of 8/16-bit disparities, to test 16 bytes of pixels
// at a time: every value that passes lies in [pass_lo, pass_hi], and the valid values are
// [valid_lo, valid_hi] minus a few holes (typically the invalid values 0 and 2047).
struct ScanPlan {
  bool simd = false;  // the valid set has that shape (else: count validity per pixel)
  std::uint32_t pass_lo = 1, pass_hi = 0;  // empty when lo > hi
  std::uint32_t valid_lo = 1, valid_hi = 0;
  std::uint32_t holes[4] = {0, 0, 0, 0};
  int hole_count = 0;
  bool pass_exact = false;  // every value in [pass_lo, pass_hi] passes: no flag look-up needed
  // The smallest and largest multiplier m (DepthConstants: z, or a raw depth) that pass.
  float z_min = 0, z_max = 0;
  // Some passing pixel's x or y may overflow to infinity (set per frame by the caller).
  bool x_y_may_overflow = true;

  static ScanPlan From(const std::uint8_t* flags, std::size_t n) {
    ScanPlan plan;
    std::int64_t plo = -1, phi = -1, vlo = -1, vhi = -1;
    for (std::size_t d = 0; d < n; ++d) {
      if (flags[d] & kPasses) {
        if (plo < 0) plo = static_cast<std::int64_t>(d);
        phi = static_cast<std::int64_t>(d);
      }
      if (flags[d] & kValid) {
        if (vlo < 0) vlo = static_cast<std::int64_t>(d);
        vhi = static_cast<std::int64_t>(d);
      }
    }
    if (plo >= 0)
      plan.pass_lo = static_cast<std::uint32_t>(plo),
      plan.pass_hi = static_cast<std::uint32_t>(phi);
    if (vlo >= 0)
      plan.valid_lo = static_cast<std::uint32_t>(vlo),
      plan.valid_hi = static_cast<std::uint32_t>(vhi);
    plan.pass_exact = true;
    for (std::int64_t d = plo; plo >= 0 && d <= phi; ++d)
      plan.pass_exact &= (flags[d] & kPasses) != 0;
    plan.simd = true;
    for (std::int64_t d = vlo; vlo >= 0 && d <= vhi; ++d) {
      if (flags[d] & kValid) continue;
      if (plan.hole_count == 4) {
        plan.simd = false;
        break;
      }
      plan.holes[plan.hole_count++] = static_cast<std::uint32_t>(d);
    }
    return plan;
  }
};

// Four floats, 16-byte aligned: an SSE register in a table.
struct alignas(16) Float4 {
  float f[4];
};

// Lanes of 16 bytes of samples within [lo, hi] (unsigned), as all-ones lanes; the constants are
// made once per frame.
template <typename Sample>
struct RangeTest {
  __m128i lo, span;
  RangeTest(std::uint32_t l, std::uint32_t h) {
    if constexpr (sizeof(Sample) == 1) {
      lo = _mm_set1_epi8(static_cast<char>(l));
      span = _mm_set1_epi8(static_cast<char>(h - l));
    } else {
      // No unsigned 16-bit compare in SSE2: flip the sign bit and compare signed.
      lo = _mm_set1_epi16(static_cast<short>(l));
      span = _mm_set1_epi16(static_cast<short>((h - l) ^ 0x8000));
    }
  }
  __m128i operator()(__m128i d) const {
    if constexpr (sizeof(Sample) == 1) {
      return _mm_cmpeq_epi8(_mm_max_epu8(_mm_sub_epi8(d, lo), span), span);
    } else {
      const __m128i x =
          _mm_xor_si128(_mm_sub_epi16(d, lo), _mm_set1_epi16(static_cast<short>(0x8000)));
      return _mm_xor_si128(_mm_cmpgt_epi16(x, span), _mm_set1_epi32(-1));
    }
  }
};
template <typename Sample>
inline __m128i Equal(__m128i d, __m128i value) {
  if constexpr (sizeof(Sample) == 1) {
    return _mm_cmpeq_epi8(d, value);
  } else {
    return _mm_cmpeq_epi16(d, value);
  }
}
template <typename Sample>
inline __m128i Splat(std::uint32_t value) {
  if constexpr (sizeof(Sample) == 1) {
    return _mm_set1_epi8(static_cast<char>(value));
  } else {
    return _mm_set1_epi16(static_cast<short>(value));
  }
}
// One bit per sample of a lane mask.
template <typename Sample>
inline unsigned LaneBits(__m128i m) {
  if constexpr (sizeof(Sample) == 1) {
    return static_cast<unsigned>(_mm_movemask_epi8(m));
  } else {
    return static_cast<unsigned>(_mm_movemask_epi8(_mm_packs_epi16(m, _mm_setzero_si128())));
  }
}

// The colour of pixel u as PCL packs it, from one 4-byte load (the byte after a 3-byte pixel is
// ignored): the caller makes sure that byte is inside the buffer.
template <ColorEncoding C>
inline std::uint32_t PackPixelWide(const std::uint8_t* row, std::uint32_t u) {
  std::uint32_t w;
  if constexpr (C == ColorEncoding::kMono8) {
    return (std::uint32_t{row[u]} * 0x010101u) | 0xFF000000u;
  } else {
    std::memcpy(&w, row + static_cast<std::size_t>(u) * (C == ColorEncoding::kRGBA8 ? 4 : 3), 4);
  }
  if constexpr (C == ColorEncoding::kBGR8) return w | 0xFF000000u;  // bytes b, g, r: in place
  return (__builtin_bswap32(w) >> 8) | 0xFF000000u;                 // bytes r, g, b: reversed
}

// 8/16-bit disparities with the passthrough on z (or off): z, validity and the passthrough
// decision all depend on the raw value only, so they come from tables. Sixteen bytes of pixels
// are tested at once against the range of passing values, and valid pixels are counted with the
// same registers; only blocks holding a passing pixel are looked at one pixel at a time.
//
// A passing pixel costs about twenty instructions: (u - cx, 0, 0, 0) comes from a per-column
// table and (z, z, z, z) from a per-value one (8-bit samples), so the point is two loads, an or
// and PCL's two products; its colour one load. The sink's state lives in locals, which the
// stores of points cannot alias.
//
// `disparity` is the frame's disparity map or depth image (DepthConstants says which).
template <typename Sample, ColorEncoding C, typename Sink, typename Values>
void RunTableKernel(const DepthConstants& c, const float* zt, const Float4* z4,
                    const Float4* column, const std::uint8_t* flags, const ScanPlan& plan,
                    const Values& disparity, const ColorView& colour, Sink* sink, Tally* tally) {
  const std::uint32_t w = disparity.width;
  std::uint32_t h = disparity.height;
  constexpr std::uint32_t kLanes = 16 / sizeof(Sample);
  std::uint64_t valid = 0;
  // Valid-pixel counts as byte counts (psadbw), divided out at the end.
  __m128i in_valid_range = _mm_setzero_si128(), in_holes = _mm_setzero_si128();
  const __m128i zero = _mm_setzero_si128();
  const bool any_pass = plan.pass_lo <= plan.pass_hi;
  const bool any_valid = plan.valid_lo <= plan.valid_hi;
  const bool simd = plan.simd;
  const bool pass_exact = plan.pass_exact;
  const bool check_finite = plan.x_y_may_overflow;
  const int hole_count = plan.hole_count;
  const RangeTest<Sample> valid_range(plan.valid_lo, plan.valid_hi);
  const RangeTest<Sample> pass_range(plan.pass_lo, plan.pass_hi);
  __m128i hole[4];
  for (int k = 0; k < 4; ++k) hole[k] = Splat<Sample>(plan.holes[k]);
  const __m128 scale = _mm_setr_ps(c.inv_fx, c.inv_fy, c.sz, 0.0f);
  Point* const first = sink->out + sink->count;
  Point* o = first;
  internal::Bounds bounds = sink->bounds;
  // Without a row table, the end of the colour buffer bounds the 4-byte loads; a row table
  // promises a readable byte after every row (ImageView::rows).
  const std::uint8_t* colour_end =
      colour.rows != nullptr ? nullptr
                             : static_cast<const std::uint8_t*>(colour.data) + colour.size_bytes;
  // kFast: a row where no test is needed per passing pixel: every value in the passing range
  // passes, no x or y can overflow, and the byte after each pixel's colour is in the buffer (all
  // rows but the last: the next row follows).
  auto scan_row = [&](std::uint32_t v, auto fast) {
    constexpr bool kFast = decltype(fast)::value;
    const std::uint8_t* drow = disparity.row(v);
    const std::uint8_t* crow = colour.row(v);
    // (0, yc, 1, 0): or-ed with (u - cx, 0, 0, 0), times (z, z, z, z), times (1/fx, 1/fy, 1, 0)
    // gives PCL's ((u - cx) * z) * (1/fx), ((v - cy) * z) * (1/fy), z * 1 * 1 == z, and 0.
    const __m128 row_part = _mm_setr_ps(0.0f, static_cast<float>(v) - c.cy, 1.0f, 0.0f);
    // Pixels whose colour can be read with one 4-byte load.
    const std::uint32_t wide_end =
        (C == ColorEncoding::kBGR8 || C == ColorEncoding::kRGB8) && colour_end != nullptr
            ? static_cast<std::uint32_t>(
                  std::min<std::size_t>(w, (static_cast<std::size_t>(colour_end - crow) - 1) / 3))
            : w;
    auto pixel = [&](std::uint32_t u, Sample d) {
      __m128 zz;
      if constexpr (std::is_same_v<Values, DepthView>) {
        // A depth's multiplier is the raw value itself (the table holds float(d)): a convert
        // instead of a load from a 256 KB table.
        zz = _mm_set1_ps(static_cast<float>(d));
      } else if constexpr (sizeof(Sample) == 1) {
        zz = _mm_load_ps(z4[d].f);
      } else {
        zz = _mm_set1_ps(zt[d]);
      }
      const __m128 p =
          _mm_mul_ps(_mm_mul_ps(_mm_or_ps(_mm_load_ps(column[u].f), row_part), zz), scale);
      if (!kFast && check_finite && !XyFinite(p)) {
        --valid;  // z finite but x or y overflowed: not a finite point
        return;
      }
      const std::uint32_t rgba =
          kFast || u < wide_end ? PackPixelWide<C>(crow, u) : internal::PackPixel<C>(crow, u);
      _mm_storeu_ps(&o->x, p);
      o->rgba = rgba;
      ++o;
      if constexpr (Sink::kTrackBounds) bounds.Add(p);
    };
    // The passing pixels of one vector of samples.
    // Inlined by force: gcc leaves it out of line for 16-bit samples, a call per vector.
    auto visit = [&](std::uint32_t at, __m128i pass) __attribute__((always_inline)) {
      for (unsigned mask = LaneBits<Sample>(pass); mask != 0; mask &= mask - 1) {
        const auto j = static_cast<std::uint32_t>(__builtin_ctz(mask));
        const Sample s = internal::LoadSample<Sample>(drow, at + j);
        if (kFast || pass_exact || (flags[s] & kPasses)) pixel(at + j, s);
      }
    };
    std::uint32_t u = 0;
    // Valid samples are counted in byte lanes (each adds sizeof(Sample) to them), folded into
    // the 64-bit sums before a lane can wrap, every 255 vectors at most.
    auto chunk = [&](std::uint32_t end, auto holes_tag, auto pass_tag) {
      constexpr bool kHoles = decltype(holes_tag)::value;
      constexpr bool kAnyPass = decltype(pass_tag)::value;  // false: no value passes
      __m128i valid_bytes = zero, hole_bytes = zero;
      auto count = [&](__m128i d) {
        valid_bytes = _mm_sub_epi8(valid_bytes, valid_range(d));
        if constexpr (kHoles) {
          for (int k = 0; k < hole_count; ++k) {
            hole_bytes = _mm_sub_epi8(hole_bytes, Equal<Sample>(d, hole[k]));
          }
        }
      };
      const std::uint8_t* at = drow + std::size_t{u} * sizeof(Sample);
      auto load = [](const std::uint8_t* q) {
        return _mm_loadu_si128(reinterpret_cast<const __m128i*>(q));
      };
      // Four vectors at a time: one branch for all four when none passes (most of a frame).
      for (; u + 4 * kLanes <= end; u += 4 * kLanes, at += 64) {
        const __m128i d0 = load(at), d1 = load(at + 16), d2 = load(at + 32), d3 = load(at + 48);
        count(d0), count(d1), count(d2), count(d3);
        if constexpr (!kAnyPass) continue;
        const __m128i p0 = pass_range(d0), p1 = pass_range(d1);
        const __m128i p2 = pass_range(d2), p3 = pass_range(d3);
        if (_mm_movemask_epi8(_mm_or_si128(_mm_or_si128(p0, p1), _mm_or_si128(p2, p3))) == 0) {
          continue;
        }
        visit(u, p0), visit(u + kLanes, p1), visit(u + 2 * kLanes, p2);
        visit(u + 3 * kLanes, p3);
      }
      for (; u + kLanes <= end; u += kLanes, at += 16) {
        const __m128i d = load(at);
        count(d);
        if constexpr (kAnyPass) visit(u, pass_range(d));
      }
      in_valid_range = _mm_add_epi64(in_valid_range, _mm_sad_epu8(valid_bytes, zero));
      in_holes = _mm_add_epi64(in_holes, _mm_sad_epu8(hole_bytes, zero));
    };
    if (simd) {
      constexpr std::uint32_t kFoldEvery = 252 * kLanes;  // a multiple of four vectors
      const std::uint32_t simd_end = w - w % kLanes;
      while (u < simd_end) {
        const std::uint32_t end = std::min(simd_end, u + kFoldEvery);
        if (!any_pass) {
          chunk(end, std::true_type{}, std::false_type{});
        } else if (hole_count == 0) {
          chunk(end, std::false_type{}, std::true_type{});
        } else {
          chunk(end, std::true_type{}, std::true_type{});
        }
      }
    }
    for (; u < w; ++u) {
      const Sample d = internal::LoadSample<Sample>(drow, u);
      const std::uint8_t f = flags[d];
      valid += f & kValid;
      if (f & kPasses) pixel(u, d);
    }
  };
  const bool fast = pass_exact && !check_finite;
  std::uint64_t passed = 0;
  // No valid value at all (every pixel invalid): nothing to count and nothing passes.
  if (!any_valid) h = 0;
  for (std::uint32_t v = 0; v < h; ++v) {
    if (fast && v + 1 < h) {
      scan_row(v, std::true_type{});
    } else {
      scan_row(v, std::false_type{});
    }
    if constexpr (Sink::kBanded) {
      const auto in_band = static_cast<std::size_t>(o - first);
      if (in_band >= sink->band || v + 1 == h) {
        sink->accumulator->AddNarrow(first, in_band);
        passed += in_band;
        o = first;
      }
    }
  }
  passed += static_cast<std::uint64_t>(o - first);
  sink->count += static_cast<std::size_t>(o - first);
  if constexpr (Sink::kTrackBounds) sink->bounds = bounds;
  alignas(16) std::uint64_t sums[2], holes[2];
  _mm_store_si128(reinterpret_cast<__m128i*>(sums), in_valid_range);
  _mm_store_si128(reinterpret_cast<__m128i*>(holes), in_holes);
  valid += (sums[0] + sums[1] - holes[0] - holes[1]) / sizeof(Sample);
  tally->valid = valid;
  tally->passed = passed;
}

// Any encoding and any passthrough axis: each pixel becomes a point, then is tested.
template <typename Sample, ColorEncoding C, typename Sink, typename Values>
void RunGenericKernel(const DepthConstants& c, const DepthTable* table,
                      const PassThroughParams& passthrough, const Values& disparity,
                      const ColorView& colour, Sink* sink, Tally* tally) {
  const std::uint32_t w = disparity.width;
  const std::uint32_t h = disparity.height;
  std::uint64_t valid = 0, passed = 0;
  for (std::uint32_t v = 0; v < h; ++v) {
    const std::uint8_t* drow = disparity.row(v);
    const std::uint8_t* crow = colour.row(v);
    for (std::uint32_t u = 0; u < w; ++u) {
      const Sample d = internal::LoadSample<Sample>(drow, u);
      float z;
      if constexpr (std::is_same_v<Sample, float>) {
        if (!c.Depth(d, &z)) continue;
      } else {
        if (!table->valid[d]) continue;
        z = table->z[d];
      }
      const std::uint32_t rgba = internal::PackPixel<C>(crow, u);
      const Point p{c.X(u, z), c.Y(v, z), c.Z(z), rgba};
      if (!internal::IsFinite(p.x) || !internal::IsFinite(p.y)) continue;
      ++valid;
      if (!internal::Passes(p, passthrough)) continue;
      ++passed;
      sink->Add(_mm_setr_ps(p.x, p.y, p.z, 0.0f), rgba);
    }
  }
  tally->valid = valid;
  tally->passed = passed;
}

}  // namespace

// Points per band of the banded path: 64 KB of them, which stay in L2 between the scan and the
// voxel grid.
constexpr std::size_t kBandPoints = 4096;

struct Pipeline::Impl {
  VoxelAccumulator accumulator;
  DepthTable table;
  // Passthrough flags per raw value, valid for `flags_table_bits` / the passthrough below.
  std::vector<std::uint8_t> flags;
  int flags_bits = -1;
  DepthConstants flags_constants{CameraModel{}};
  PassThroughParams flags_passthrough;
  // The points that pass, before the voxel grid.
  PointVector passed;
  // The last Run's voxel grid, while the accumulator holds its voxels (for RefilterVoxels).
  bool voxels_held = false;
  VoxelGridParams held_voxel;

  ScanPlan plan;
  // (z, z, z, z) per 8-bit value, made with the flags; (u - cx, 0, 0, 0) per column.
  std::vector<Float4> z4;
  std::vector<Float4> column;
  std::uint32_t column_width = 0;
  float column_cx = 0;

  const Float4* Columns(std::uint32_t w, float cx) {
    if (column_width == w && column_cx == cx && !column.empty()) return column.data();
    column.resize(w);
    for (std::uint32_t u = 0; u < w; ++u) {
      column[u] = Float4{{static_cast<float>(u) - cx, 0.0f, 0.0f, 0.0f}};
    }
    column_width = w;
    column_cx = cx;
    return column.data();
  }

  // Whether a pixel that passes may have an x or y beyond float's range: z is at most
  // plan.z_max, and |u - cx|, |v - cy| are largest at the frame's edges.
  bool XyMayOverflow(const DepthConstants& c, std::uint32_t w, std::uint32_t h) const {
    const double du = std::max(std::fabs(0.0 - c.cx), std::fabs(w - 1.0 - c.cx));
    const double dv = std::max(std::fabs(0.0 - c.cy), std::fabs(h - 1.0 - c.cy));
    const double z = plan.z_max;
    // Float rounding adds a few parts in 10^7 to each product: far inside the margin.
    constexpr double kSafe = 1e37;
    return !(du * z * std::fabs(c.inv_fx) < kSafe && dv * z * std::fabs(c.inv_fy) < kSafe);
  }

  const std::uint8_t* PassFlags(const DepthConstants& c, const PassThroughParams& pt, int bits) {
    if (flags_bits == bits && flags_constants.SameAs(c) &&
        flags_passthrough.enabled == pt.enabled && flags_passthrough.axis == pt.axis &&
        flags_passthrough.min == pt.min && flags_passthrough.max == pt.max &&
        flags_passthrough.negative == pt.negative) {
      return flags.data();
    }
    const std::size_t n = std::size_t{1} << bits;
    flags.assign(n, 0);
    for (std::size_t d = 0; d < n; ++d) {
      if (!table.valid[d]) continue;
      const float z = c.Z(table.z[d]);
      const bool inside = z >= pt.min && z <= pt.max;
      flags[d] = kValid | ((!pt.enabled || inside != pt.negative) ? kPasses : 0);
    }
    flags_bits = bits;
    flags_constants = c;
    flags_passthrough = pt;
    plan = ScanPlan::From(flags.data(), n);
    plan.z_min = std::numeric_limits<float>::max();
    plan.z_max = 0;
    for (std::size_t d = 0; d < n; ++d) {
      if (!(flags[d] & kPasses)) continue;
      plan.z_min = std::min(plan.z_min, table.z[d]);
      plan.z_max = std::max(plan.z_max, table.z[d]);
    }
    if (bits == 8) {
      z4.resize(n);
      for (std::size_t d = 0; d < n; ++d)
        z4[d] = Float4{{table.z[d], table.z[d], table.z[d], table.z[d]}};
    }
    return flags.data();
  }

  // A box holding every point the table kernel can produce on a w x h frame, from the range of
  // z that passes and the frame's edges: x and y are products that float rounding keeps
  // monotonic in each factor, so their extremes are at the corners (computed as the kernel
  // computes points). False when nothing passes or some x or y may overflow.
  bool StreamBox(const DepthConstants& c, std::uint32_t w, std::uint32_t h,
                 internal::Bounds* box) const {
    if (plan.pass_lo > plan.pass_hi || plan.x_y_may_overflow) return false;
    const __m128 scale = _mm_setr_ps(c.inv_fx, c.inv_fy, c.sz, 0.0f);
    for (const float u : {0.0f, static_cast<float>(w - 1)}) {
      for (const float v : {0.0f, static_cast<float>(h - 1)}) {
        for (const float z : {plan.z_min, plan.z_max}) {
          const __m128 a = _mm_setr_ps(u - c.cx, v - c.cy, 1.0f, 0.0f);
          box->Add(_mm_mul_ps(_mm_mul_ps(a, _mm_set1_ps(z)), scale));
        }
      }
    }
    return true;
  }

  template <typename Values>
  absl::Status RunFused(const PipelineOptions& options, const DepthConstants& c,
                        const Values& values, const ColorView& colour, PointCloud* out,
                        StageCounts* counts);

  // Set by the kernel when it voxelised the points band by band (the Pipeline then has
  // nothing left to do but count).
  bool streamed = false;

  // `disparity`: the frame's disparity map or depth image.
  template <typename Sink, typename Values>
  struct Kernel {
    Impl* impl;
    const DepthConstants& c;
    const PassThroughParams& passthrough;
    const Values& disparity;
    const ColorView& colour;
    Sink* sink;
    Tally* tally;
    // With the voxel grid on: its parameters and output, for the banded path.
    const VoxelGridParams* voxel = nullptr;
    PointVector* voxel_out = nullptr;

    template <typename Sample, ColorEncoding C>
    void operator()() const {
      if constexpr (std::is_same_v<Sample, float>) {
        RunGenericKernel<Sample, C>(c, nullptr, passthrough, disparity, colour, sink, tally);
      } else {
        constexpr int kBits = 8 * sizeof(Sample);
        impl->table.Prepare(c, kBits);
        if (!passthrough.enabled || passthrough.axis == Axis::kZ) {
          const std::uint8_t* flags = impl->PassFlags(c, passthrough, kBits);
          impl->plan.x_y_may_overflow = impl->XyMayOverflow(c, disparity.width, disparity.height);
          const Float4* column = impl->Columns(disparity.width, c.cx);
          internal::Bounds box;
          if (voxel != nullptr && impl->StreamBox(c, disparity.width, disparity.height, &box) &&
              impl->accumulator.BeginNarrow(box, *voxel,
                                            std::size_t{disparity.width} * disparity.height)) {
            BandSink band{sink->out, 0, {}, &impl->accumulator, kBandPoints};
            RunTableKernel<Sample, C>(c, impl->table.z.data(), impl->z4.data(), column, flags,
                                      impl->plan, disparity, colour, &band, tally);
            impl->accumulator.Finish(*voxel, voxel_out);
            impl->streamed = true;
            return;
          }
          RunTableKernel<Sample, C>(c, impl->table.z.data(), impl->z4.data(), column, flags,
                                    impl->plan, disparity, colour, sink, tally);
        } else {
          RunGenericKernel<Sample, C>(c, &impl->table, passthrough, disparity, colour, sink, tally);
        }
      }
    }
  };
};

Pipeline::Pipeline() : impl_(std::make_unique<Impl>()) {}
Pipeline::~Pipeline() = default;
Pipeline::Pipeline(Pipeline&&) noexcept = default;
Pipeline& Pipeline::operator=(Pipeline&&) noexcept = default;

// Both kinds of frame: `values` is a disparity map or a depth image, `c` its constants.
template <typename Values>
absl::Status Pipeline::Impl::RunFused(const PipelineOptions& options, const DepthConstants& c,
                                      const Values& values, const ColorView& colour,
                                      PointCloud* out, StageCounts* counts) {
  Tally tally;
  const std::size_t pixels = std::size_t{values.width} * values.height;
  voxels_held = false;
  if (options.voxel.enabled) {
    if (passed.size() < pixels) passed.resize(pixels);
    PointSink<true> sink{passed.data(), 0, {}};
    streamed = false;
    internal::DispatchEncodings(
        values.encoding, colour.encoding,
        Kernel<PointSink<true>, Values>{this, c, options.passthrough, values, colour, &sink, &tally,
                                        &options.voxel, &out->points});
    if (streamed) {
      // Voxelised band by band.
    } else if (auto s = accumulator.Run(passed.data(), sink.count, options.voxel, &out->points,
                                        &sink.bounds);
               !s.ok()) {
      out->points.clear();
      out->width = 0;
      return s;
    }
    voxels_held = true;
    held_voxel = options.voxel;
  } else {
    out->points.resize(pixels);
    PointSink<false> sink{out->points.data(), 0, {}};
    internal::DispatchEncodings(values.encoding, colour.encoding,
                                Kernel<PointSink<false>, Values>{this, c, options.passthrough,
                                                                 values, colour, &sink, &tally});
    out->points.resize(sink.count);
  }
  out->width = static_cast<std::uint32_t>(out->points.size());
  out->height = 1;
  if (counts != nullptr) {
    counts->pixels = pixels;
    counts->valid_points = tally.valid;
    counts->after_passthrough = tally.passed;
    counts->after_voxel = out->points.size();
  }
  return absl::OkStatus();
}

namespace {

absl::Status StartRun(const PipelineOptions& options, PointCloud* out) {
  if (out == nullptr) return absl::InvalidArgumentError("output cloud is null");
  out->points.clear();
  out->width = 0;
  out->height = 1;
  return options.Validate();
}

}  // namespace

absl::Status Pipeline::Run(const PipelineOptions& options, const DisparityView& disparity,
                           const ColorView& colour, PointCloud* out, StageCounts* counts) {
  impl_->voxels_held = false;
  if (auto s = StartRun(options, out); !s.ok()) return s;
  if (auto s = ValidateFrame(disparity, colour, options.limits); !s.ok()) return s;
  return impl_->RunFused(options, DepthConstants(options.camera), disparity, colour, out, counts);
}

absl::Status Pipeline::Run(const PipelineOptions& options, const DepthView& depth,
                           const ColorView& colour, PointCloud* out, StageCounts* counts) {
  impl_->voxels_held = false;
  if (auto s = StartRun(options, out); !s.ok()) return s;
  if (auto s = ValidateFrame(depth, colour, options.limits); !s.ok()) return s;
  return impl_->RunFused(options, DepthConstants::ForDepth(options.camera, depth.encoding), depth,
                         colour, out, counts);
}

absl::Status Pipeline::RefilterVoxels(std::uint32_t min_points, PointCloud* out) {
  if (out == nullptr) return absl::InvalidArgumentError("output cloud is null");
  if (!impl_->voxels_held) {
    return absl::FailedPreconditionError(
        "RefilterVoxels: the last Run did not succeed with the voxel grid on");
  }
  impl_->accumulator.EmitAgain(impl_->held_voxel, min_points, &out->points);
  out->width = static_cast<std::uint32_t>(out->points.size());
  out->height = 1;
  return absl::OkStatus();
}

}  // namespace cloudcast
