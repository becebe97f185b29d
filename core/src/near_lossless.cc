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

// The longest ray of the image: |P' - P| = |z' - z| * ray, ray = sqrt(1 + ((u - cx) / fx)^2 +
// ((v - cy) / fy)^2), largest at a corner. The quantizer bounds every pixel with it, so that its
// choice depends on the value alone: equal values stay equal (a smooth region keeps its runs),
// and 8- and 16-bit samples are mapped through a table.
double LongestRay(const CameraModel& c, std::uint32_t width, std::uint32_t height) {
  double longest = 1;
  for (double u : {0.0, width - 1.0}) {
    for (double v : {0.0, height - 1.0}) {
      const double a = (u - c.cx) / c.fx, b = (v - c.cy) / c.fy;
      longest = std::max(longest, std::sqrt(1 + a * a + b * b));
    }
  }
  return longest;
}

// A disparity value's replacement, `valid` false for a value the server makes no point of.
struct DisparityMapper {
  double fb, s, o, bound;  // bound: on |z' - z|, before the float margin
  float ffb, fs, fo;
  const std::vector<double>* invalid;

  DisparityMapper(const CameraModel& c, double z_bound)
      : fb(c.fx * c.baseline),
        s(c.disparity_scale),
        o(c.disparity_offset),
        bound(z_bound),
        ffb(static_cast<float>(fb)),
        fs(static_cast<float>(s)),
        fo(static_cast<float>(o)),
        invalid(&c.invalid_disparities) {}

  // Whether the server makes a point of a raw value: its test, in its float arithmetic
  // (camera.h; core's DepthConstants::Depth), so that validity is kept exactly.
  bool Valid(double d) const {
    const float f = static_cast<float>(d);
    if (!std::isfinite(f)) return false;
    for (double v : *invalid) {
      if (f == static_cast<float>(v)) return false;
    }
    const float den = f * fs + fo;
    return den > 0.0f && std::isfinite(ffb / den) && d * s + o > 0;
  }

  template <typename T>
  T Map(T raw, bool* valid) const {
    const double d = static_cast<double>(raw);
    *valid = Valid(d);
    if (!*valid) return raw;
    const double z = fb / (d * s + o);
    const double t = bound - kFloatError * std::abs(z);  // |z' - z| allowed
    if (!(t > 0)) return raw;
    // z' in [max(z - t, z / 2), z + t]: the lower end kept positive so d' stays finite.
    double lo = (fb / (z + t) - o) / s, hi = (fb / std::max(z - t, z / 2) - o) / s;
    if (lo > hi) std::swap(lo, hi);
    return Pick<T>(raw, lo, hi, [&](T x) {
      const double dx = static_cast<double>(x);
      return Valid(dx) && std::abs(fb / (dx * s + o) - z) <= t;
    });
  }
};

// A depth value's replacement.
struct DepthMapper {
  double scale, bound;  // bound: on |z' - z|, before the float margin
  float fscale;

  DepthMapper(const CameraModel& c, DepthEncoding e, double z_bound)
      : scale(c.DepthScale(e)), bound(z_bound), fscale(static_cast<float>(scale)) {}

  // The server's test of a depth (core's DepthConstants::Depth): z = raw * scale, in float, a
  // positive normal float.
  bool Valid(double d) const {
    const float f = static_cast<float>(d);
    return std::isfinite(f) && f * fscale >= std::numeric_limits<float>::min();
  }

  template <typename T>
  T Map(T raw, bool* valid) const {
    const double d = static_cast<double>(raw);
    *valid = Valid(d);
    if (!*valid) return raw;
    const double t = (bound - kFloatError * std::abs(d * scale)) / std::abs(scale);  // raw units
    if (!(t > 0)) return raw;
    // D' in [max(D - t, D / 2), D + t]: never 0 (valid depths are positive).
    return Pick<T>(raw, std::max(d - t, d / 2), d + t, [&](T x) {
      const double dx = static_cast<double>(x);
      return Valid(dx) && std::abs(dx - d) <= t;
    });
  }
};

