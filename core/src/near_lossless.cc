#include "cloudcast/core/near_lossless.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <type_traits>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/limits.h"

namespace cloudcast {
namespace {

// The server computes points in float: each of its points is off by a few 1e-7 of its distance
// (a few operations of half an ulp, 6e-8, each), the lossless point as much as the quantized
// one. A replacement therefore keeps 1% of the bound and 1e-6 of the point's distance for them
// (at a 1 mm bound: 10 um, plus 12 um at 12 m).
constexpr double kMargin = 0.99;
constexpr double kFloatError = 1e-6;

constexpr Limits kNoLimits{std::numeric_limits<std::uint32_t>::max(),
                           std::numeric_limits<std::uint64_t>::max()};

absl::Status CheckBound(double max_point_error) {
  if (!std::isfinite(max_point_error) || max_point_error < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "max_point_error is ", max_point_error, "; it must be a finite distance >= 0 (0: lossless)"));
  }
  return absl::OkStatus();
}

template <typename View>
absl::Status CheckInput(const View& in, const CameraModel& camera, double max_point_error,
                        std::string_view field) {
  if (absl::Status s = ValidateView(in, kNoLimits, field); !s.ok()) return s;
  if (absl::Status s = camera.Validate("camera"); !s.ok()) return s;
  return CheckBound(max_point_error);
}

float FloatOf(std::uint32_t bits) {
  float f;
  std::memcpy(&f, &bits, sizeof f);
  return f;
}
std::uint32_t BitsOf(float f) {
  std::uint32_t bits;
  std::memcpy(&bits, &f, sizeof bits);
  return bits;
}

// The raw value for a pixel whose valid value is `value`, given the interval [lo, hi] (in raw
// units, doubles) in which its point stays within the bound, and `ok`, the exact check of a
// candidate. Integer samples: the roundest integer of the interval; float samples (positive
// only: their bit patterns are ordered like their values): the roundest bit pattern.
template <typename T, typename Ok>
T Pick(T value, double lo, double hi, const Ok& ok) {
  if constexpr (std::is_floating_point_v<T>) {
    if (!(value > 0.0f) || !std::isfinite(value)) return value;
    float flo = static_cast<float>(lo);
    if (static_cast<double>(flo) < lo) flo = std::nextafter(flo, std::numeric_limits<float>::max());
    float fhi = static_cast<float>(hi);
    if (static_cast<double>(fhi) > hi) fhi = std::nextafter(fhi, 0.0f);
    if (!(flo > 0.0f)) flo = std::numeric_limits<float>::denorm_min();
    if (!std::isfinite(fhi)) fhi = std::numeric_limits<float>::max();
    std::uint32_t blo = BitsOf(std::min(flo, value));
    std::uint32_t bhi = BitsOf(std::max(fhi, value));
    const T x = FloatOf(RoundestInRange(blo, bhi));
    return ok(x) ? x : value;
  } else {
    constexpr double kMax = static_cast<double>(std::numeric_limits<T>::max());
    const double clo = std::clamp(std::ceil(lo), 0.0, kMax);
    const double chi = std::clamp(std::floor(hi), 0.0, kMax);
    const std::uint32_t ilo = std::min<std::uint32_t>(static_cast<std::uint32_t>(clo), value);
    const std::uint32_t ihi = std::max<std::uint32_t>(static_cast<std::uint32_t>(chi), value);
    const T x = static_cast<T>(RoundestInRange(ilo, ihi));
    return ok(x) ? x : value;
  }
}

// Per pixel ray lengths: |P' - P| = |z' - z| * ray.
struct Rays {
  const std::vector<double>& x2;
  double y2;
  double at(std::uint32_t u) const { return std::sqrt(1.0 + x2[u] + y2); }
};

void FillRayX2(const CameraModel& camera, std::uint32_t width, std::vector<double>* x2) {
  x2->resize(width);
  for (std::uint32_t u = 0; u < width; ++u) {
    const double a = (u - camera.cx) / camera.fx;
    (*x2)[u] = a * a;
  }
}

