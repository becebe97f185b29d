#include "yuv.h"

#include <cstring>
#include <utility>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "libyuv/convert.h"
#include "libyuv/convert_argb.h"
#include "libyuv/convert_from_argb.h"
#include "libyuv/planar_functions.h"
#include "libyuv/scale.h"

namespace cloudcast::video::internal {
namespace {

using Layout = YuvPlanes::Layout;

// libyuv names packed formats by their order in a little-endian word: its RGB24 is our BGR8 (B,
// G, R in memory), RAW our RGB8, ABGR our RGBA8, and ARGB is B, G, R, A in memory.

// BT.601 limited range with 15-bit fractions: with L = Kr R + Kg G + Kb B, Y' = 16 + 219/255 L,
// Cb = 128 + 224/255 (B - L) / 1.772, Cr = 128 + 224/255 (R - L) / 1.402. Rounding the
// coefficients moves a sample by at most 255 * 3 / 2^16 of a level (1/85), so every sample is the
// exact colour rounded, or its neighbour where the exact value lies within 1/85 of a level of the
// halfway point. The results stay in [16, 240]: no clamping. 15
// bits keep each coefficient in an int16, for SSE2's multiply-add of pairs.
constexpr int kFractionBits = 15;
constexpr std::int32_t Fixed(double v) {
  return static_cast<std::int32_t>(v * (1 << kFractionBits) + (v < 0 ? -0.5 : 0.5));
}
constexpr double kKr = 0.299, kKg = 0.587, kKb = 0.114;
constexpr std::int32_t Luma(double k) { return Fixed(k * 219.0 / 255.0); }
constexpr std::int32_t Chroma(double k) { return Fixed(k * 224.0 / 255.0); }
constexpr std::int32_t Offset(int level) {
  return (level << kFractionBits) + (1 << (kFractionBits - 1));  // with the rounding half
}
constexpr double kCbScale = 2 * (1 - kKb), kCrScale = 2 * (1 - kKr);  // 1.772, 1.402
// Per output: the R, G and B coefficients, then the offset.
constexpr std::int32_t kY[4] = {Luma(kKr), Luma(kKg), Luma(kKb), Offset(16)};
constexpr std::int32_t kU[4] = {Chroma(-kKr / kCbScale), Chroma(-kKg / kCbScale), Chroma(0.5),
                                Offset(128)};
constexpr std::int32_t kV[4] = {Chroma(0.5), Chroma(-kKg / kCrScale), Chroma(-kKb / kCrScale),
                                Offset(128)};

std::uint8_t Sample(const std::int32_t (&k)[4], std::int32_t r, std::int32_t g, std::int32_t b) {
  return static_cast<std::uint8_t>((k[0] * r + k[1] * g + k[2] * b + k[3]) >> kFractionBits);
}

#if defined(__SSE2__)
// SSE2 (every x86-64) has no 32-bit multiply; its multiply-add of int16 pairs does a sample's sum
// in two: (R, G) by the first two coefficients, (B, 256) by the third and the offset / 256.
constexpr int kOffsetLane = 256;
constexpr bool FitsPairs(const std::int32_t (&k)[4]) {
  for (int i = 0; i < 3; ++i) {
    if (k[i] < -32768 || k[i] > 32767) return false;
  }
  return k[3] % kOffsetLane == 0 && k[3] / kOffsetLane <= 32767;
}
static_assert(FitsPairs(kY) && FitsPairs(kU) && FitsPairs(kV));

// Four (low, high) int16 pairs, low first in memory.
__m128i Pair(std::int32_t low, std::int32_t high) {
  const auto l = static_cast<std::int16_t>(low), h = static_cast<std::int16_t>(high);
  return _mm_set_epi16(h, l, h, l, h, l, h, l);
}

struct Coefficients {
  __m128i rg, b_offset;
  explicit Coefficients(const std::int32_t (&k)[4])
      : rg(Pair(k[0], k[1])), b_offset(Pair(k[2], k[3] / kOffsetLane)) {}
};

// Eight samples (int16 lanes) from eight pixels' R, G, B (int16 lanes).
__m128i Samples8(const Coefficients& k, __m128i r, __m128i g, __m128i b) {
  const __m128i offset = _mm_set1_epi16(kOffsetLane);
  const __m128i rg_lo = _mm_unpacklo_epi16(r, g), rg_hi = _mm_unpackhi_epi16(r, g);
  const __m128i bo_lo = _mm_unpacklo_epi16(b, offset), bo_hi = _mm_unpackhi_epi16(b, offset);
  const __m128i lo = _mm_srai_epi32(
      _mm_add_epi32(_mm_madd_epi16(rg_lo, k.rg), _mm_madd_epi16(bo_lo, k.b_offset)), kFractionBits);
  const __m128i hi = _mm_srai_epi32(
      _mm_add_epi32(_mm_madd_epi16(rg_hi, k.rg), _mm_madd_epi16(bo_hi, k.b_offset)), kFractionBits);
  return _mm_packs_epi32(lo, hi);
}
#endif

// One row of planar R, G, B into Y, Cb, Cr, on rows short enough to stay in L1 between libyuv's
// split and here.
void PlanarRowTo444(const std::uint8_t* r, const std::uint8_t* g, const std::uint8_t* b,
                    std::uint8_t* y, std::uint8_t* u, std::uint8_t* v, int width) {
  int x = 0;
#if defined(__SSE2__)
  const Coefficients ky(kY), ku(kU), kv(kV);
  const __m128i zero = _mm_setzero_si128();
  for (; x + 16 <= width; x += 16) {
    const __m128i r8 = _mm_loadu_si128(reinterpret_cast<const __m128i*>(r + x));
    const __m128i g8 = _mm_loadu_si128(reinterpret_cast<const __m128i*>(g + x));
    const __m128i b8 = _mm_loadu_si128(reinterpret_cast<const __m128i*>(b + x));
    const __m128i r_lo = _mm_unpacklo_epi8(r8, zero), r_hi = _mm_unpackhi_epi8(r8, zero);
    const __m128i g_lo = _mm_unpacklo_epi8(g8, zero), g_hi = _mm_unpackhi_epi8(g8, zero);
    const __m128i b_lo = _mm_unpacklo_epi8(b8, zero), b_hi = _mm_unpackhi_epi8(b8, zero);
    _mm_storeu_si128(
        reinterpret_cast<__m128i*>(y + x),
        _mm_packus_epi16(Samples8(ky, r_lo, g_lo, b_lo), Samples8(ky, r_hi, g_hi, b_hi)));
    _mm_storeu_si128(
        reinterpret_cast<__m128i*>(u + x),
        _mm_packus_epi16(Samples8(ku, r_lo, g_lo, b_lo), Samples8(ku, r_hi, g_hi, b_hi)));
    _mm_storeu_si128(
        reinterpret_cast<__m128i*>(v + x),
        _mm_packus_epi16(Samples8(kv, r_lo, g_lo, b_lo), Samples8(kv, r_hi, g_hi, b_hi)));
  }
#endif
  for (; x < width; ++x) {
    y[x] = Sample(kY, r[x], g[x], b[x]);
    u[x] = Sample(kU, r[x], g[x], b[x]);
    v[x] = Sample(kV, r[x], g[x], b[x]);
  }
}

void CopyPlane(const std::uint8_t* src, int src_stride, std::uint8_t* dst, int dst_stride,
               int width, int height) {
  for (int v = 0; v < height; ++v) {
    std::memcpy(dst + static_cast<std::ptrdiff_t>(v) * dst_stride,
                src + static_cast<std::ptrdiff_t>(v) * src_stride, static_cast<std::size_t>(width));
  }
}

}  // namespace

absl::Status PackedToYuv::Convert(const std::uint8_t* src, int src_stride, ColorEncoding from,
                                  int width, int height, const YuvPlanes& dst) {
  const YuvPlanes& d = dst;
  if (d.layout == Layout::kGrey || d.full_range) {
    return absl::InternalError("PackedToYuv makes limited-range 4:2:0 or 4:4:4 pictures only");
  }
  if (d.layout == Layout::k444) {
    // Each row split into planes by libyuv, then converted by ours: see yuv.h.
    const auto w = static_cast<std::size_t>(width);
    scratch_.resize(3 * w);
    std::uint8_t* first = scratch_.data();  // the row's channels in memory order
    std::uint8_t* second = first + w;
    std::uint8_t* third = second + w;
    for (int row = 0; row < height; ++row) {
      const std::uint8_t* in = src + static_cast<std::ptrdiff_t>(row) * src_stride;
      const std::uint8_t *r = first, *g = second, *b = third;
      switch (from) {
        case ColorEncoding::kBGR8:
        case ColorEncoding::kRGB8:
          libyuv::SplitRGBPlane(in, src_stride, first, width, second, width, third, width, width,
                                1);
          if (from == ColorEncoding::kBGR8) std::swap(r, b);
          break;
        case ColorEncoding::kRGBA8:  // libyuv's ARGB split reads B, G, R, A: ours is R, G, B, A
          libyuv::SplitARGBPlane(in, src_stride, third, width, second, width, first, width, nullptr,
                                 0, width, 1);
          break;
        case ColorEncoding::kMono8:
          r = g = b = in;
          break;
        default:
          return absl::InvalidArgumentError("PackedToYuv: an unknown packed encoding");
      }
      PlanarRowTo444(r, g, b, d.y + static_cast<std::ptrdiff_t>(row) * d.y_stride,
                     d.u + static_cast<std::ptrdiff_t>(row) * d.u_stride,
                     d.v + static_cast<std::ptrdiff_t>(row) * d.v_stride, width);
    }
    return absl::OkStatus();
  }
  int rc = -1;
  switch (from) {
    case ColorEncoding::kBGR8:
      rc = libyuv::RGB24ToI420(src, src_stride, d.y, d.y_stride, d.u, d.u_stride, d.v, d.v_stride,
                               width, height);
      break;
    case ColorEncoding::kRGB8:
      rc = libyuv::RAWToI420(src, src_stride, d.y, d.y_stride, d.u, d.u_stride, d.v, d.v_stride,
                             width, height);
      break;
    case ColorEncoding::kRGBA8:
      rc = libyuv::ABGRToI420(src, src_stride, d.y, d.y_stride, d.u, d.u_stride, d.v, d.v_stride,
                              width, height);
      break;
    case ColorEncoding::kMono8: {  // full range, as swscale reads grey: r = g = b = y
      scratch_.resize(static_cast<std::size_t>(width) * 4 * static_cast<std::size_t>(height));
      rc = libyuv::J400ToARGB(src, src_stride, scratch_.data(), width * 4, width, height);
      if (rc == 0) {
        rc = libyuv::ARGBToI420(scratch_.data(), width * 4, d.y, d.y_stride, d.u, d.u_stride, d.v,
                                d.v_stride, width, height);
      }
      break;
    }
  }
  if (rc != 0) return absl::InternalError("libyuv cannot convert the image to YUV");
  return absl::OkStatus();
}

absl::Status YuvToPacked(const YuvPlanes& src, int width, int height, ColorEncoding to,
                         std::uint8_t* dst, int dst_stride) {
  const YuvPlanes& s = src;
  if (to == ColorEncoding::kMono8) {
    CopyPlane(s.y, s.y_stride, dst, dst_stride, width, height);
    return absl::OkStatus();
  }
  if (s.layout == Layout::kGrey) {  // full range: r = g = b = y
    for (int v = 0; v < height; ++v) {
      const std::uint8_t* in = s.y + static_cast<std::ptrdiff_t>(v) * s.y_stride;
      std::uint8_t* out = dst + static_cast<std::ptrdiff_t>(v) * dst_stride;
      if (to == ColorEncoding::kRGBA8) {
        for (int x = 0; x < width; ++x, out += 4) out[0] = out[1] = out[2] = in[x], out[3] = 255;
      } else {
        for (int x = 0; x < width; ++x, out += 3) out[0] = out[1] = out[2] = in[x];
      }
    }
    return absl::OkStatus();
  }
  // Our RGB8 and RGBA8 put red first, libyuv's RGB24 and ARGB blue: the same conversion with U
  // and V swapped and the matrix mirrored (libyuv's own way to its RAW and ABGR).
  const bool red_first = to != ColorEncoding::kBGR8;
  const libyuv::YuvConstants* m =
      s.full_range ? (red_first ? &libyuv::kYvuJPEGConstants : &libyuv::kYuvJPEGConstants)
                   : (red_first ? &libyuv::kYvuI601Constants : &libyuv::kYuvI601Constants);
  const std::uint8_t* u = red_first ? s.v : s.u;
  const std::uint8_t* v = red_first ? s.u : s.v;
  const int us = red_first ? s.v_stride : s.u_stride;
  const int vs = red_first ? s.u_stride : s.v_stride;
  const bool four = to == ColorEncoding::kRGBA8;
  int rc;
  if (s.layout == Layout::k444) {
    rc = four ? libyuv::I444ToARGBMatrix(s.y, s.y_stride, u, us, v, vs, dst, dst_stride, m, width,
                                         height)
              : libyuv::I444ToRGB24Matrix(s.y, s.y_stride, u, us, v, vs, dst, dst_stride, m, width,
                                          height);
  } else {  // chroma interpolated, as swscale's was: 0.3 dB closer than repeated, for 0.05 ms
    rc = four ? libyuv::I420ToARGBMatrixFilter(s.y, s.y_stride, u, us, v, vs, dst, dst_stride, m,
                                               width, height, libyuv::kFilterBilinear)
              : libyuv::I420ToRGB24MatrixFilter(s.y, s.y_stride, u, us, v, vs, dst, dst_stride, m,
                                                width, height, libyuv::kFilterBilinear);
  }
  if (rc != 0) return absl::InternalError("libyuv cannot convert the picture");
  return absl::OkStatus();
}

}  // namespace cloudcast::video::internal
