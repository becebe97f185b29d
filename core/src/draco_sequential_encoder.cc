#include "draco_sequential_encoder.h"

#if !defined(__SSE2__)
#error "the Draco encoder uses SSE2, which every x86-64 CPU has"
#endif
#include <emmintrin.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <limits>
#include <string>
#include <vector>

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__,
              "the encoder stores multi-byte values as Draco's little-endian format has them");

namespace cloudcast::internal {
namespace {

template <typename T>
using Buffer = std::vector<T, DefaultInitAllocator<T>>;

// Constants of Draco 1.5.5's format and coder, as its encoder uses them here.
constexpr std::uint8_t kPredictionDifference = 0;  // PREDICTION_DIFFERENCE
constexpr std::uint8_t kTransformWrap = 1;         // PREDICTION_TRANSFORM_WRAP
constexpr std::uint8_t kSymbolCodingTagged = 0;    // SYMBOL_CODING_TAGGED
constexpr std::uint8_t kSymbolCodingRaw = 1;       // SYMBOL_CODING_RAW
constexpr int kMaxRawEncodingBitLength = 18;       // symbol_encoding.cc
constexpr int kTagPrecisionBits = 12;              // RAnsSymbolEncoder<5>
constexpr std::uint32_t kRansIoBase = 256;         // DRACO_ANS_IO_BASE
// Draco's rANS state stays below 2^30 (l_rans_base * IO base at 20 precision bits), which the
// division by reciprocal below relies on.
constexpr int kStateBits = 30;

void PutU8(std::string* out, std::uint8_t v) { out->push_back(static_cast<char>(v)); }

template <typename T>
void PutLe(std::string* out, T v) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &v, sizeof(T));
  out->append(bytes, sizeof(T));
}

// Draco's EncodeVarint for unsigned values (LEB128).
void PutVarint(std::string* out, std::uint64_t v) {
  while (v >= 0x80) {
    PutU8(out, static_cast<std::uint8_t>((v & 0x7F) | 0x80));
    v >>= 7;
  }
  PutU8(out, static_cast<std::uint8_t>(v));
}

int MostSignificantBit(std::uint32_t v) { return 31 ^ __builtin_clz(v); }  // v > 0

void Store32(std::uint8_t* p, std::uint32_t v) { std::memcpy(p, &v, 4); }
void Store64(std::uint8_t* p, std::uint64_t v) { std::memcpy(p, &v, 8); }

// One symbol of the rANS coder: Draco's (probability, cumulative probability) and what replaces
// its division by the probability. For a state x < 2^30 and probability p <= 2^20, with
// l = ceil(log2 p), shift = 30 + l and mult = ceil(2^shift / p), (x * mult) >> shift equals x / p
// exactly: the error mult * p - 2^shift is below p <= 2^l, so x times it stays below 2^shift.
struct RansSymbol {
  std::uint32_t mult;
  std::uint32_t shift;
  std::uint32_t renorm_limit;  // the state must be below this before the symbol is added
  std::uint32_t complement;    // precision - probability
  std::uint32_t cumulative;
};

struct Scratch {
  Buffer<std::uint32_t> symbols;     // one attribute's symbols, 3 per point (+1 for 4-lane stores)
  Buffer<std::uint8_t> bit_lengths;  // per point, for the tagged scheme
  std::vector<std::uint32_t> histogram;
  std::vector<std::uint32_t> probabilities;
  std::vector<std::uint64_t> order;
  std::vector<RansSymbol> coder;
  Buffer<std::uint8_t> rans;
  // f * log2(f / N) per frequency f of the current ComputeShannonEntropy, memoized: most symbols
  // share a handful of small frequencies, and each log2 costs tens of cycles.
  std::vector<double> term;
  std::vector<std::uint32_t> term_stamp;
  std::uint32_t stamp = 0;
};

constexpr std::uint32_t kMemoizedFrequencies = 1u << 12;