template <typename T>
void QuantizeDisparityRows(const DisparityView& in, const CameraModel& c, double bound,
                           const std::vector<double>& ray_x2, std::uint8_t* out,
                           QuantizeStats* stats) {
  const double fb = c.fx * c.baseline;
  const double s = c.disparity_scale;
  const double o = c.disparity_offset;
  // Whether the server makes a point of a raw value: its test, in its float arithmetic
  // (camera.h; core's DepthConstants::Depth), so that validity is kept exactly.
  const float ffb = static_cast<float>(fb), fs = static_cast<float>(s),
              fo = static_cast<float>(o);
  auto valid = [&](double d) {
    const float f = static_cast<float>(d);
    if (!std::isfinite(f)) return false;
    for (double invalid : c.invalid_disparities) {
      if (f == static_cast<float>(invalid)) return false;
    }
    const float den = f * fs + fo;
    return den > 0.0f && std::isfinite(ffb / den);
  };
  const std::size_t row_bytes = std::size_t{in.width} * sizeof(T);
  for (std::uint32_t v = 0; v < in.height; ++v) {
    const double ry = (v - c.cy) / c.fy;
    const Rays rays{ray_x2, ry * ry};
    const std::uint8_t* src = in.row(v);
    std::uint8_t* dst = out + v * row_bytes;
    for (std::uint32_t u = 0; u < in.width; ++u) {
      T raw;  // read through memcpy: views need not be aligned
      std::memcpy(&raw, src + u * sizeof(T), sizeof(T));
      const double d = static_cast<double>(raw);
      const double den = d * s + o;
      T result = raw;
      if (valid(d) && den > 0) {
        ++stats->valid;
        const double z = fb / den;
        const double t = bound / rays.at(u) - kFloatError * std::abs(z);  // |z' - z| allowed
        // z' in [max(z - t, z / 2), z + t]: the lower end kept positive so d' stays finite.
        const double den_lo = fb / (z + t);
        const double den_hi = fb / std::max(z - t, z / 2);
        double lo = (den_lo - o) / s, hi = (den_hi - o) / s;
        if (lo > hi) std::swap(lo, hi);
        auto ok = [&](T x) {
          const double dx = static_cast<double>(x);
          const double den_x = dx * s + o;
          if (!valid(dx) || !(den_x > 0)) return false;
          return std::abs(fb / den_x - z) <= t;
        };
        if (t > 0) result = Pick<T>(raw, lo, hi, ok);
        if (result != raw) ++stats->changed;
      }
      std::memcpy(dst + u * sizeof(T), &result, sizeof(T));
    }
  }
}

template <typename T>
void QuantizeDepthRows(const DepthView& in, const CameraModel& c, double bound,
                       const std::vector<double>& ray_x2, std::uint8_t* out,
                       QuantizeStats* stats) {
  const double scale = c.DepthScale(in.encoding);
  // The server's test of a depth (core's DepthConstants::Depth): z = raw * scale, in float, a
  // positive normal float.
  const float fscale = static_cast<float>(scale);
  auto valid = [&](double d) {
    const float f = static_cast<float>(d);
    return std::isfinite(f) && f * fscale >= std::numeric_limits<float>::min();
  };
  const std::size_t row_bytes = std::size_t{in.width} * sizeof(T);
  for (std::uint32_t v = 0; v < in.height; ++v) {
    const double ry = (v - c.cy) / c.fy;
    const Rays rays{ray_x2, ry * ry};
    const std::uint8_t* src = in.row(v);
    std::uint8_t* dst = out + v * row_bytes;
    for (std::uint32_t u = 0; u < in.width; ++u) {
      T raw;
      std::memcpy(&raw, src + u * sizeof(T), sizeof(T));
      const double d = static_cast<double>(raw);
      T result = raw;
      if (valid(d)) {
        ++stats->valid;
        // |D' - D| allowed, in raw units.
        const double t = (bound / rays.at(u) - kFloatError * std::abs(d * scale)) / std::abs(scale);
        // D' in [max(D - t, D / 2), D + t]: never 0 (valid depths are positive).
        const double lo = std::max(d - t, d / 2);
        const double hi = d + t;
        auto ok = [&](T x) {
          const double dx = static_cast<double>(x);
          return valid(dx) && std::abs(dx - d) <= t;
        };
        if (t > 0) result = Pick<T>(raw, lo, hi, ok);
        if (result != raw) ++stats->changed;
      }
      std::memcpy(dst + u * sizeof(T), &result, sizeof(T));
    }
  }
}

}  // namespace

