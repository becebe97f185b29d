// The AVX-512 kernels (compiled with -mavx512f -mavx512bw -mavx512vl -mavx512vbmi -mavx512bitalg
// -mbmi2 -mpopcnt; chosen at run time only on a CPU that has them: Ice Lake and later): sgm_simd.h
// over 64-byte vectors (the matcher pads the disparities to a multiple of 64 for them). GCC 12
// warns inside its own AVX-512 headers (_mm512_extracti64x4_epi64 and the like: their
// _mm*_undefined_* source operand, GCC bug 105593); nothing in this file is uninitialized.
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>

#include "sgm_simd.h"

namespace cloudcast::stereo::sgm {
namespace {

// The smallest byte of 32 (V512::HMin ends here).
std::uint8_t HMin256(__m256i v) {
  __m128i m = _mm_min_epu8(_mm256_castsi256_si128(v), _mm256_extracti128_si256(v, 1));
  m = _mm_min_epu8(m, _mm_srli_epi16(m, 8));
  m = _mm_minpos_epu16(_mm_and_si128(m, _mm_set1_epi16(0xFF)));
  return static_cast<std::uint8_t>(_mm_cvtsi128_si32(m));
}

struct V512 {
  using T = __m512i;
  static constexpr int kLanes = 64;
  static constexpr int kPlaneBits = 8;
  static T PopCount(T a) { return _mm512_popcnt_epi8(a); }  // AVX512_BITALG
  static T Zero() { return _mm512_setzero_si512(); }
  static T Set1(std::uint8_t v) { return _mm512_set1_epi8(static_cast<char>(v)); }
  static T Load(const void* p) { return _mm512_loadu_si512(p); }
  static void Store(void* p, T v) { _mm512_storeu_si512(p, v); }
  // S1, written once a frame and read back a pass later: past the caches (no read for ownership).
  // p is aligned: dp is a multiple of the lanes.
  static void StoreStream(void* p, T v) { _mm512_stream_si512(static_cast<__m512i*>(p), v); }
  static void StreamFence() { _mm_sfence(); }
  static T AddSat(T a, T b) { return _mm512_adds_epu8(a, b); }
  static T SubSat(T a, T b) { return _mm512_subs_epu8(a, b); }
  static T Min(T a, T b) { return _mm512_min_epu8(a, b); }
  static T Max(T a, T b) { return _mm512_max_epu8(a, b); }
  static T Add8(T a, T b) { return _mm512_add_epi8(a, b); }
  static T Xor(T a, T b) { return _mm512_xor_si512(a, b); }
  static T UnpackLo8(T a, T b) { return _mm512_unpacklo_epi8(a, b); }
  static T UnpackHi8(T a, T b) { return _mm512_unpackhi_epi8(a, b); }
  static T Min16(T a, T b) { return _mm512_min_epu16(a, b); }
  static int HMin16(T v) {
    const __m256i h = _mm256_min_epu16(_mm512_castsi512_si256(v), _mm512_extracti64x4_epi64(v, 1));
    const __m128i m = _mm_min_epu16(_mm256_castsi256_si128(h), _mm256_extracti128_si256(h, 1));
    return _mm_cvtsi128_si32(_mm_minpos_epu16(m)) & 0xFFFF;
  }
  static T Or(T a, T b) { return _mm512_or_si512(a, b); }
  static T FirstLane255() { return _mm512_setr_epi64(0xFF, 0, 0, 0, 0, 0, 0, 0); }
  static T LastLane255() {
    return _mm512_setr_epi64(0, 0, 0, 0, 0, 0, 0, static_cast<long long>(0xFF00000000000000ull));
  }
  static T Lookup(T table, T index) { return _mm512_shuffle_epi8(table, index); }
  // Bits set in 0..15, in every 128-bit lane (a constant: _mm512_broadcast_i32x4 trips GCC 12's
  // uninitialized warning in its own header).
  static T NibbleCounts() {
    const long long lo = 0x0302020102010100LL, hi = 0x0403030203020201LL;
    return _mm512_set_epi64(hi, lo, hi, lo, hi, lo, hi, lo);
  }