// Draco's ComputeShannonEntropy over a histogram `freq` of symbols 0..max_value (inclusive) of
// `count` values: the same double terms summed in the same order, so the same truncated result.
std::int64_t ShannonEntropyBits(const std::uint32_t* freq, std::uint32_t max_value,
                                std::uint64_t count, int* unique, Scratch* s) {
  if (s->term.empty()) {
    s->term.resize(kMemoizedFrequencies);
    s->term_stamp.assign(kMemoizedFrequencies, 0);
  }
  if (++s->stamp == 0) {  // wrapped: forget every memo
    std::fill(s->term_stamp.begin(), s->term_stamp.end(), 0);
    s->stamp = 1;
  }
  const double count_d = static_cast<double>(count);
  double total_bits = 0;
  int num_unique = 0;
  for (std::uint32_t i = 0; i <= max_value; ++i) {
    const std::uint32_t f = freq[i];
    if (f == 0) continue;
    ++num_unique;
    double term;
    if (f < kMemoizedFrequencies && s->term_stamp[f] == s->stamp) {
      term = s->term[f];
    } else {
      term = static_cast<double>(f) * std::log2(static_cast<double>(f) / count_d);
      if (f < kMemoizedFrequencies) {
        s->term[f] = term;
        s->term_stamp[f] = s->stamp;
      }
    }
    total_bits += term;
  }
  *unique = num_unique;
  return static_cast<std::int64_t>(-total_bits);
}

// Draco's ApproximateRAnsFrequencyTableBits.
std::int64_t RansTableBits(std::int32_t max_value, int num_unique) {
  const std::int64_t zero_bits = 8 * (num_unique + (max_value - num_unique) / 64);
  return 8 * num_unique + zero_bits;
}