// Every pixel of `in` through `mapper` into packed rows at `out`. 8- and 16-bit samples go
// through a table of the values met (`table`: value -> replacement + 1, 0 = not yet).
template <typename T, typename View, typename Mapper>
void MapRows(const View& in, const Mapper& mapper, std::vector<std::uint32_t>* table,
             std::uint8_t* out, QuantizeStats* stats) {
  constexpr bool kTabled = std::is_integral_v<T>;
  constexpr std::uint32_t kValidBit = 1u << 31;
  if constexpr (kTabled) table->assign(std::size_t{1} << (8 * sizeof(T)), 0);
  const std::size_t row_bytes = std::size_t{in.width} * sizeof(T);
  [[maybe_unused]] T last_raw{}, last_result{};  // floats: the previous pixel's value, replacement
  [[maybe_unused]] bool last_valid = false;
  // Counted in locals: through `stats` every byte stored to `out` (which may alias it) would
  // force a reload.
  std::uint64_t valid_count = 0, changed_count = 0;
  for (std::uint32_t v = 0; v < in.height; ++v) {
    const std::uint8_t* src = in.row(v);
    std::uint8_t* dst = out + v * row_bytes;
    for (std::uint32_t u = 0; u < in.width; ++u) {
      T raw;  // read through memcpy: views need not be aligned
      std::memcpy(&raw, src + u * sizeof(T), sizeof(T));
      T result;
      bool valid;
      if constexpr (kTabled) {
        std::uint32_t& entry = (*table)[raw];
        if (entry == 0) {
          result = mapper.Map(raw, &valid);
          entry = (std::uint32_t{result} + 1) | (valid ? kValidBit : 0);
        }
        result = static_cast<T>((entry & ~kValidBit) - 1);
        valid = (entry & kValidBit) != 0;
      } else if (u > 0 && std::memcmp(&raw, &last_raw, sizeof(T)) == 0) {
        result = last_result;  // runs of one value (a plane, a hole) cost one Map
        valid = last_valid;
      } else {
        result = mapper.Map(raw, &valid);
        last_raw = raw;
        last_result = result;
        last_valid = valid;
      }
      valid_count += valid;
      changed_count += std::memcmp(&result, &raw, sizeof(T)) != 0;
      std::memcpy(dst + u * sizeof(T), &result, sizeof(T));
    }
  }
  stats->valid = valid_count;
  stats->changed = changed_count;
}

// Sizes `buffer` for `in`'s rows packed (no row padding) and returns a row's bytes; with `copy`
// (a bound of 0: lossless) copies them in, else the caller maps each pixel into it.
template <typename View>
std::size_t PackRows(const View& in, bool copy, std::vector<std::uint8_t>* buffer) {
  const std::size_t row_bytes = std::size_t{in.width} * BytesPerPixel(in.encoding);
  buffer->resize(row_bytes * in.height);
  if (copy) {
    for (std::uint32_t v = 0; v < in.height; ++v) {
      std::memcpy(buffer->data() + v * row_bytes, in.row(v), row_bytes);
    }
  }
  return row_bytes;
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
  const std::size_t row_bytes = PackRows(in, max_point_error == 0, &buffer_);
  if (max_point_error != 0) {
    const DisparityMapper mapper(
        camera, max_point_error * kMargin / LongestRay(camera, in.width, in.height));
    switch (in.encoding) {
      case DisparityEncoding::kU8:
        MapRows<std::uint8_t>(in, mapper, &table_, buffer_.data(), &stats_);
        break;
      case DisparityEncoding::kU16:
        MapRows<std::uint16_t>(in, mapper, &table_, buffer_.data(), &stats_);
        break;
      case DisparityEncoding::kF32:
        MapRows<float>(in, mapper, &table_, buffer_.data(), &stats_);
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
  const std::size_t row_bytes = PackRows(in, max_point_error == 0, &buffer_);
  if (max_point_error != 0) {
    const DepthMapper mapper(camera, in.encoding,
                             max_point_error * kMargin / LongestRay(camera, in.width, in.height));
    switch (in.encoding) {
      case DepthEncoding::kU16:
        MapRows<std::uint16_t>(in, mapper, &table_, buffer_.data(), &stats_);
        break;
      case DepthEncoding::kF32:
        MapRows<float>(in, mapper, &table_, buffer_.data(), &stats_);
        break;
    }
  }
  *out = DepthView{buffer_.data(), buffer_.size(), in.width, in.height, row_bytes, in.encoding};
  return absl::OkStatus();
}

}  // namespace cloudcast