  static T PushBit(T acc, T a, T b) {
    const T twice = _mm512_add_epi8(acc, acc);
    return _mm512_mask_add_epi8(twice, _mm512_cmpgt_epi8_mask(a, b), twice, _mm512_set1_epi8(1));
  }
  static std::uint8_t HMin(T v) {
    return HMin256(_mm256_min_epu8(_mm512_castsi512_si256(v), _mm512_extracti64x4_epi64(v, 1)));
  }
  // Lane i: i == 0 ? a[63] : b[i - 1], and i == 63 ? b[0] : a[i + 1] (alignr works per 128-bit
  // lane; valignq brings the neighbouring lane in).
  static T ShiftInBelow(T a, T b) {
    return _mm512_alignr_epi8(b, _mm512_alignr_epi64(b, a, 6), 15);
  }
  static T ShiftInAbove(T a, T b) { return _mm512_alignr_epi8(_mm512_alignr_epi64(b, a, 2), a, 1); }
  static T HalveUp(T a) { return _mm512_avg_epu8(a, _mm512_setzero_si512()); }
  // 64 pixels at a time, by a tree that halves each pixel's bytes while it merges vectors (three
  // instructions per pair), so a pixel costs about 3 instructions instead of a reduction of its
  // own. Comments give the pixels (of the group of 64) each vector holds, in order.
  static void RowMinima(const std::uint8_t* vectors, int n, std::uint8_t* minima) {
    // After the tree, byte j of a group of 16 holds pixel j / 4 + 4 * (j % 4).
    const __m128i order = _mm_setr_epi8(0, 4, 8, 12, 1, 5, 9, 13, 2, 6, 10, 14, 3, 7, 11, 15);
    for (int g = 0; g < n; g += 64) {
      const std::uint8_t* v = vectors + static_cast<std::size_t>(g) * 64;
      T l1[32], l2[16], l3[8], l4[4];
      for (int i = 0; i < 32; ++i) {  // 32 bytes each of pixels 2i, 2i + 1
        const T a = Load(v + 128 * i), b = Load(v + 128 * i + 64);
        l1[i] = Min(_mm512_shuffle_i64x2(a, b, 0x44), _mm512_shuffle_i64x2(a, b, 0xEE));
      }
      for (int i = 0; i < 16; ++i) {  // 16 bytes each of pixels 4i .. 4i + 3
        l2[i] = Min(_mm512_shuffle_i64x2(l1[2 * i], l1[2 * i + 1], 0x88),
                    _mm512_shuffle_i64x2(l1[2 * i], l1[2 * i + 1], 0xDD));
      }
      for (int i = 0; i < 8; ++i) {  // 8 bytes each: lane L pixels 8i + L, 8i + 4 + L
        l3[i] = Min(_mm512_unpacklo_epi64(l2[2 * i], l2[2 * i + 1]),
                    _mm512_unpackhi_epi64(l2[2 * i], l2[2 * i + 1]));
      }
      for (int i = 0; i < 4; ++i) {  // 4 bytes each: lane L pixels 16i + L + 0, 4, 8, 12
        const __m512 a = _mm512_castsi512_ps(l3[2 * i]), b = _mm512_castsi512_ps(l3[2 * i + 1]);
        l4[i] = Min(_mm512_castps_si512(_mm512_shuffle_ps(a, b, 0x88)),
                    _mm512_castps_si512(_mm512_shuffle_ps(a, b, 0xDD)));
      }
      for (int i = 0; i < 4; ++i) {
        T m = Min(l4[i], _mm512_srli_epi32(l4[i], 16));
        m = Min(m, _mm512_srli_epi32(m, 8));  // byte 0 of each 4: their minimum
        const __m128i out = _mm_shuffle_epi8(_mm512_cvtepi32_epi8(m), order);
        _mm_storeu_si128(reinterpret_cast<__m128i*>(minima + g + 16 * i), out);
      }
    }
  }
  static std::uint64_t EqMask(T a, T b) { return _mm512_cmpeq_epi8_mask(a, b); }
  static std::uint64_t LessEqMask(T a, T b) { return _mm512_cmple_epu8_mask(a, b); }
};

// CheckPixel, 16 pixels at a time: the parabola's division in float lanes (the same IEEE division
// as the scalar one), the right matches by gather.
void CheckRow(const CheckArgs& a) {
  const __m512i lanes = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
  const __m512i none = _mm512_set1_epi32(kNoMatch), width = _mm512_set1_epi32(a.width);
  const __m512i tolerance = _mm512_set1_epi32(a.tolerance), fifteen = _mm512_set1_epi32(15);
  const __m512i byte = _mm512_set1_epi32(255), one = _mm512_set1_epi32(1);
  int x = 0;
  for (; x + 16 <= a.width; x += 16) {
    const __m512i d = _mm512_loadu_si512(a.disparity + x);
    const __m512i p = _mm512_loadu_si512(a.parabola + x);
    const __m512i before = _mm512_and_si512(p, byte);
    const __m512i after = _mm512_and_si512(_mm512_srli_epi32(p, 8), byte);
    const __m512i here = _mm512_and_si512(_mm512_srli_epi32(p, 16), byte);
    const __mmask16 inner = _mm512_test_epi32_mask(p, _mm512_set1_epi32(1 << 24));
    const __m512i denom2 = _mm512_max_epi32(
        _mm512_sub_epi32(_mm512_add_epi32(before, after), _mm512_slli_epi32(here, 1)), one);
    const __m512i num =
        _mm512_add_epi32(_mm512_slli_epi32(_mm512_sub_epi32(before, after), 4), denom2);
    const __m512i fraction = _mm512_maskz_cvttps_epi32(
        inner,
        _mm512_div_ps(_mm512_cvtepi32_ps(num), _mm512_cvtepi32_ps(_mm512_slli_epi32(denom2, 1))));
    const __mmask16 matched = _mm512_cmpneq_epi32_mask(d, none);
    const __m512i d1 = _mm512_add_epi32(_mm512_slli_epi32(d, 4), fraction);
    __mmask16 keep = matched & _mm512_cmpgt_epi32_mask(d1, _mm512_setzero_si512());
    if (a.tolerance >= 0) {
      const __m512i xs = _mm512_add_epi32(_mm512_set1_epi32(x), lanes);
      const __m512i d_lo = _mm512_srai_epi32(d1, 4);
      const __m512i d_hi = _mm512_srai_epi32(_mm512_add_epi32(d1, fifteen), 4);
      __m512i x_lo = _mm512_sub_epi32(xs, d_lo), x_hi = _mm512_sub_epi32(xs, d_hi);
      x_lo =
          _mm512_mask_mov_epi32(x_lo, _mm512_cmplt_epi32_mask(x_lo, _mm512_setzero_si512()), width);
      x_hi =
          _mm512_mask_mov_epi32(x_hi, _mm512_cmplt_epi32_mask(x_hi, _mm512_setzero_si512()), width);
      // Lanes without a match gather slot width (kNoMatch), and are dropped anyway.
      x_lo = _mm512_mask_mov_epi32(width, keep, x_lo);
      x_hi = _mm512_mask_mov_epi32(width, keep, x_hi);
      const __m512i r_lo = _mm512_i32gather_epi32(x_lo, a.right_disparity, 4);
      const __m512i r_hi = _mm512_i32gather_epi32(x_hi, a.right_disparity, 4);
      const __mmask16 bad_lo =
          _mm512_cmpneq_epi32_mask(r_lo, none) &
          _mm512_cmpgt_epi32_mask(_mm512_abs_epi32(_mm512_sub_epi32(r_lo, d_lo)), tolerance);
      const __mmask16 bad_hi =
          _mm512_cmpneq_epi32_mask(r_hi, none) &
          _mm512_cmpgt_epi32_mask(_mm512_abs_epi32(_mm512_sub_epi32(r_hi, d_hi)), tolerance);
      keep &= static_cast<__mmask16>(~(bad_lo & bad_hi));
    }
    const __m512i out = _mm512_maskz_mov_epi32(keep, d1);
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(a.out + x), _mm512_cvtepi32_epi16(out));
  }
  for (; x < a.width; ++x) a.out[x] = CheckPixel(a, x);
}

void Census(const CensusArgs& a) { simd::Census<V512>(a); }
void Forward(const RowArgs& a) { simd::Row<V512, true>(a); }
void Backward(const RowArgs& a) { simd::Row<V512, false>(a); }

}  // namespace

const Kernels* Avx512Kernels() {
  static const Kernels k{"avx512", 64, 8, Census, Forward, Backward, CheckRow};
  return &k;
}

}  // namespace cloudcast::stereo::sgm