// Draco's RAnsSymbolEncoder::Create and EncodeTable: turns `count` frequencies into
// probabilities summing to 2^precision_bits (with Draco's rounding and its fix-up passes), writes
// the table to *out and fills s->coder. False where Draco's Create fails (it would then write a
// broken stream without saying so).
bool BuildRansCoder(const std::uint32_t* freq, std::uint32_t count, int precision_bits, Scratch* s,
                    std::string* out) {
  const std::uint32_t precision = 1u << precision_bits;
  std::uint64_t total_freq = 0;
  std::uint32_t max_valid = 0;
  for (std::uint32_t i = 0; i < count; ++i) {
    total_freq += freq[i];
    if (freq[i] > 0) max_valid = i;
  }
  const std::uint32_t num_symbols = max_valid + 1;
  std::vector<std::uint32_t>& prob = s->probabilities;
  prob.resize(num_symbols);
  const double total_freq_d = static_cast<double>(total_freq);
  const double precision_d = static_cast<double>(precision);
  int total_prob = 0;
  for (std::uint32_t i = 0; i < num_symbols; ++i) {
    const double p = static_cast<double>(freq[i]) / total_freq_d;
    auto rans_prob = static_cast<std::uint32_t>(p * precision_d + 0.5);
    if (rans_prob == 0 && freq[i] > 0) rans_prob = 1;
    prob[i] = rans_prob;
    total_prob += static_cast<int>(rans_prob);
  }
  if (total_prob < static_cast<int>(precision)) {
    // Draco gives the shortfall to the last symbol of a stable ascending sort by probability:
    // the most probable one, the highest index among equals.
    std::uint32_t best = 0;
    for (std::uint32_t i = 0; i < num_symbols; ++i) {
      if (prob[i] >= prob[best]) best = i;
    }
    prob[best] += precision - static_cast<std::uint32_t>(total_prob);
  } else if (total_prob > static_cast<int>(precision)) {
    // Draco walks a stable ascending sort from its end down to (not including) its first entry,
    // scaling each probability down, and stops a walk at the first probability <= 1. That walk
    // is: probabilities above 1 by probability, then index, both descending; the entry with the
    // smallest probability (and index) is never visited.
    std::vector<std::uint64_t>& order = s->order;
    order.clear();
    for (std::uint32_t i = 0; i < num_symbols; ++i) {
      if (prob[i] > 1) order.push_back((std::uint64_t{prob[i]} << 32) | i);
    }
    std::sort(order.begin(), order.end(), std::greater<std::uint64_t>());
    if (order.size() == num_symbols) order.pop_back();
    if (order.empty()) return false;  // the most frequent symbol would be emptied
    std::int32_t error = total_prob - static_cast<std::int32_t>(precision);
    while (error > 0) {
      const double act_rel_error_d = precision_d / static_cast<double>(total_prob);
      for (std::size_t k = 0; k < order.size(); ++k) {
        const auto id = static_cast<std::uint32_t>(order[k]);
        if (prob[id] <= 1) {
          if (k == 0) return false;
          break;
        }
        const auto new_prob =
            static_cast<std::int32_t>(std::floor(act_rel_error_d * static_cast<double>(prob[id])));
        auto fix = static_cast<std::int32_t>(prob[id] - static_cast<std::uint32_t>(new_prob));
        if (fix == 0) fix = 1;
        if (fix >= static_cast<std::int32_t>(prob[id]))
          fix = static_cast<std::int32_t>(prob[id]) - 1;
        if (fix > error) fix = error;
        prob[id] -= static_cast<std::uint32_t>(fix);
        total_prob -= fix;
        error -= fix;
        if (total_prob == static_cast<int>(precision)) break;
      }
    }
  }

  // The table: a varint count, then each probability in 1..3 bytes whose low two bits hold the
  // extra byte count, or a run of up to 64 zero probabilities in one byte (low bits 3).
  PutVarint(out, num_symbols);
  for (std::uint32_t i = 0; i < num_symbols; ++i) {
    const std::uint32_t p = prob[i];
    if (p == 0) {
      std::uint32_t offset = 0;
      while (offset < 63 && prob[i + offset + 1] == 0) ++offset;  // the last symbol is non-zero
      PutU8(out, static_cast<std::uint8_t>((offset << 2) | 3));
      i += offset;
      continue;
    }
    const int extra = p >= (1u << 14) ? 2 : p >= (1u << 6) ? 1 : 0;
    if (p >= (1u << 22)) return false;
    PutU8(out, static_cast<std::uint8_t>((p << 2) | static_cast<std::uint32_t>(extra)));
    for (int b = 0; b < extra; ++b) PutU8(out, static_cast<std::uint8_t>(p >> (8 * (b + 1) - 2)));
  }

  s->coder.resize(num_symbols);
  std::uint32_t cumulative = 0;
  for (std::uint32_t i = 0; i < num_symbols; ++i) {
    const std::uint32_t p = prob[i];
    RansSymbol& c = s->coder[i];
    c = RansSymbol{0, 0, 0, 0, cumulative};
    cumulative += p;
    if (p == 0) continue;                                      // never coded
    const int l = p == 1 ? 0 : MostSignificantBit(p - 1) + 1;  // ceil(log2 p)
    c.shift = static_cast<std::uint32_t>(kStateBits + l);
    c.mult = static_cast<std::uint32_t>(((std::uint64_t{1} << c.shift) + p - 1) / p);
    // Draco renormalizes while state >= l_rans_base / precision * IO base * p = 1024 p.
    c.renorm_limit = 4 * kRansIoBase * p;
    c.complement = precision - p;
  }
  return cumulative == precision;
}

