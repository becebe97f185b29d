// The AVX2 kernels (compiled with -mavx2 -mbmi2 -mpopcnt; chosen at run time only on a CPU that
// has them): sgm_simd.h over 32-byte vectors.
#include <immintrin.h>

#include "sgm_simd.h"

namespace cloudcast::stereo::sgm {
namespace {

struct V256 {
  using T = __m256i;
  static constexpr int kLanes = 32;
  static constexpr int kPlaneBits = 4;
  static T Zero() { return _mm256_setzero_si256(); }
  static T Set1(std::uint8_t v) { return _mm256_set1_epi8(static_cast<char>(v)); }
  static T Load(const void* p) { return _mm256_loadu_si256(static_cast<const __m256i*>(p)); }
  static void Store(void* p, T v) { _mm256_storeu_si256(static_cast<__m256i*>(p), v); }
  // S1, written once a frame and read back a pass later: past the caches (no read for ownership).
  // p is aligned: dp is a multiple of the lanes.
  static void StoreStream(void* p, T v) { _mm256_stream_si256(static_cast<__m256i*>(p), v); }
  static void StreamFence() { _mm_sfence(); }
  static T AddSat(T a, T b) { return _mm256_adds_epu8(a, b); }
  static T SubSat(T a, T b) { return _mm256_subs_epu8(a, b); }
  static T Min(T a, T b) { return _mm256_min_epu8(a, b); }
  static T Max(T a, T b) { return _mm256_max_epu8(a, b); }
  static T Add8(T a, T b) { return _mm256_add_epi8(a, b); }
  static T Xor(T a, T b) { return _mm256_xor_si256(a, b); }
  static T UnpackLo8(T a, T b) { return _mm256_unpacklo_epi8(a, b); }
  static T UnpackHi8(T a, T b) { return _mm256_unpackhi_epi8(a, b); }
  static T Min16(T a, T b) { return _mm256_min_epu16(a, b); }
  static int HMin16(T v) {
    const __m128i m = _mm_min_epu16(_mm256_castsi256_si128(v), _mm256_extracti128_si256(v, 1));
    return _mm_cvtsi128_si32(_mm_minpos_epu16(m)) & 0xFFFF;
  }
  static T Or(T a, T b) { return _mm256_or_si256(a, b); }
  static T FirstLane255() { return _mm256_setr_epi64x(0xFF, 0, 0, 0); }
  static T LastLane255() {
    return _mm256_setr_epi64x(0, 0, 0, static_cast<long long>(0xFF00000000000000ull));
  }
  static T Lookup(T table, T index) { return _mm256_shuffle_epi8(table, index); }
  static T NibbleCounts() {
    return _mm256_setr_epi8(0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4, 0, 1, 1, 2, 1, 2, 2, 3,
                            1, 2, 2, 3, 2, 3, 3, 4);
  }
  // acc * 2 + 1 where a > b: the compare gives -1 there.
  static T PushBit(T acc, T a, T b) {
    return _mm256_sub_epi8(_mm256_add_epi8(acc, acc), _mm256_cmpgt_epi8(a, b));
  }
  static std::uint8_t HMin(T v) {
    __m128i m = _mm_min_epu8(_mm256_castsi256_si128(v), _mm256_extracti128_si256(v, 1));
    m = _mm_min_epu8(m, _mm_srli_epi16(m, 8));  // each 16-bit lane: the min of its two bytes
    m = _mm_minpos_epu16(_mm_and_si128(m, _mm_set1_epi16(0xFF)));
    return static_cast<std::uint8_t>(_mm_cvtsi128_si32(m));
  }
  // Lane i: i == 0 ? a[31] : b[i - 1], and i == 31 ? b[0] : a[i + 1] (alignr works per 128-bit
  // lane; the permute brings the neighbouring half in).
  static T ShiftInBelow(T a, T b) {
    return _mm256_alignr_epi8(b, _mm256_permute2x128_si256(a, b, 0x21), 15);
  }
  static T ShiftInAbove(T a, T b) {
    return _mm256_alignr_epi8(_mm256_permute2x128_si256(a, b, 0x21), a, 1);
  }
  static T HalveUp(T a) { return _mm256_avg_epu8(a, _mm256_setzero_si256()); }
  // 32 pixels at a time, by a tree that halves each pixel's bytes while it merges vectors (three
  // instructions per pair), so a pixel costs 3.5 instructions instead of a reduction of its own.
  // Comments give the pixels (of the group of 32) each vector holds, in order.
  static void RowMinima(const std::uint8_t* vectors, int n, std::uint8_t* minima) {
    const __m128i first_bytes =
        _mm_setr_epi8(0, 4, 8, 12, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1);
    const T gather = _mm256_broadcastsi128_si256(first_bytes);
    for (int g = 0; g < n; g += 32) {
      const std::uint8_t* v = vectors + static_cast<std::size_t>(g) * 32;
      T l1[16], l2[8], l3[4];
      for (int i = 0; i < 16; ++i) {  // 16 bytes each of pixels 2i, 2i + 1
        const T a = Load(v + 64 * i), b = Load(v + 64 * i + 32);
        l1[i] = Min(_mm256_permute2x128_si256(a, b, 0x20), _mm256_permute2x128_si256(a, b, 0x31));
      }
      for (int i = 0; i < 8;
           ++i) {  // 8 bytes each: lane 0 pixels 4i, 4i + 2; lane 1 4i + 1, 4i + 3
        l2[i] = Min(_mm256_unpacklo_epi64(l1[2 * i], l1[2 * i + 1]),
                    _mm256_unpackhi_epi64(l1[2 * i], l1[2 * i + 1]));
      }
      for (int i = 0; i < 4; ++i) {  // 4 bytes each: lane 0 pixels 8i + 0, 2, 4, 6; lane 1 + 1
        const __m256 a = _mm256_castsi256_ps(l2[2 * i]), b = _mm256_castsi256_ps(l2[2 * i + 1]);
        l3[i] = Min(_mm256_castps_si256(_mm256_shuffle_ps(a, b, 0x88)),
                    _mm256_castps_si256(_mm256_shuffle_ps(a, b, 0xDD)));
      }
      for (int i = 0; i < 4; ++i) {
        T m = Min(l3[i], _mm256_srli_epi32(l3[i], 16));
        m = Min(m, _mm256_srli_epi32(m, 8));  // byte 0 of each 4: their minimum
        m = _mm256_shuffle_epi8(m, gather);   // lane 0: pixels 0, 2, 4, 6; lane 1: 1, 3, 5, 7
        const __m128i out =
            _mm_unpacklo_epi8(_mm256_castsi256_si128(m), _mm256_extracti128_si256(m, 1));
        _mm_storel_epi64(reinterpret_cast<__m128i*>(minima + g + 8 * i), out);
      }
    }
  }
  static std::uint64_t EqMask(T a, T b) {
    return static_cast<std::uint32_t>(_mm256_movemask_epi8(_mm256_cmpeq_epi8(a, b)));
  }
  // a <= b unsigned: min(a, b) == a.
  static std::uint64_t LessEqMask(T a, T b) {
    return static_cast<std::uint32_t>(
        _mm256_movemask_epi8(_mm256_cmpeq_epi8(_mm256_min_epu8(a, b), a)));
  }
};

// CheckPixel, 8 pixels at a time: the parabola's division in float lanes (the same IEEE division
// as the scalar one), the right matches by gather.
void CheckRow(const CheckArgs& a) {
  const __m256i lanes = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  const __m256i none = _mm256_set1_epi32(kNoMatch), width = _mm256_set1_epi32(a.width);
  const __m256i tolerance = _mm256_set1_epi32(a.tolerance), fifteen = _mm256_set1_epi32(15);
  const __m256i zero = _mm256_setzero_si256(), byte = _mm256_set1_epi32(255);
  const __m256i one = _mm256_set1_epi32(1);
  int x = 0;
  for (; x + 8 <= a.width; x += 8) {
    const __m256i d = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(a.disparity + x));
    const __m256i p = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(a.parabola + x));
    const __m256i before = _mm256_and_si256(p, byte);
    const __m256i after = _mm256_and_si256(_mm256_srli_epi32(p, 8), byte);
    const __m256i here = _mm256_and_si256(_mm256_srli_epi32(p, 16), byte);
    const __m256i inner = _mm256_cmpgt_epi32(_mm256_srli_epi32(p, 24), zero);
    const __m256i denom2 = _mm256_max_epi32(
        _mm256_sub_epi32(_mm256_add_epi32(before, after), _mm256_slli_epi32(here, 1)), one);
    const __m256i num =
        _mm256_add_epi32(_mm256_slli_epi32(_mm256_sub_epi32(before, after), 4), denom2);
    const __m256i fraction = _mm256_and_si256(
        inner, _mm256_cvttps_epi32(_mm256_div_ps(
                   _mm256_cvtepi32_ps(num), _mm256_cvtepi32_ps(_mm256_slli_epi32(denom2, 1)))));
    const __m256i matched = _mm256_xor_si256(_mm256_cmpeq_epi32(d, none), _mm256_set1_epi32(-1));
    const __m256i d1 = _mm256_add_epi32(_mm256_slli_epi32(d, 4), fraction);
    __m256i keep = _mm256_and_si256(matched, _mm256_cmpgt_epi32(d1, zero));
    if (a.tolerance >= 0) {
      const __m256i xs = _mm256_add_epi32(_mm256_set1_epi32(x), lanes);
      const __m256i d_lo = _mm256_srai_epi32(d1, 4);
      const __m256i d_hi = _mm256_srai_epi32(_mm256_add_epi32(d1, fifteen), 4);
      __m256i x_lo = _mm256_sub_epi32(xs, d_lo), x_hi = _mm256_sub_epi32(xs, d_hi);
      x_lo = _mm256_blendv_epi8(x_lo, width, _mm256_cmpgt_epi32(zero, x_lo));
      x_hi = _mm256_blendv_epi8(x_hi, width, _mm256_cmpgt_epi32(zero, x_hi));
      // Lanes without a match gather slot width (kNoMatch), and are dropped anyway.
      x_lo = _mm256_blendv_epi8(width, x_lo, keep);
      x_hi = _mm256_blendv_epi8(width, x_hi, keep);
      const __m256i r_lo = _mm256_i32gather_epi32(a.right_disparity, x_lo, 4);
      const __m256i r_hi = _mm256_i32gather_epi32(a.right_disparity, x_hi, 4);
      const __m256i bad_lo = _mm256_andnot_si256(
          _mm256_cmpeq_epi32(r_lo, none),
          _mm256_cmpgt_epi32(_mm256_abs_epi32(_mm256_sub_epi32(r_lo, d_lo)), tolerance));
      const __m256i bad_hi = _mm256_andnot_si256(
          _mm256_cmpeq_epi32(r_hi, none),
          _mm256_cmpgt_epi32(_mm256_abs_epi32(_mm256_sub_epi32(r_hi, d_hi)), tolerance));
      keep = _mm256_andnot_si256(_mm256_and_si256(bad_lo, bad_hi), keep);
    }
    const __m256i out = _mm256_and_si256(keep, d1);
    // Values <= 32767: the signed pack keeps them.
    const __m128i packed =
        _mm_packs_epi32(_mm256_castsi256_si128(out), _mm256_extracti128_si256(out, 1));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(a.out + x), packed);
  }
  for (; x < a.width; ++x) a.out[x] = CheckPixel(a, x);
}

void Census(const CensusArgs& a) { simd::Census<V256>(a); }
void Forward(const RowArgs& a) { simd::Row<V256, true>(a); }
void Backward(const RowArgs& a) { simd::Row<V256, false>(a); }

}  // namespace

const Kernels* Avx2Kernels() {
  static const Kernels k{"avx2", 32, 4, Census, Forward, Backward, CheckRow};
  return &k;
}

}  // namespace cloudcast::stereo::sgm
