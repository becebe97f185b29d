#include "cloudcast/core/filters.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <type_traits>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#include <string>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/checks.h"
#include "kernels.h"

namespace cloudcast {

namespace internal {

DepthConstants::DepthConstants(const CameraModel& c)
    : fxb(static_cast<float>(c.fx * c.baseline)),
      scale(static_cast<float>(c.disparity_scale)),
      offset(static_cast<float>(c.disparity_offset)),
      inv_fx(1.0f / static_cast<float>(c.fx)),
      inv_fy(1.0f / static_cast<float>(c.fy)),
      cx(static_cast<float>(c.cx)),
      cy(static_cast<float>(c.cy)) {
  for (double v : c.invalid_disparities) {
    if (invalid_count < 16) invalid[invalid_count++] = static_cast<float>(v);
  }
}

DepthConstants DepthConstants::ForDepth(const CameraModel& c, DepthEncoding encoding) {
  DepthConstants k(c);
  k.depth_image = true;
  k.invalid_count = 0;
  k.fxb = 0;
  k.scale = 1;
  k.offset = 0;
  // depth_image_proc: unit_scaling = toMeters(T(1)) in double (for 16 bits, 1 * 0.001f), then
  // constant_x = unit_scaling / fx in double, stored as float; z = D * 0.001f.
  const float s = static_cast<float>(c.DepthScale(encoding));
  k.inv_fx = static_cast<float>(static_cast<double>(s) / c.fx);
  k.inv_fy = static_cast<float>(static_cast<double>(s) / c.fy);
  k.sz = s;
  return k;
}

bool DepthConstants::SameAs(const DepthConstants& o) const {
  if (depth_image != o.depth_image || sz != o.sz) return false;
  if (fxb != o.fxb || scale != o.scale || offset != o.offset || invalid_count != o.invalid_count) {
    return false;
  }
  for (int i = 0; i < invalid_count; ++i) {
    if (invalid[i] != o.invalid[i]) return false;
  }
  return true;
}

void DepthTable::Prepare(const DepthConstants& c, int sample_bits) {
  if (bits == sample_bits && constants.SameAs(c)) return;
  const std::size_t n = std::size_t{1} << sample_bits;
  z.assign(n, std::numeric_limits<float>::quiet_NaN());
  valid.assign(n, 0);
  for (std::size_t d = 0; d < n; ++d) {
    float depth;
    if (c.Depth(static_cast<float>(d), &depth)) {
      z[d] = depth;
      valid[d] = 1;
    }
  }
  constants = c;
  bits = sample_bits;
}

namespace {

// `disparity`: a disparity map or a depth image (DepthConstants says which).
template <typename Values>
struct OrganizedKernel {
  const DepthConstants& c;
  const Values& disparity;
  const ColorView& colour;
  Point* out;