// Draco's RAnsEncoder: symbols are added last to first, each renormalizing the state by whole
// bytes first; the bytes come out in the order written. `symbol_at(k)` gives the k-th symbol
// of the `count`; returns the bytes, then the final state, as Draco's write_end leaves them.
template <typename SymbolAt>
std::size_t RansEncode(std::size_t count, SymbolAt symbol_at, int precision_bits, Scratch* s) {
  const std::uint32_t base = 4u << precision_bits;  // l_rans_base
  // Each symbol emits at most 3 bytes (the state shrinks below 1024 p from below 1024 * 2^20),
  // the end 4, and the stores below write 4 at a time.
  if (s->rans.size() < 3 * count + 8) s->rans.resize(3 * count + 8);
  std::uint8_t* const begin = s->rans.data();
  std::uint8_t* o = begin;
  std::uint32_t x = base;
  const RansSymbol* const table = s->coder.data();
  for (std::size_t k = count; k-- > 0;) {
    const RansSymbol& c = table[symbol_at(k)];
    // Draco's "while (x >= limit) emit x's low byte, x >>= 8", without branches: it runs once per
    // power of 256 that limit * 256^i <= x, and emits x's bytes in little-endian order.
    Store32(o, x);
    const std::uint64_t x64 = x, limit = c.renorm_limit;
    const unsigned bytes = static_cast<unsigned>(x64 >= limit) +
                           static_cast<unsigned>(x64 >= (limit << 8)) +
                           static_cast<unsigned>(x64 >= (limit << 16));
    o += bytes;
    x >>= 8 * bytes;
    const auto q = static_cast<std::uint32_t>((std::uint64_t{x} * c.mult) >> c.shift);
    x += q * c.complement + c.cumulative;
  }
  const std::uint32_t state = x - base;
  if (state < (1u << 6)) {
    *o++ = static_cast<std::uint8_t>(state);
  } else if (state < (1u << 14)) {
    const std::uint32_t v = (1u << 14) + state;
    *o++ = static_cast<std::uint8_t>(v);
    *o++ = static_cast<std::uint8_t>(v >> 8);
  } else if (state < (1u << 22)) {
    const std::uint32_t v = (2u << 22) + state;
    *o++ = static_cast<std::uint8_t>(v);
    *o++ = static_cast<std::uint8_t>(v >> 8);
    *o++ = static_cast<std::uint8_t>(v >> 16);
  } else {
    Store32(o, (3u << 30) + state);  // state < 2^30
    o += 4;
  }
  return static_cast<std::size_t>(o - begin);
}

// RAnsSymbolEncoder::EndEncoding: the byte count as a varint, then the bytes.
void PutRansStream(std::size_t bytes, const Scratch& s, std::string* out) {
  PutVarint(out, bytes);
  out->append(reinterpret_cast<const char*>(s.rans.data()), bytes);
}