std::uint32_t RoundestInRange(std::uint32_t lo, std::uint32_t hi) {
  if (lo >= hi) return lo;
  // lo and hi agree above their highest differing bit m, where lo has 0 and hi has 1. hi with
  // the bits below m cleared is in range and has m trailing zeros; only lo itself can have more
  // (when its bits up to m are all zero).
  const int m = 31 - __builtin_clz(lo ^ hi);  // lo != hi
  const std::uint64_t below_m_inclusive = (std::uint64_t{2} << m) - 1;
  if ((lo & below_m_inclusive) == 0) return lo;
  return hi & ~static_cast<std::uint32_t>((std::uint64_t{1} << m) - 1);
}

absl::Status PointErrorQuantizer::Quantize(const DisparityView& in, const CameraModel& camera,
                                           double max_point_error, std::string_view field,
                                           DisparityView* out) {
  if (absl::Status s = CheckInput(in, camera, max_point_error, field); !s.ok()) return s;
  stats_ = {};
  const std::size_t row_bytes = std::size_t{in.width} * BytesPerPixel(in.encoding);
  buffer_.resize(row_bytes * in.height);
  const double bound = max_point_error * kMargin;
  FillRayX2(camera, in.width, &ray_x2_);
  if (max_point_error == 0) {
    for (std::uint32_t v = 0; v < in.height; ++v) {
      std::memcpy(buffer_.data() + v * row_bytes, in.row(v), row_bytes);
    }
  } else {
    switch (in.encoding) {
      case DisparityEncoding::kU8:
        QuantizeDisparityRows<std::uint8_t>(in, camera, bound, ray_x2_, buffer_.data(), &stats_);
        break;
      case DisparityEncoding::kU16:
        QuantizeDisparityRows<std::uint16_t>(in, camera, bound, ray_x2_, buffer_.data(), &stats_);
        break;
      case DisparityEncoding::kF32:
        QuantizeDisparityRows<float>(in, camera, bound, ray_x2_, buffer_.data(), &stats_);
        break;
    }
  }
  *out = DisparityView{buffer_.data(), buffer_.size(), in.width, in.height, row_bytes,
                       in.encoding};
  return absl::OkStatus();
}

absl::Status PointErrorQuantizer::Quantize(const DepthView& in, const CameraModel& camera,
                                           double max_point_error, std::string_view field,
                                           DepthView* out) {
  if (absl::Status s = CheckInput(in, camera, max_point_error, field); !s.ok()) return s;
  stats_ = {};
  const std::size_t row_bytes = std::size_t{in.width} * BytesPerPixel(in.encoding);
  buffer_.resize(row_bytes * in.height);
  const double bound = max_point_error * kMargin;
  FillRayX2(camera, in.width, &ray_x2_);
  if (max_point_error == 0) {
    for (std::uint32_t v = 0; v < in.height; ++v) {
      std::memcpy(buffer_.data() + v * row_bytes, in.row(v), row_bytes);
    }
  } else {
    switch (in.encoding) {
      case DepthEncoding::kU16:
        QuantizeDepthRows<std::uint16_t>(in, camera, bound, ray_x2_, buffer_.data(), &stats_);
        break;
      case DepthEncoding::kF32:
        QuantizeDepthRows<float>(in, camera, bound, ray_x2_, buffer_.data(), &stats_);
        break;
    }
  }
  *out = DepthView{buffer_.data(), buffer_.size(), in.width, in.height, row_bytes, in.encoding};
  return absl::OkStatus();
}

}  // namespace cloudcast
