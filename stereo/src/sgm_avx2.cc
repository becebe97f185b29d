// The AVX2 kernels (compiled with -mavx2 -mbmi2 -mpopcnt; chosen at run time only on a CPU that
// has them): sgm_simd.h over 32-byte vectors.
#include <immintrin.h>

#include "sgm_simd.h"

namespace cloudcast::stereo::sgm {
namespace {

struct V256 {
  using T = __m256i;
  static constexpr int kLanes = 32;
  static T Zero() { return _mm256_setzero_si256(); }
  static T Set1(std::uint8_t v) { return _mm256_set1_epi8(static_cast<char>(v)); }
  static T Load(const void* p) { return _mm256_loadu_si256(static_cast<const __m256i*>(p)); }
  static void Store(void* p, T v) { _mm256_storeu_si256(static_cast<__m256i*>(p), v); }
  static T AddSat(T a, T b) { return _mm256_adds_epu8(a, b); }
  static T SubSat(T a, T b) { return _mm256_subs_epu8(a, b); }
  static T Min(T a, T b) { return _mm256_min_epu8(a, b); }
  static T Max(T a, T b) { return _mm256_max_epu8(a, b); }
  static T Add8(T a, T b) { return _mm256_add_epi8(a, b); }
  static T Xor(T a, T b) { return _mm256_xor_si256(a, b); }
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
  static std::uint64_t EqMask(T a, T b) {
    return static_cast<std::uint32_t>(_mm256_movemask_epi8(_mm256_cmpeq_epi8(a, b)));
  }
  // a <= b unsigned: min(a, b) == a.
  static std::uint64_t LessEqMask(T a, T b) {
    return static_cast<std::uint32_t>(
        _mm256_movemask_epi8(_mm256_cmpeq_epi8(_mm256_min_epu8(a, b), a)));
  }
};

void Census(const CensusArgs& a) { simd::Census<V256>(a); }
void Forward(const RowArgs& a) { simd::Row<V256, true>(a); }
void Backward(const RowArgs& a) { simd::Row<V256, false>(a); }
void Wta(const WtaArgs& a) { simd::Wta<V256>(a); }

}  // namespace

const Kernels* Avx2Kernels() {
  static const Kernels k{"avx2", 32, Census, Forward, Backward, Wta};
  return &k;
}

}  // namespace cloudcast::stereo::sgm