// Draco's EncodeSymbols for `n` points of 3 components each, with compression level 0 (speed
// 10): it estimates the bits of its two schemes and takes the tagged one unless the raw one is
// strictly cheaper and its values have at most 18 bits.
//   tagged: per point, the bit length of its largest value is rANS-coded (precision 12), then
//           every value follows in that many bits, LSB first;
//   raw:    every value is rANS-coded over the histogram of all values.
bool EncodeSymbols(const std::uint32_t* sym, std::size_t n, std::uint32_t ored, Scratch* s,
                   std::string* out) {
  const std::uint64_t num_values = 3 * std::uint64_t{n};
  if (s->bit_lengths.size() < n) s->bit_lengths.resize(n);
  std::uint8_t* const bl = s->bit_lengths.data();
  std::uint32_t tag_freq[33] = {};
  std::uint64_t total_bit_length = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t v = sym[3 * i] | sym[3 * i + 1] | sym[3 * i + 2];
    const auto b = static_cast<std::uint8_t>(32 - __builtin_clz(v | 1));
    bl[i] = b;
    ++tag_freq[b];
    total_bit_length += b;
  }
  int tag_unique = 0;
  const std::int64_t tag_bits = ShannonEntropyBits(tag_freq, 32, n, &tag_unique, s);
  const std::int64_t tagged_bits = static_cast<std::int64_t>(
      static_cast<std::uint64_t>(tag_bits + RansTableBits(tag_unique, tag_unique)) +
      total_bit_length * 3);

  // The largest value has the bit length of the OR of all values.
  const int max_value_bit_length = MostSignificantBit(std::max(1u, ored)) + 1;
  bool raw = false;
  std::uint32_t max_value = 0;
  int raw_unique = 0;
  if (max_value_bit_length <= kMaxRawEncodingBitLength) {
    std::vector<std::uint32_t>& hist = s->histogram;
    hist.assign(std::size_t{1} << max_value_bit_length, 0);
    for (std::uint64_t i = 0; i < num_values; ++i) ++hist[sym[i]];
    max_value = static_cast<std::uint32_t>(hist.size() - 1);
    while (hist[max_value] == 0) --max_value;
    const std::int64_t data_bits =
        ShannonEntropyBits(hist.data(), max_value, num_values, &raw_unique, s);
    const std::int64_t raw_bits =
        RansTableBits(static_cast<std::int32_t>(max_value), raw_unique) + data_bits;
    raw = !(tagged_bits < raw_bits);
  }

  if (!raw) {
    PutU8(out, kSymbolCodingTagged);
    if (tag_freq[32] != 0) return false;  // Draco's 32-entry table would overflow
    if (!BuildRansCoder(tag_freq, 32, kTagPrecisionBits, s, out)) return false;
    const std::size_t bytes = RansEncode(
        n, [bl](std::size_t k) { return bl[k]; }, kTagPrecisionBits, s);
    PutRansStream(bytes, *s, out);
    // The values, in point order, each in its point's bit length.
    const std::uint64_t value_bytes = (total_bit_length * 3 + 7) / 8;
    const std::size_t at = out->size();
    out->resize(at + value_bytes + 8);
    auto* dst = reinterpret_cast<std::uint8_t*>(&(*out)[at]);
    std::uint64_t acc = 0;
    unsigned fill = 0;  // bits in acc, < 8 between values
    for (std::size_t i = 0; i < n; ++i) {
      const unsigned b = bl[i];
      for (int c = 0; c < 3; ++c) {
        acc |= std::uint64_t{sym[3 * i + c]} << fill;
        fill += b;
        Store64(dst, acc);
        dst += fill >> 3;
        acc >>= fill & ~7u;
        fill &= 7;
      }
    }
    out->resize(at + value_bytes);
    return true;
  }

  PutU8(out, kSymbolCodingRaw);
  const int symbol_bits =
      raw_unique > 0 ? MostSignificantBit(static_cast<std::uint32_t>(raw_unique)) : 0;
  int unique_bit_length = symbol_bits + 1;
  if (unique_bit_length > kMaxRawEncodingBitLength) return false;  // Draco fails here too
  // Compression level 0 (10 - speed) takes two bits off; Draco's precision is then
  // max(12, min(20, 3 * bits / 2)).
  unique_bit_length = std::clamp(unique_bit_length - 2, 1, kMaxRawEncodingBitLength);
  PutU8(out, static_cast<std::uint8_t>(unique_bit_length));
  const int precision_bits = std::clamp(3 * unique_bit_length / 2, 12, 20);
  if (!BuildRansCoder(s->histogram.data(), max_value + 1, precision_bits, s, out)) return false;
  const std::size_t bytes = RansEncode(
      num_values, [sym](std::size_t k) { return sym[k]; }, precision_bits, s);
  PutRansStream(bytes, *s, out);
  return true;
}