  template <typename Sample, ColorEncoding C>
  void operator()() const {
    const std::uint32_t w = disparity.width;
    const std::uint32_t h = disparity.height;
    if constexpr (std::is_same_v<Sample, float>) {
      for (std::uint32_t v = 0; v < h; ++v) {
        const std::uint8_t* drow = disparity.row(v);
        const std::uint8_t* crow = colour.row(v);
        Point* o = out + static_cast<std::size_t>(v) * w;
        for (std::uint32_t u = 0; u < w; ++u) {
          float z;
          if (c.Depth(LoadSample<float>(drow, u), &z)) {
            o[u] = Point{c.X(u, z), c.Y(v, z), c.Z(z), PackPixel<C>(crow, u)};
          } else {
            o[u] = NanPoint();
          }
        }
      }
    } else {
      thread_local DepthTable table;
      table.Prepare(c, 8 * sizeof(Sample));
      const float* zt = table.z.data();
      const std::uint8_t* valid = table.valid.data();
      for (std::uint32_t v = 0; v < h; ++v) {
        const std::uint8_t* drow = disparity.row(v);
        const std::uint8_t* crow = colour.row(v);
        Point* o = out + static_cast<std::size_t>(v) * w;
        const float yc = static_cast<float>(v) - c.cy;
        for (std::uint32_t u = 0; u < w; ++u) {
          const Sample d = LoadSample<Sample>(drow, u);
          const float z = zt[d];
          // Invalid pixels compute NaN coordinates from z = NaN; only the colour needs a choice.
          const std::uint32_t rgba = valid[d] ? PackPixel<C>(crow, u) : 0u;
          o[u] = Point{((static_cast<float>(u) - c.cx) * z) * c.inv_fx, (yc * z) * c.inv_fy, c.Z(z),
                       rgba};
        }
      }
    }
  }
};

}  // namespace
}  // namespace internal

namespace {

template <typename Values>
absl::Status Organize(const internal::DepthConstants& c, const Values& values,
                      const ColorView& colour, PointCloud* out) {
  out->points.resize(static_cast<std::size_t>(values.width) * values.height);
  out->width = values.width;
  out->height = values.height;
  internal::DispatchEncodings(
      values.encoding, colour.encoding,
      internal::OrganizedKernel<Values>{c, values, colour, out->points.data()});
  return absl::OkStatus();
}

}  // namespace

absl::Status ConvertToOrganized(const CameraModel& camera, const DisparityView& disparity,
                                const ColorView& colour, PointCloud* out, const Limits& limits) {
  if (out == nullptr) return absl::InvalidArgumentError("output cloud is null");
  if (auto s = camera.Validate(); !s.ok()) return s;
  if (auto s = ValidateFrame(disparity, colour, limits); !s.ok()) return s;
  return Organize(internal::DepthConstants(camera), disparity, colour, out);
}

absl::Status ConvertToOrganized(const CameraModel& camera, const DepthView& depth,
                                const ColorView& colour, PointCloud* out, const Limits& limits) {
  if (out == nullptr) return absl::InvalidArgumentError("output cloud is null");
  if (auto s = camera.Validate(); !s.ok()) return s;
  if (auto s = ValidateFrame(depth, colour, limits); !s.ok()) return s;
  return Organize(internal::DepthConstants::ForDepth(camera, depth.encoding), depth, colour, out);
}

namespace {

#if defined(__SSE2__)
// One point per 128-bit register: lanes x, y, z and the colour word. `lo <= v <= hi` is false
// for NaN, and with +-FLT_MAX on the lanes that are not the filtered axis it is false for
// infinities there too; the axis lane's own limits are finite. So one pair of comparisons tests
// finiteness and the range at once. Every point is stored and the output index advances only when
// it is kept: no branch to mispredict.
template <bool kNegative>
std::size_t PassThroughLoop(const Point* in, std::size_t n, __m128 lo, __m128 hi, int axis_bit,
                            Point* out) {
  const float big = std::numeric_limits<float>::max();
  const __m128 finite_lo = _mm_set1_ps(-big), finite_hi = _mm_set1_ps(big);
  auto keep = [&](__m128 v) -> std::size_t {
    const int in_range = _mm_movemask_ps(_mm_and_ps(_mm_cmple_ps(lo, v), _mm_cmple_ps(v, hi)));
    if constexpr (!kNegative) {
      return static_cast<std::size_t>(((in_range & 7) + 1) >> 3);  // all of x, y, z pass
    } else {
      const int finite =
          _mm_movemask_ps(_mm_and_ps(_mm_cmple_ps(finite_lo, v), _mm_cmple_ps(v, finite_hi)));
      return static_cast<std::size_t>((((finite & 7) + 1) >> 3) & ((in_range & axis_bit) == 0));
    }
  };
  std::size_t k = 0, i = 0;
  for (; i + 4 <= n; i += 4) {  // four at a time: the tests overlap, only k is sequential
    const __m128 v0 = _mm_loadu_ps(&in[i].x), v1 = _mm_loadu_ps(&in[i + 1].x);
    const __m128 v2 = _mm_loadu_ps(&in[i + 2].x), v3 = _mm_loadu_ps(&in[i + 3].x);
    const std::size_t k0 = keep(v0), k1 = keep(v1), k2 = keep(v2), k3 = keep(v3);
    _mm_storeu_ps(&out[k].x, v0);
    k += k0;
    _mm_storeu_ps(&out[k].x, v1);
    k += k1;
    _mm_storeu_ps(&out[k].x, v2);
    k += k2;
    _mm_storeu_ps(&out[k].x, v3);
    k += k3;
  }
  for (; i < n; ++i) {
    const __m128 v = _mm_loadu_ps(&in[i].x);
    _mm_storeu_ps(&out[k].x, v);
    k += keep(v);
  }
  return k;
}

std::size_t PassThroughKernel(const Point* in, std::size_t n, const PassThroughParams& params,
                              Point* out) {
  const float big = std::numeric_limits<float>::max();
  alignas(16) float lo[4] = {-big, -big, -big, -big};
  alignas(16) float hi[4] = {big, big, big, big};
  const int axis = static_cast<int>(params.axis);
  if (params.enabled) {
    lo[axis] = params.min;
    hi[axis] = params.max;
  }
  const __m128 vlo = _mm_load_ps(lo), vhi = _mm_load_ps(hi);
  if (params.enabled && params.negative) {
    return PassThroughLoop<true>(in, n, vlo, vhi, 1 << axis, out);
  }
  return PassThroughLoop<false>(in, n, vlo, vhi, 1 << axis, out);
}
#else
std::size_t PassThroughKernel(const Point* in, std::size_t n, const PassThroughParams& params,
                              Point* out) {
  std::size_t k = 0;
  for (std::size_t i = 0; i < n; ++i) {
    out[k] = in[i];
    k += internal::Passes(in[i], params) ? 1 : 0;
  }
  return k;
}
#endif

}  // namespace

absl::Status PassThrough(const PointCloud& in, const PassThroughParams& params, PointCloud* out) {
  if (out == nullptr) return absl::InvalidArgumentError("output cloud is null");
  if (out == &in) return absl::InvalidArgumentError("passthrough output must not alias its input");
  if (auto s = params.Validate(); !s.ok()) return s;
  // Sized for the worst case without initialising (PointVector), then cut to what was kept.
  out->points.resize(in.points.size());
  const std::size_t kept =
      PassThroughKernel(in.points.data(), in.points.size(), params, out->points.data());
  out->points.resize(kept);
  out->width = static_cast<std::uint32_t>(kept);
  out->height = 1;
  return absl::OkStatus();
}

}  // namespace cloudcast