// SequentialIntegerAttributeEncoder::EncodeValues for one attribute of `n` points whose symbols
// (and their OR) are ready, with the wrap transform's bounds.
bool EncodeAttributeValues(const std::uint32_t* sym, std::size_t n, std::uint32_t ored,
                           std::int32_t wrap_min, std::int32_t wrap_max, bool entropy_coding,
                           Scratch* s, std::string* out) {
  PutU8(out, kPredictionDifference);
  PutU8(out, kTransformWrap);
  if (entropy_coding) {
    PutU8(out, 1);
    if (!EncodeSymbols(sym, n, ored, s, out)) return false;
  } else {
    // Stored: as many bytes per value as the largest needs.
    const int bytes = 1 + (ored == 0 ? 0 : MostSignificantBit(ored)) / 8;
    PutU8(out, 0);
    PutU8(out, static_cast<std::uint8_t>(bytes));
    const std::size_t values = 3 * n;
    const std::size_t at = out->size();
    out->resize(at + values * bytes + 4);
    auto* dst = reinterpret_cast<std::uint8_t*>(&(*out)[at]);
    for (std::size_t i = 0; i < values; ++i, dst += bytes) Store32(dst, sym[i]);
    out->resize(at + values * bytes);
  }
  PutLe<std::int32_t>(out, wrap_min);
  PutLe<std::int32_t>(out, wrap_max);
  return true;
}

// Draco's wrap transform (PredictionSchemeWrapEncodingTransform) over the values of one attribute,
// which all lie in [min, max]: a correction (value minus prediction) outside
// [min_correction, max_correction] is moved by max_dif = max - min + 1 back into it. Then
// ConvertSignedIntsToSymbols' zigzag: 2c for c >= 0, -2c - 1 below.
struct Wrap {
  __m128i min_correction, max_correction, max_dif;

  Wrap(std::int32_t min, std::int32_t max) {
    const std::int32_t dif = 1 + (max - min);
    std::int32_t max_corr = dif / 2;
    const std::int32_t min_corr = -max_corr;
    if ((dif & 1) == 0) max_corr -= 1;
    min_correction = _mm_set1_epi32(min_corr);
    max_correction = _mm_set1_epi32(max_corr);
    max_dif = _mm_set1_epi32(dif);
  }

  __m128i Symbols(__m128i value, __m128i predicted) const {
    __m128i c = _mm_sub_epi32(value, predicted);
    const __m128i below = _mm_cmpgt_epi32(min_correction, c);
    const __m128i above = _mm_cmpgt_epi32(c, max_correction);
    c = _mm_add_epi32(c, _mm_and_si128(below, max_dif));
    c = _mm_sub_epi32(c, _mm_and_si128(above, max_dif));
    return _mm_xor_si128(_mm_slli_epi32(c, 1), _mm_srai_epi32(c, 31));
  }
};

// Draco predicts the first point from zero, clamped into the values' range.
__m128i FirstPrediction(std::int32_t min, std::int32_t max) {
  return _mm_set1_epi32(0 > max ? max : (0 < min ? min : 0));
}

std::uint32_t HorizontalOr3(__m128i v) {
  alignas(16) std::uint32_t lanes[4];
  _mm_store_si128(reinterpret_cast<__m128i*>(lanes), v);
  return lanes[0] | lanes[1] | lanes[2];
}

// Position symbols: AttributeQuantizationTransform's q = floor((v - min) * (max_q / range) + 0.5)
// in float, then delta and wrap. v - min >= 0, so floor is truncation (cvttps2dq), and the
// largest q per axis is that of the axis maximum.
std::uint32_t PositionSymbols(const Point* points, std::size_t n, const float lo[3], float inv,
                              std::int32_t wrap_max, std::uint32_t* sym) {
  const Wrap wrap(0, wrap_max);
  const __m128 min4 = _mm_setr_ps(lo[0], lo[1], lo[2], 0.0f);
  const __m128 inv4 = _mm_set1_ps(inv);
  const __m128 half = _mm_set1_ps(0.5f);
  __m128i predicted = FirstPrediction(0, wrap_max);
  __m128i ored = _mm_setzero_si128();
  for (std::size_t i = 0; i < n; ++i) {
    const __m128 v = _mm_loadu_ps(&points[i].x);  // lane 3 (colour bits) is ignored
    const __m128i q = _mm_cvttps_epi32(_mm_add_ps(_mm_mul_ps(_mm_sub_ps(v, min4), inv4), half));
    const __m128i s = wrap.Symbols(q, predicted);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(sym + 3 * i), s);  // lane 3 overwritten next
    ored = _mm_or_si128(ored, s);
    predicted = q;
  }
  return HorizontalOr3(ored);
}

// Colour symbols: R, G, B (through `lut` if any), delta and wrap.
std::uint32_t ColorSymbols(const Point* points, std::size_t n, const std::uint8_t* lut,
                           std::int32_t wrap_min, std::int32_t wrap_max, std::uint32_t* sym) {
  const Wrap wrap(wrap_min, wrap_max);
  __m128i predicted = FirstPrediction(wrap_min, wrap_max);
  __m128i ored = _mm_setzero_si128();
  const __m128i zero = _mm_setzero_si128();
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t rgba = points[i].rgba;
    __m128i v;
    if (lut == nullptr) {
      // 0xAARRGGBB: bytes B, G, R, A widened to lanes, then reordered to R, G, B.
      const __m128i bytes = _mm_cvtsi32_si128(static_cast<int>(rgba));
      const __m128i lanes = _mm_unpacklo_epi16(_mm_unpacklo_epi8(bytes, zero), zero);
      v = _mm_shuffle_epi32(lanes, _MM_SHUFFLE(3, 0, 1, 2));
    } else {
      v = _mm_setr_epi32(lut[RedOf(rgba)], lut[GreenOf(rgba)], lut[BlueOf(rgba)], 0);
    }
    const __m128i s = wrap.Symbols(v, predicted);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(sym + 3 * i), s);
    ored = _mm_or_si128(ored, s);
    predicted = v;
  }
  return HorizontalOr3(ored);
}

void PutHeader(std::string* out, std::int32_t num_points) {
  out->append("DRACO", 5);
  PutU8(out, 2);                 // kDracoPointCloudBitstreamVersionMajor
  PutU8(out, 3);                 // kDracoPointCloudBitstreamVersionMinor
  PutU8(out, 0);                 // POINT_CLOUD
  PutU8(out, 0);                 // POINT_CLOUD_SEQUENTIAL_ENCODING
  PutLe<std::uint16_t>(out, 0);  // flags: no metadata
  PutLe<std::int32_t>(out, num_points);
}

}  // namespace

DracoCloudExtent ScanForDraco(const Point* points, std::size_t n) {
  const float inf = std::numeric_limits<float>::infinity();
  __m128 lo = _mm_set1_ps(inf), hi = _mm_set1_ps(-inf);
  __m128i color_lo = _mm_set1_epi8(-1), color_hi = _mm_setzero_si128();
  const __m128i exponent = _mm_set1_epi32(0x7F800000);
  std::size_t finite = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const __m128 v = _mm_loadu_ps(&points[i].x);
    const __m128i bits = _mm_castps_si128(v);
    const int non_finite =
        _mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(_mm_and_si128(bits, exponent), exponent)));
    if ((non_finite & 7) != 0) continue;
    // minps(v, lo) keeps lo unless v < lo, as Draco's "if (min > v) min = v": an equal value
    // (0.0 after -0.0) never replaces the first.
    lo = _mm_min_ps(v, lo);
    hi = _mm_max_ps(v, hi);
    color_lo = _mm_min_epu8(color_lo, bits);  // bytes 12..14 are B, G, R
    color_hi = _mm_max_epu8(color_hi, bits);
    ++finite;
  }
  DracoCloudExtent e;
  alignas(16) float l[4], h[4];
  _mm_store_ps(l, lo);
  _mm_store_ps(h, hi);
  alignas(16) std::uint8_t cl[16], ch[16];
  _mm_store_si128(reinterpret_cast<__m128i*>(cl), color_lo);
  _mm_store_si128(reinterpret_cast<__m128i*>(ch), color_hi);
  for (int c = 0; c < 3; ++c) {
    e.lo[c] = l[c];
    e.hi[c] = h[c];
  }
  e.color_lo = std::min({cl[12], cl[13], cl[14]});
  e.color_hi = std::max({ch[12], ch[13], ch[14]});
  e.finite = finite;
  return e;
}

bool EncodeDracoSequential(const Point* points, std::size_t n, const DracoCloudExtent& extent,
                           const DracoSequentialOptions& options, std::string* out) {
  // Draco counts values (3 per point) in an int.
  if (n == 0 || n > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max() / 3)) {
    return false;
  }
  const int bits = options.position_bits;
  if (bits < 1 || bits > 30) return false;
  thread_local Scratch scratch;
  Scratch* s = &scratch;
  if (s->symbols.size() < 3 * n + 1) s->symbols.resize(3 * n + 1);
  std::uint32_t* const sym = s->symbols.data();

  out->clear();
  PutHeader(out, static_cast<std::int32_t>(n));
  // One attributes encoder (SequentialAttributeEncodersController) holding both attributes.
  PutU8(out, 1);
  PutVarint(out, 2);
  const std::uint8_t descriptors[] = {
      0, 9, 3, 0, 0,  // POSITION, DT_FLOAT32, 3 components, not normalized, unique id 0
      2, 2, 3, 1, 1,  // COLOR, DT_UINT8, 3 components, normalized, unique id 1
      2, 1,           // SEQUENTIAL_ATTRIBUTE_ENCODER_QUANTIZATION, _INTEGER
  };
  out->append(reinterpret_cast<const char*>(descriptors), sizeof descriptors);

  // Positions. The range is the largest side, computed as Draco computes it (1 for a point).
  float range = 0.0f;
  for (int c = 0; c < 3; ++c) {
    const float dif = extent.hi[c] - extent.lo[c];
    if (dif > range) range = dif;
  }
  if (range == 0.0f) range = 1.0f;
  const auto max_quantized = static_cast<std::int32_t>((1u << bits) - 1);
  const float inv = static_cast<float>(max_quantized) / range;
  // A range below about 1e-30 overflows the scale: Draco's quantized values are then undefined
  // (float-to-int conversions of infinities), which we do not imitate.
  if (!std::isfinite(inv)) return false;
  std::int32_t q_max = 0;
  for (int c = 0; c < 3; ++c) {
    q_max = std::max(q_max, static_cast<std::int32_t>((extent.hi[c] - extent.lo[c]) * inv + 0.5f));
  }
  std::uint32_t ored = PositionSymbols(points, n, extent.lo, inv, q_max, sym);
  if (!EncodeAttributeValues(sym, n, ored, 0, q_max, options.entropy_coding, s, out)) return false;

  // Colours.
  const std::uint8_t* lut = options.color_lut;
  const std::int32_t c_min = lut ? lut[extent.color_lo] : extent.color_lo;
  const std::int32_t c_max = lut ? lut[extent.color_hi] : extent.color_hi;
  ored = ColorSymbols(points, n, lut, c_min, c_max, sym);
  if (!EncodeAttributeValues(sym, n, ored, c_min, c_max, options.entropy_coding, s, out)) {
    return false;
  }

  // The quantization parameters follow all values.
  for (int c = 0; c < 3; ++c) PutLe<float>(out, extent.lo[c]);
  PutLe<float>(out, range);
  PutU8(out, static_cast<std::uint8_t>(bits));
  return true;
}

void EncodeDracoEmpty(std::string* out) {
  out->clear();
  PutHeader(out, 0);
  PutU8(out, 1);  // one attributes encoder
  PutVarint(out, 1);
  const std::uint8_t descriptor[] = {
      0, 9, 3, 0, 0,  // POSITION, DT_FLOAT32, 3 components, not normalized, unique id 0
      0,              // SEQUENTIAL_ATTRIBUTE_ENCODER_GENERIC: raw values, none here
  };
  out->append(reinterpret_cast<const char*>(descriptor), sizeof descriptor);
}

}  // namespace cloudcast::internal
