#include "draco_sequential_encoder.h"

#if !defined(__SSE2__) || !defined(__x86_64__) || !defined(__GNUC__)
#error "the Draco encoder is written for x86-64 (SSE2, which every such CPU has) with GCC or Clang"
#endif
#include <emmintrin.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <limits>
#include <string>
#include <type_traits>
#include <vector>

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__,
              "the encoder stores multi-byte values as Draco's little-endian format has them");

// How the encoder is organised (n points, all in per-thread scratch):
//   1. ScanForDraco: the bounding box and colour range, as Draco finds them.
//   2. ComputeNarrowSymbols (or ComputeWideSymbols for wide position ranges): one pass computing
//      both attributes' symbols (quantization, delta, wrap, zigzag) and what Draco's scheme
//      choice needs: histograms and per-point bit lengths.
//   3. PlanSymbols: per attribute, Draco's choice (tagged or raw) and its probability table.
//   4. EncodeStreams: one backward pass writing both rANS streams and the tagged scheme's
//      values. The position stream's state (three symbols a point) is the critical path of the
//      whole encoder; everything else overlaps it.
// Draco 1.5.5 does the same work in separate passes over temporary buffers, with a virtual call
// per attribute value, a symbol table of the quantization's whole range and a division per rANS
// symbol.

namespace cloudcast::internal {
namespace {

template <typename T>
using Buffer = std::vector<T, DefaultInitAllocator<T>>;

// The per-symbol steps must be inlined into their loops; GCC's heuristics give up on some.
#define CLOUDCAST_INLINE inline __attribute__((always_inline))

// Constants of Draco 1.5.5's format and coder, as its encoder uses them here.
constexpr std::uint8_t kPredictionDifference = 0;  // PREDICTION_DIFFERENCE
constexpr std::uint8_t kTransformWrap = 1;         // PREDICTION_TRANSFORM_WRAP
constexpr std::uint8_t kSymbolCodingTagged = 0;    // SYMBOL_CODING_TAGGED
constexpr std::uint8_t kSymbolCodingRaw = 1;       // SYMBOL_CODING_RAW
constexpr int kMaxRawEncodingBitLength = 18;       // symbol_encoding.cc
constexpr int kTagPrecisionBits = 12;              // RAnsSymbolEncoder<5>
constexpr std::uint32_t kRansIoBase = 256;         // DRACO_ANS_IO_BASE

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

// ---------------------------------------------------------------------------------------------
// Draco's rANS coder.

// One symbol: Draco's probability p and cumulative probability, and what replaces its division
// of the state x by p (x < 1024 * precision <= 2^30), exactly:
//  - above precisions of 2^14: with m = (2^64 - 1) / p, x / p is the high half of (x + 1) * m,
//    which is (x + 1) / p - (x + 1) * (1 + (2^64 - 1) % p) / (p * 2^64), the subtracted part
//    positive and below 1 / p (as (x + 1) * p < 2^64);
//  - up to 2^14 ("small"): with k = 54 - bits and m = ceil(2^k / p), x / p is (x * m) >> k: the
//    excess m * p - 2^k is below p, so x times it stays below 2^(10 + 2 bits) <= 2^k; and x * m
//    fits 64 bits (x < 2^(10 + bits) = 2^(64 - k), m <= 2^k for p = 1, 2^(k - 1) + 1 above).
struct RansSymbol {
  // Draco renormalizes while x >= 1024 p (l_rans_base / precision * IO base * p), a byte at a
  // time; limit[i] = 1024 p * 256^i (saturated: x < 2^30 never reaches those) count the bytes.
  std::uint32_t limit[3];
  std::uint32_t complement;  // precision - p
  std::uint64_t reciprocal;  // m above
  std::uint32_t cumulative;
  std::uint32_t unused;
};
static_assert(sizeof(RansSymbol) == 32);

constexpr int kSmallPrecisionMaxBits = 14;
constexpr int ReciprocalShift(int precision_bits) {
  return precision_bits <= kSmallPrecisionMaxBits ? 54 - precision_bits : 64;
}

// Up to 2^16, the state stays below 1024 * 2^16 = 2^26, and a third byte of renormalization
// would need x >= 1024 p * 2^16 >= 2^26: two bytes at most.
constexpr int kTwoByteRenormMaxPrecisionBits = 16;

// RansSymbol's m for precision_bits: (2^64 - 1) / p, or ceil(2^k / p) = (2^k - 1) / p + 1 for
// small precisions. Below 2^12 (all of the tags' and most probabilities of raw tables) from a
// table of (2^64 - 1) / p, shifted: floor(floor(a / p) / 2^j) is floor(floor(a / 2^j) / p), and
// (2^64 - 1) / 2^(64 - k) is 2^k - 1. A 64-bit division costs tens of cycles, and raw tables
// have thousands of symbols.
std::uint64_t Reciprocal(std::uint32_t p, int precision_bits) {
  constexpr std::uint32_t kTabled = 1u << 12;
  static const std::vector<std::uint64_t> table = [] {
    std::vector<std::uint64_t> t(kTabled);
    for (std::uint32_t i = 1; i < kTabled; ++i) t[i] = ~std::uint64_t{0} / i;
    return t;
  }();
  const int k = ReciprocalShift(precision_bits);
  if (k == 64) return p < kTabled ? table[p] : ~std::uint64_t{0} / p;
  return (p < kTabled ? table[p] >> (64 - k) : ((std::uint64_t{1} << k) - 1) / p) + 1;
}

// Draco's RAnsEncoder. Symbols are added last to first; each first renormalizes the state by
// whole bytes, which come out in the order written. kPrecisionBits: the stream's when it is at
// most kSmallPrecisionMaxBits (the division then takes a 64-bit product and a fixed shift), 16
// for 15 and 16 bits (two bytes of renormalization at most), or 0.
template <int kPrecisionBits>
class RansWriter {
 public:
  // `out` must hold 3 bytes per symbol plus 8.
  RansWriter(int precision_bits, std::uint8_t* out)
      : base_(4u << precision_bits), x_(base_), begin_(out), o_(out) {}

  CLOUDCAST_INLINE void Put(const RansSymbol& c) {
    if constexpr (kPrecisionBits != 0 && kPrecisionBits <= kSmallPrecisionMaxBits) {
      PutSmallPrecision(c);
      return;
    }
    // Draco's "while (x >= 1024 p) emit x's low byte, x >>= 8" without branches: it runs once
    // per limit x reaches, and emits x's bytes in little-endian order.
    Store32(o_, x_);
    unsigned bytes =
        static_cast<unsigned>(x_ >= c.limit[0]) + static_cast<unsigned>(x_ >= c.limit[1]);
    if constexpr (kPrecisionBits == 0 || kPrecisionBits > kTwoByteRenormMaxPrecisionBits) {
      bytes += static_cast<unsigned>(x_ >= c.limit[2]);
    }
    o_ += bytes;
    // Then x = (x / p) * precision + x % p + cumulative on the renormalized x' = x / 256^bytes,
    // that is x' + (x' / p) * (precision - p) + cumulative, where x' / p = (x / p) / 256^bytes:
    // the division starts while the bytes are counted.
    const unsigned shift = 8 * bytes;
    const auto q =
        static_cast<std::uint32_t>((static_cast<unsigned __int128>(x_ + 1) * c.reciprocal) >> 64);
    x_ = (x_ >> shift) + (q >> shift) * c.complement + c.cumulative;
  }

  // Put for precisions up to 2^14, by hand: the state's dependency chain is the encoder's
  // bottleneck (one stream, three symbols a point), and GCC 12 lengthens it by computing the
  // shift count from the comparisons (9% slower on Tsukuba 00001). Here the division's fixed shift
  // k and the renormalization's 8 per byte make one count, selected by conditional moves; the
  // renormalized state is (x << k) shifted by it too (x < 2^(10 + bits) = 2^(64 - k)). The same
  // arithmetic as Put's, with the small precisions' m.
  CLOUDCAST_INLINE void PutSmallPrecision(const RansSymbol& c) {
    constexpr unsigned k = ReciprocalShift(kPrecisionBits);
    std::uint64_t x = x_, q, renormalized;
    std::uint8_t* o = o_;
    const std::uint64_t k8 = k + 8, k16 = k + 16;
    asm("movl %k[x], %[out]\n\t"  // Store32(o, x)
        "movl %k[x], %k[q]\n\t"   // q = x * reciprocal
        "imulq %[reciprocal], %q[q]\n\t"
        "movl %k[x], %k[r]\n\t"  // r = x << k
        "shlq %[k], %q[r]\n\t"
        "movl %[k], %%ecx\n\t"  // count = k + 8 * bytes
        "cmpl %[limit0], %k[x]\n\t"
        "cmovael %k[k8], %%ecx\n\t"
        "sbbq $-1, %[o]\n\t"  // o += x >= limit0
        "cmpl %[limit1], %k[x]\n\t"
        "cmovael %k[k16], %%ecx\n\t"
        "sbbq $-1, %[o]\n\t"    // o += x >= limit1
        "shrq %%cl, %q[q]\n\t"  // x' / p
        "shrq %%cl, %q[r]\n\t"  // x'
        "imull %[complement], %k[q]\n\t"
        "addl %[cumulative], %k[r]\n\t"
        "leal (%q[r], %q[q]), %k[x]"
        : [x] "+r"(x), [o] "+r"(o), [q] "=&r"(q), [r] "=&r"(renormalized),
          [out] "=m"(*reinterpret_cast<std::uint32_t*>(o_))
        : [k] "i"(k), [k8] "r"(k8), [k16] "r"(k16), [limit0] "m"(c.limit[0]),
          [limit1] "m"(c.limit[1]), [reciprocal] "m"(c.reciprocal), [complement] "m"(c.complement),
          [cumulative] "m"(c.cumulative)
        : "rcx", "cc");
    x_ = static_cast<std::uint32_t>(x);
    o_ = o;
  }

  // Draco's write_end: the final state in 1..4 bytes. Returns the stream's size.
  std::size_t Finish() {
    const std::uint32_t state = x_ - base_;
    if (state < (1u << 6)) {
      *o_++ = static_cast<std::uint8_t>(state);
    } else if (state < (1u << 14)) {
      const std::uint32_t v = (1u << 14) + state;
      *o_++ = static_cast<std::uint8_t>(v);
      *o_++ = static_cast<std::uint8_t>(v >> 8);
    } else if (state < (1u << 22)) {
      const std::uint32_t v = (2u << 22) + state;
      *o_++ = static_cast<std::uint8_t>(v);
      *o_++ = static_cast<std::uint8_t>(v >> 8);
      *o_++ = static_cast<std::uint8_t>(v >> 16);
    } else {
      Store32(o_, (3u << 30) + state);  // state < 2^30
      o_ += 4;
    }
    return static_cast<std::size_t>(o_ - begin_);
  }

 private:
  std::uint32_t base_;  // l_rans_base = 4 * precision
  std::uint32_t x_;
  std::uint8_t* begin_;
  std::uint8_t* o_;
};

// ---------------------------------------------------------------------------------------------
// Scratch, reused per thread.

// Per attribute: its histogram, coder and streams.
struct AttributeScratch {
  // All zero between calls: each call clears what it used (HistogramCleaner), so that its cost
  // follows the symbols' range, not the quantization's.
  std::vector<std::uint32_t> histogram;
  std::size_t histogram_used = 0;
  std::vector<RansSymbol> coder;
  Buffer<std::uint8_t> rans;         // the rANS bytes, as Draco writes them before their size
  std::vector<std::uint8_t> values;  // the tagged scheme's values
  std::string prefix;                // what precedes the rANS stream: method bytes and table
};

struct Scratch {
  AttributeScratch position, color;
  // The symbols, in one of two layouts (see NarrowSymbols and WideSymbols).
  Buffer<std::uint16_t> records;
  Buffer<std::uint32_t> wide_positions;
  Buffer<std::uint16_t> wide_colors;
  // Per point: the bit length of its largest position symbol and, in the high byte, of its
  // largest colour symbol: the tags of the tagged scheme.
  Buffer<std::uint16_t> bit_lengths;
  std::vector<std::uint32_t> probabilities;
  std::vector<std::uint64_t> order;
  // f * log2(f / N) per frequency f of the current ComputeShannonEntropy, memoized: most symbols
  // share a handful of small frequencies, and each log2 costs tens of cycles.
  std::vector<double> term;
  std::vector<std::uint32_t> term_stamp;
  std::uint32_t stamp = 0;
};

// Where the symbols are. Positions are kept x, y, z; colours B, G, R (the order of PCL's colour
// word), so whoever reads a colour's components in Draco's order (R, G, B) reads them backwards.
//
// Narrow: one record of eight 16-bit lanes per point, x y z - B G R -, computed together with
// 16-bit vector arithmetic: for wraps below 2^14 (every colour; positions up to 13 bits, and
// wider ones whose values span less). The lanes hold 4 times the symbol: that is the offset of
// its counter in the per-component histograms, and an eighth of its coder entry's.
struct NarrowSymbols {
  static constexpr bool kScaled = true;
  const std::uint16_t* records;
  std::uint32_t Position(std::size_t i, int k) const { return records[8 * i + k] >> 2; }
  std::uint32_t Color(std::size_t i, int k) const { return records[8 * i + 4 + k] >> 2; }
  std::uint32_t PositionScaled(std::size_t i, int k) const { return records[8 * i + k]; }
  std::uint32_t ColorScaled(std::size_t i, int k) const { return records[8 * i + 4 + k]; }
  static const RansSymbol& Entry(const RansSymbol* table, std::uint32_t scaled) {
    return *reinterpret_cast<const RansSymbol*>(reinterpret_cast<const char*>(table) +
                                                8 * std::size_t{scaled});
  }
};
// Wide: positions in 32 bits, 3 per point; colours in 16, 3 per point.
struct WideSymbols {
  static constexpr bool kScaled = false;
  const std::uint32_t* positions;
  const std::uint16_t* colors;
  std::uint32_t Position(std::size_t i, int k) const { return positions[3 * i + k]; }
  std::uint32_t Color(std::size_t i, int k) const { return colors[3 * i + k]; }
  std::uint32_t PositionScaled(std::size_t i, int k) const { return Position(i, k); }
  std::uint32_t ColorScaled(std::size_t i, int k) const { return Color(i, k); }
  static const RansSymbol& Entry(const RansSymbol* table, std::uint32_t symbol) {
    return table[symbol];
  }
};

// ---------------------------------------------------------------------------------------------
// Draco's estimates and tables.

constexpr std::uint32_t kMemoizedFrequencies = 1u << 12;

// The first index at or after i (below end) whose count is not zero, or end: tables of wide
// quantizations are mostly zeros, skipped four at a time.
std::uint32_t NextNonZero(const std::uint32_t* f, std::uint32_t i, std::uint32_t end) {
  const __m128i zero = _mm_setzero_si128();
  for (; i + 4 <= end; i += 4) {
    const __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(f + i));
    const int zeros = _mm_movemask_epi8(_mm_cmpeq_epi32(v, zero));
    if (zeros != 0xFFFF) return i + static_cast<std::uint32_t>(__builtin_ctz(~zeros)) / 4;
  }
  while (i < end && f[i] == 0) ++i;
  return i;
}

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
  for (std::uint32_t i = NextNonZero(freq, 0, max_value + 1); i <= max_value;
       i = NextNonZero(freq, i + 1, max_value + 1)) {
    const std::uint32_t f = freq[i];
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

// Draco's ApproximateRAnsFrequencyTableBits, in its int arithmetic.
std::int64_t RansTableBits(std::int32_t max_value, int num_unique) {
  const auto zero_bits =
      static_cast<std::int64_t>(8 * (num_unique + (max_value - num_unique) / 64));
  return static_cast<std::int64_t>(8 * num_unique) + zero_bits;
}

// Draco's RAnsSymbolEncoder::Create and EncodeTable: turns `count` frequencies into
// probabilities summing to 2^precision_bits (with Draco's rounding and its fix-up passes), writes
// the table to *out and fills *coder. False where Draco's Create fails (it would then write a
// broken stream without saying so).
bool BuildRansCoder(const std::uint32_t* freq, std::uint32_t count, int precision_bits, Scratch* s,
                    std::vector<RansSymbol>* coder, std::string* out) {
  const std::uint32_t precision = 1u << precision_bits;
  std::uint64_t total_freq = 0;
  std::uint32_t max_valid = 0;
  for (std::uint32_t i = NextNonZero(freq, 0, count); i < count;
       i = NextNonZero(freq, i + 1, count)) {
    total_freq += freq[i];
    max_valid = i;
  }
  const std::uint32_t num_symbols = max_valid + 1;
  std::vector<std::uint32_t>& prob = s->probabilities;
  prob.assign(num_symbols, 0);  // what Draco computes for a zero count, without its division
  const double total_freq_d = static_cast<double>(total_freq);
  const double precision_d = static_cast<double>(precision);
  int total_prob = 0;
  for (std::uint32_t i = NextNonZero(freq, 0, num_symbols); i < num_symbols;
       i = NextNonZero(freq, i + 1, num_symbols)) {
    const double p = static_cast<double>(freq[i]) / total_freq_d;
    // Draco's rounding (truncation of + 0.5), not lround's.
    auto rans_prob = static_cast<std::uint32_t>(p * precision_d + 0.5);  // NOLINT

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
    const std::uint32_t* const pr = prob.data();
    for (std::uint32_t i = NextNonZero(pr, 0, num_symbols); i < num_symbols;
         i = NextNonZero(pr, i + 1, num_symbols)) {
      if (pr[i] > 1) order.push_back((std::uint64_t{pr[i]} << 32) | i);
    }
    std::sort(order.begin(), order.end(), std::greater<std::uint64_t>());
    if (order.size() == num_symbols) order.pop_back();  // every probability above 1
    if (order.empty()) return false;                    // the most frequent symbol would be emptied
    std::int32_t error = total_prob - static_cast<std::int32_t>(precision);
    while (error > 0) {
      const double act_rel_error_d = precision_d / static_cast<double>(total_prob);
      for (std::size_t k = 0; k < order.size(); ++k) {
        const auto id = static_cast<std::uint32_t>(order[k]);
        const auto current = static_cast<std::int32_t>(prob[id]);
        if (current <= 1) {
          if (k == 0) return false;
          break;
        }
        const auto new_prob =
            static_cast<std::int32_t>(std::floor(act_rel_error_d * static_cast<double>(current)));
        std::int32_t fix = current - new_prob;
        if (fix == 0) fix = 1;
        if (fix >= current) fix = current - 1;
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
      // The last symbol is non-zero; zero probabilities are exactly the zero counts.
      const std::uint32_t offset =
          std::min(NextNonZero(prob.data(), i + 1, num_symbols) - i - 1, 63u);
      PutU8(out, static_cast<std::uint8_t>((offset << 2) | 3));
      i += offset;
      continue;
    }
    if (p >= (1u << 22)) return false;
    const int extra = p >= (1u << 14) ? 2 : p >= (1u << 6) ? 1 : 0;
    PutU8(out, static_cast<std::uint8_t>((p << 2) | static_cast<std::uint32_t>(extra)));
    for (int b = 0; b < extra; ++b) PutU8(out, static_cast<std::uint8_t>(p >> (8 * (b + 1) - 2)));
  }

  coder->resize(num_symbols);
  std::uint32_t cumulative = 0;
  for (std::uint32_t i = NextNonZero(prob.data(), 0, num_symbols); i < num_symbols;
       i = NextNonZero(prob.data(), i + 1, num_symbols)) {
    const std::uint32_t p = prob[i];  // zero ones are never coded: their entries are not read
    RansSymbol& c = (*coder)[i];
    c.cumulative = cumulative;
    cumulative += p;
    for (int b = 0; b < 3; ++b) {
      const std::uint64_t limit = (std::uint64_t{4} * kRansIoBase * p) << (8 * b);
      c.limit[b] = static_cast<std::uint32_t>(std::min<std::uint64_t>(limit, 0xFFFFFFFFu));
    }
    c.complement = precision - p;
    c.reciprocal = Reciprocal(p, precision_bits);
  }
  return cumulative == precision;
}

// ---------------------------------------------------------------------------------------------
// Symbols.

// Draco's wrap transform (PredictionSchemeWrapEncodingTransform) over the values of one
// attribute, which all lie in [min, max]: a correction (value minus prediction) outside
// [min_correction, max_correction] is moved by max_dif = max - min + 1 back into it. Then
// ConvertSignedIntsToSymbols' zigzag: 2c for c >= 0, -2c - 1 below.
struct Wrap {
  std::int32_t min, max;
  std::int32_t max_dif;
  std::int32_t min_correction, max_correction;
  __m128i min_correction4, max_correction4, max_dif4;

  Wrap(std::int32_t lo, std::int32_t hi) : min(lo), max(hi), max_dif(1 + (hi - lo)) {
    max_correction = max_dif / 2;
    min_correction = -max_correction;
    if ((max_dif & 1) == 0) max_correction -= 1;
    min_correction4 = _mm_set1_epi32(min_correction);
    max_correction4 = _mm_set1_epi32(max_correction);
    max_dif4 = _mm_set1_epi32(max_dif);
  }

  __m128i Symbols(__m128i value, __m128i predicted) const {
    __m128i c = _mm_sub_epi32(value, predicted);
    const __m128i below = _mm_cmpgt_epi32(min_correction4, c);
    const __m128i above = _mm_cmpgt_epi32(c, max_correction4);
    c = _mm_add_epi32(c, _mm_and_si128(below, max_dif4));
    c = _mm_sub_epi32(c, _mm_and_si128(above, max_dif4));
    return _mm_xor_si128(_mm_slli_epi32(c, 1), _mm_srai_epi32(c, 31));
  }

  // Draco predicts the first point from zero, clamped into the values' range.
  std::int32_t FirstPrediction() const { return 0 > max ? max : (0 < min ? min : 0); }

  // A wrapped correction lies within max_dif / 2 of 0, so no symbol exceeds max_dif: a
  // histogram needs max_dif + 1 entries. Below 2^14, the values, their differences and 4 times
  // the symbols all fit 16-bit lanes (NarrowSymbols).
  std::uint32_t HistogramSize() const { return static_cast<std::uint32_t>(max_dif) + 1; }
  bool FitsNarrow() const { return max_dif < (1 << 14); }
};

std::uint32_t HorizontalOr3(__m128i v) {
  alignas(16) std::uint32_t lanes[4];
  _mm_store_si128(reinterpret_cast<__m128i*>(lanes), v);
  return lanes[0] | lanes[1] | lanes[2];
}

// The bit length Draco tags a point with: that of its largest symbol, at least 1.
inline std::uint32_t BitLength(std::uint32_t a, std::uint32_t b, std::uint32_t c) {
  return static_cast<std::uint32_t>(MostSignificantBit(a | b | c | 1) + 1);
}

// The bit lengths of a point's largest position symbol and largest colour symbol (BitLength),
// from its scaled symbols (x y z - B G R -, 4 times the symbols, in 16-bit lanes), in 32-bit
// lanes 0 and 2. Each attribute's three lanes are or-ed (the OR of 4a, 4b and 4c is 4 (a | b | c))
// and or-ed with 4 (a symbol of at least 1); as a float that is exact (below 2^16), and its
// exponent is 127 + 2 + floor(log2(symbols | 1)), the bit length plus 128. In the vector unit,
// where the symbols already are: a table look-up per attribute took more instructions (and BSR
// takes 4 cycles of its unit per use on AMD's cores).
CLOUDCAST_INLINE __m128i ScaledBitLengths(__m128i scaled) {
  __m128i o = _mm_or_si128(scaled, _mm_srli_epi64(scaled, 16));
  o = _mm_or_si128(o, _mm_srli_epi64(scaled, 32));  // lanes 0 and 4: the three lanes or-ed
  o = _mm_and_si128(o, _mm_setr_epi32(0xFFFF, 0, 0xFFFF, 0));
  o = _mm_or_si128(o, _mm_setr_epi32(4, 0, 4, 0));
  const __m128i exponent = _mm_srli_epi32(_mm_castps_si128(_mm_cvtepi32_ps(o)), 23);
  return _mm_sub_epi32(exponent, _mm_set1_epi32(128));
}

// What Draco's EncodeSymbols looks at to choose between its schemes, gathered with the symbols.
struct SymbolStats {
  int max_bit_length = 1;  // of the largest symbol (at least 1)
  std::uint32_t tag_freq[33] = {};
  std::uint64_t total_bit_length = 0;
  bool histogram_ready = false;
  std::size_t histogram_entries = 0;  // valid counts at the start of the attribute's histogram
};

struct PositionQuantizer {
  __m128 min;  // lane 3: 0
  __m128 inv;  // (2^bits - 1) / range
};

// Histograms count each component apart (entries 4 s + component, summed afterwards):
// consecutive points often share symbols, and increments of one counter wait for each other.
constexpr std::size_t kHistogramLanes = 4;

// Tag counts and totals into the stats.
void FinishTagStats(const std::uint32_t tag[33], SymbolStats* st) {
  st->total_bit_length = 0;
  for (int b = 1; b <= 32; ++b) {
    st->tag_freq[b] = tag[b];
    st->total_bit_length += std::uint64_t{tag[b]} * static_cast<std::uint64_t>(b);
    if (tag[b] != 0) st->max_bit_length = b;
  }
}

// The symbols of both attributes in one pass over the points (and, with kStats, what the scheme
// choice needs). Positions: AttributeQuantizationTransform's q = floor((v - min) * inv + 0.5)
// in float (v - min >= 0, so floor is cvttps2dq's truncation). Colours: the colour word's bytes
// (through `lut` when kLut). Both: delta from the previous point, wrap and zigzag, in 16-bit
// lanes, all six values at once. n > 0 (EncodeDracoSequential takes no empty cloud).
template <bool kLut, bool kStats>
void ComputeNarrowSymbols(const Point* points, std::size_t n, const PositionQuantizer& pq,
                          const Wrap& wp, const Wrap& wc, const std::uint8_t* lut, Scratch* s,
                          SymbolStats* ps, SymbolStats* cs) {
  static_assert(kHistogramLanes == 4, "records hold 4 times the symbols");
  std::uint16_t* const rec = s->records.data();
  std::uint16_t* const bl = s->bit_lengths.data();
  std::uint32_t* const phist = s->position.histogram.data();
  std::uint32_t* const chist = s->color.histogram.data();
  auto lanes = [](std::int32_t p, std::int32_t c) {
    const auto p16 = static_cast<std::int16_t>(p), c16 = static_cast<std::int16_t>(c);
    return _mm_setr_epi16(p16, p16, p16, 0, c16, c16, c16, 0);
  };
  // Lanes 3 and 7 (the colour bits as a float, alpha) are carried along and never read.
  const __m128i min_correction = lanes(wp.min_correction, wc.min_correction);
  const __m128i max_correction = lanes(wp.max_correction, wc.max_correction);
  const __m128i max_dif = lanes(wp.max_dif, wc.max_dif);
  __m128i prev = lanes(wp.FirstPrediction(), wc.FirstPrediction());
  const __m128 half = _mm_set1_ps(0.5f);
  const __m128i zero = _mm_setzero_si128();
  std::uint32_t ptag[33] = {}, ctag[33] = {};
  // The statistics of point i - 1 are gathered while point i is computed: they wait for the
  // vector results no longer, and the two halves of the work overlap.
  auto gather = [&](__m128i scaled, std::size_t i) {
    // The six lanes reach the integer side in two 64-bit moves.
    const auto lo = static_cast<std::uint64_t>(_mm_cvtsi128_si64(scaled));
    const auto hi =
        static_cast<std::uint64_t>(_mm_cvtsi128_si64(_mm_unpackhi_epi64(scaled, scaled)));
    const std::size_t p0 = lo & 0xFFFF, p1 = (lo >> 16) & 0xFFFF, p2 = (lo >> 32) & 0xFFFF;
    const std::size_t c0 = hi & 0xFFFF, c1 = (hi >> 16) & 0xFFFF, c2 = (hi >> 32) & 0xFFFF;
    ++phist[p0];
    ++phist[p1 + 1];
    ++phist[p2 + 2];
    ++chist[c0];
    ++chist[c1 + 1];
    ++chist[c2 + 2];
    // Lanes 0 and 2 of the bit lengths in one 64-bit move.
    const auto lengths = static_cast<std::uint64_t>(
        _mm_cvtsi128_si64(_mm_shuffle_epi32(ScaledBitLengths(scaled), 0x08)));
    const auto pb = static_cast<std::uint32_t>(lengths),
               cb = static_cast<std::uint32_t>(lengths >> 32);
    bl[i] = static_cast<std::uint16_t>(pb | (cb << 8));
    ++ptag[pb];
    ++ctag[cb];
  };
  // Point i's scaled symbols (kHistogramLanes times them), stored for the stream pass.
  auto symbols = [&](std::size_t i) {
    const __m128 v = _mm_loadu_ps(&points[i].x);
    const __m128i q = _mm_cvttps_epi32(_mm_add_ps(_mm_mul_ps(_mm_sub_ps(v, pq.min), pq.inv), half));
    __m128i value;  // x y z - B G R -; positions below 2^15 survive the signed pack
    if constexpr (kLut) {
      const std::uint32_t rgba = points[i].rgba;
      value = _mm_packs_epi32(
          q, _mm_setr_epi32(lut[BlueOf(rgba)], lut[GreenOf(rgba)], lut[RedOf(rgba)], 0));
    } else {
      // Bytes 12..15 of the point (B, G, R, A) widen into lanes 4..7.
      const __m128i color = _mm_unpackhi_epi8(_mm_castps_si128(v), zero);
      value = _mm_castpd_si128(
          _mm_move_sd(_mm_castsi128_pd(color), _mm_castsi128_pd(_mm_packs_epi32(q, q))));
    }
    __m128i c = _mm_sub_epi16(value, prev);
    const __m128i below = _mm_cmpgt_epi16(min_correction, c);
    const __m128i above = _mm_cmpgt_epi16(c, max_correction);
    c = _mm_add_epi16(c, _mm_and_si128(below, max_dif));
    c = _mm_sub_epi16(c, _mm_and_si128(above, max_dif));
    const __m128i zigzag = _mm_xor_si128(_mm_slli_epi16(c, 1), _mm_srai_epi16(c, 15));
    const __m128i scaled = _mm_slli_epi16(zigzag, 2);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(rec + 8 * i), scaled);
    prev = value;
    return scaled;
  };
  if constexpr (kStats) {
    // The first point outside the loop: inside it, every point has a predecessor to gather.
    __m128i pending = symbols(0);
    for (std::size_t i = 1; i < n; ++i) {
      const __m128i scaled = symbols(i);
      gather(pending, i - 1);
      pending = scaled;
    }
    gather(pending, n - 1);
    FinishTagStats(ptag, ps);
    FinishTagStats(ctag, cs);
  } else {
    __m128i ored = zero;  // for the largest bit lengths
    for (std::size_t i = 0; i < n; ++i) ored = _mm_or_si128(ored, symbols(i));
    alignas(16) std::uint16_t o[8];
    _mm_store_si128(reinterpret_cast<__m128i*>(o), _mm_srli_epi16(ored, 2));  // the symbols
    ps->max_bit_length = static_cast<int>(BitLength(o[0], o[1], o[2]));
    cs->max_bit_length = static_cast<int>(BitLength(o[4], o[5], o[6]));
  }
}

// The same for wider position values, in 32-bit lanes (colours, always narrow, go along). With
// kPositionHistogram the positions' histogram too (ranges up to 2^18, the raw scheme's limit).
template <bool kLut, bool kStats, bool kPositionHistogram>
void ComputeWideSymbols(const Point* points, std::size_t n, const PositionQuantizer& pq,
                        const Wrap& wp, const Wrap& wc, const std::uint8_t* lut, Scratch* s,
                        SymbolStats* ps, SymbolStats* cs) {
  std::uint32_t* const psym = s->wide_positions.data();
  std::uint16_t* const csym = s->wide_colors.data();
  std::uint16_t* const bl = s->bit_lengths.data();
  std::uint32_t* const phist = s->position.histogram.data();
  std::uint32_t* const chist = s->color.histogram.data();
  const __m128 half = _mm_set1_ps(0.5f);
  const __m128i zero = _mm_setzero_si128();
  __m128i pprev = _mm_set1_epi32(wp.FirstPrediction());
  __m128i cprev = _mm_set1_epi32(wc.FirstPrediction());
  __m128i por = zero, cor = zero;  // without kStats: for the largest bit lengths
  std::uint32_t ptag[33] = {}, ctag[33] = {};
  // As in ComputeNarrowSymbols: point i - 1's statistics while point i is computed.
  auto gather = [&](std::size_t i) {
    const std::uint32_t p0 = psym[3 * i], p1 = psym[3 * i + 1], p2 = psym[3 * i + 2];
    const std::uint32_t c0 = csym[3 * i], c1 = csym[3 * i + 1], c2 = csym[3 * i + 2];
    if constexpr (kPositionHistogram) {
      ++phist[kHistogramLanes * p0];
      ++phist[kHistogramLanes * p1 + 1];
      ++phist[kHistogramLanes * p2 + 2];
    }
    ++chist[kHistogramLanes * c0];
    ++chist[kHistogramLanes * c1 + 1];
    ++chist[kHistogramLanes * c2 + 2];
    const std::uint32_t pb = BitLength(p0, p1, p2), cb = BitLength(c0, c1, c2);
    bl[i] = static_cast<std::uint16_t>(pb | (cb << 8));
    ++ptag[pb];
    ++ctag[cb];
  };
  for (std::size_t i = 0; i < n; ++i) {
    const __m128 v = _mm_loadu_ps(&points[i].x);
    const __m128i q = _mm_cvttps_epi32(_mm_add_ps(_mm_mul_ps(_mm_sub_ps(v, pq.min), pq.inv), half));
    __m128i c;
    if constexpr (kLut) {
      const std::uint32_t rgba = points[i].rgba;
      c = _mm_setr_epi32(lut[BlueOf(rgba)], lut[GreenOf(rgba)], lut[RedOf(rgba)], 0);
    } else {
      c = _mm_unpackhi_epi16(_mm_unpackhi_epi8(_mm_castps_si128(v), zero), zero);
    }
    const __m128i sp = wp.Symbols(q, pprev);
    const __m128i sc = wc.Symbols(c, cprev);
    pprev = q;
    cprev = c;
    // 4-lane stores; lane 3 is overwritten by the next point (the buffers hold one extra).
    _mm_storeu_si128(reinterpret_cast<__m128i*>(psym + 3 * i), sp);
    _mm_storel_epi64(reinterpret_cast<__m128i*>(csym + 3 * i), _mm_packs_epi32(sc, sc));
    if constexpr (kStats) {
      if (i > 0) gather(i - 1);
    } else {
      por = _mm_or_si128(por, sp);
      cor = _mm_or_si128(cor, sc);
    }
  }
  if constexpr (kStats) gather(n - 1);
  if constexpr (kStats) {
    FinishTagStats(ptag, ps);
    FinishTagStats(ctag, cs);
  } else {
    ps->max_bit_length = static_cast<int>(BitLength(HorizontalOr3(por), 0, 0));
    cs->max_bit_length = static_cast<int>(BitLength(HorizontalOr3(cor), 0, 0));
  }
}

// ---------------------------------------------------------------------------------------------
// Draco's symbol coding.

// How one attribute's symbols are coded.
struct Coding {
  bool raw = false;  // SYMBOL_CODING_RAW, else tagged
  int precision_bits = kTagPrecisionBits;
};

// Draco's EncodeSymbols up to the symbols themselves, for `n` points of 3 components with
// compression level 0 (speed 10): it estimates the bits of its two schemes and takes the
// tagged one unless the raw one is strictly cheaper and its values have at most 18 bits.
//   tagged: per point, the bit length of its largest value is rANS-coded (precision 12), then
//           every value follows in that many bits, LSB first;
//   raw:    every value is rANS-coded over the histogram of all values.
// Writes the scheme, its parameters and the probability table to a->prefix and builds
// a->coder. False where Draco would fail or write a broken stream.
bool PlanSymbols(std::size_t n, const std::uint32_t* wide_symbols, SymbolStats* st,
                 AttributeScratch* a, Scratch* s, Coding* coding) {
  const std::uint64_t num_values = 3 * std::uint64_t{n};
  int tag_unique = 0;
  const std::int64_t tag_bits = ShannonEntropyBits(st->tag_freq, 32, n, &tag_unique, s);
  const std::int64_t tagged_bits = static_cast<std::int64_t>(
      static_cast<std::uint64_t>(tag_bits + RansTableBits(tag_unique, tag_unique)) +
      st->total_bit_length * 3);
  const int max_value_bit_length = st->max_bit_length;
  std::uint32_t max_value = 0;
  int raw_unique = 0;
  coding->raw = false;
  if (max_value_bit_length <= kMaxRawEncodingBitLength) {
    std::vector<std::uint32_t>& hist = a->histogram;
    if (!st->histogram_ready) {  // only positions, of ranges of 2^18 and more: wide symbols
      const std::size_t entries = std::size_t{1} << max_value_bit_length;
      if (hist.size() < entries) hist.resize(entries);
      a->histogram_used = std::max(a->histogram_used, entries);
      for (std::uint64_t i = 0; i < num_values; ++i) ++hist[wide_symbols[i]];
      st->histogram_ready = true;
      st->histogram_entries = entries;
    }
    max_value = static_cast<std::uint32_t>(std::min<std::size_t>(
        st->histogram_entries - 1, (std::size_t{1} << max_value_bit_length) - 1));
    while (hist[max_value] == 0) --max_value;
    const std::int64_t data_bits =
        ShannonEntropyBits(hist.data(), max_value, num_values, &raw_unique, s);
    const std::int64_t raw_bits =
        RansTableBits(static_cast<std::int32_t>(max_value), raw_unique) + data_bits;
    coding->raw = !(tagged_bits < raw_bits);
  }

  std::string* prefix = &a->prefix;
  prefix->clear();
  PutU8(prefix, kPredictionDifference);
  PutU8(prefix, kTransformWrap);
  PutU8(prefix, 1);  // entropy coded
  if (!coding->raw) {
    PutU8(prefix, kSymbolCodingTagged);
    if (st->tag_freq[32] != 0) return false;  // Draco's 32-entry table would overflow
    coding->precision_bits = kTagPrecisionBits;
    return BuildRansCoder(st->tag_freq, 32, kTagPrecisionBits, s, &a->coder, prefix);
  }
  PutU8(prefix, kSymbolCodingRaw);
  const int symbol_bits =
      raw_unique > 0 ? MostSignificantBit(static_cast<std::uint32_t>(raw_unique)) : 0;
  int unique_bit_length = symbol_bits + 1;
  if (unique_bit_length > kMaxRawEncodingBitLength) return false;  // Draco fails here too
  // Compression level 0 (10 - speed) takes two bits off; Draco's precision is then
  // max(12, min(20, 3 * bits / 2)).
  unique_bit_length = std::clamp(unique_bit_length - 2, 1, kMaxRawEncodingBitLength);
  PutU8(prefix, static_cast<std::uint8_t>(unique_bit_length));
  coding->precision_bits = std::clamp(3 * unique_bit_length / 2, 12, 20);
  return BuildRansCoder(a->histogram.data(), max_value + 1, coding->precision_bits, s, &a->coder,
                        prefix);
}

// The tagged scheme's values: in point order, each point's three in its bit length, LSB first.
// Written backwards, alongside the rANS streams, by OR-ing each point's bits in at their offset
// (3 times the bit lengths before it) into a zeroed buffer of the size plus 8.
class TaggedValueWriter {
 public:
  TaggedValueWriter(std::uint8_t* zeroed, std::uint64_t total_bits)
      : base_(zeroed), offset_(total_bits) {}

  // The same for 4 times the values (NarrowSymbols), at most 14 bits: shifted together.
  CLOUDCAST_INLINE void PutScaled(std::uint32_t v0, std::uint32_t v1, std::uint32_t v2,
                                  unsigned bits) {
    offset_ -= 3 * bits;
    Or((std::uint64_t{v0} | (std::uint64_t{v1} << bits) | (std::uint64_t{v2} << (2 * bits))) >> 2);
  }

  CLOUDCAST_INLINE void Put(std::uint32_t v0, std::uint32_t v1, std::uint32_t v2, unsigned bits) {
    if (bits <= 19) {  // the three values and the offset's 7 bits fit in 64
      offset_ -= 3 * bits;
      Or(std::uint64_t{v0} | (std::uint64_t{v1} << bits) | (std::uint64_t{v2} << (2 * bits)));
    } else {
      offset_ -= bits;
      Or(v2);
      offset_ -= bits;
      Or(v1);
      offset_ -= bits;
      Or(v0);
    }
  }

 private:
  CLOUDCAST_INLINE void Or(std::uint64_t v) {
    std::uint8_t* const p = base_ + (offset_ >> 3);
    std::uint64_t word;
    std::memcpy(&word, p, 8);
    word |= v << (offset_ & 7);
    std::memcpy(p, &word, 8);
  }

  std::uint8_t* base_;
  std::uint64_t offset_;
};

std::uint64_t TaggedValueBytes(const SymbolStats& st) { return (st.total_bit_length * 3 + 7) / 8; }

// Both attributes' rANS streams (and tagged values) in one backward pass over the points. Raw
// coding adds a point's three symbols (last component first), tagged coding its bit length.
template <bool kPositionRaw, bool kColorRaw, int kPositionPrecision, int kColorPrecision,
          typename Symbols>
void EncodeStreams(const Symbols sym, std::size_t n, const Coding& pc, const Coding& cc,
                   const SymbolStats& ps, const SymbolStats& cs, Scratch* s,
                   std::size_t* position_bytes, std::size_t* color_bytes) {
  AttributeScratch& pa = s->position;
  AttributeScratch& ca = s->color;
  // Each symbol emits at most 3 bytes (below 1024 * 2^20, the state shrinks by at most 2^24 to
  // get below 1024 p), the end 4, and the stores write 4 at a time.
  const std::size_t psize = (kPositionRaw ? 9 : 3) * n + 8, csize = (kColorRaw ? 9 : 3) * n + 8;
  if (pa.rans.size() < psize) pa.rans.resize(psize);
  if (ca.rans.size() < csize) ca.rans.resize(csize);
  if constexpr (!kPositionRaw) pa.values.assign(TaggedValueBytes(ps) + 8, 0);
  if constexpr (!kColorRaw) ca.values.assign(TaggedValueBytes(cs) + 8, 0);
  RansWriter<kPositionPrecision> pw(pc.precision_bits, pa.rans.data());
  RansWriter<kColorPrecision> cw(cc.precision_bits, ca.rans.data());
  TaggedValueWriter pv(pa.values.data(), ps.total_bit_length * 3),
      cv(ca.values.data(), cs.total_bit_length * 3);
  const RansSymbol* const pt = pa.coder.data();
  const RansSymbol* const ct = ca.coder.data();
  const std::uint16_t* const bl = s->bit_lengths.data();
  for (std::size_t i = n; i-- > 0;) {
    const unsigned pbl = bl[i] & 0xFF, cbl = bl[i] >> 8;
    if constexpr (kPositionRaw) {
      pw.Put(Symbols::Entry(pt, sym.PositionScaled(i, 2)));
      pw.Put(Symbols::Entry(pt, sym.PositionScaled(i, 1)));
      pw.Put(Symbols::Entry(pt, sym.PositionScaled(i, 0)));
    } else {
      pw.Put(pt[pbl]);
      if constexpr (Symbols::kScaled) {
        pv.PutScaled(sym.PositionScaled(i, 0), sym.PositionScaled(i, 1), sym.PositionScaled(i, 2),
                     pbl);
      } else {
        pv.Put(sym.Position(i, 0), sym.Position(i, 1), sym.Position(i, 2), pbl);
      }
    }
    if constexpr (kColorRaw) {  // stored B, G, R: Draco's last component first
      cw.Put(Symbols::Entry(ct, sym.ColorScaled(i, 0)));
      cw.Put(Symbols::Entry(ct, sym.ColorScaled(i, 1)));
      cw.Put(Symbols::Entry(ct, sym.ColorScaled(i, 2)));
    } else {
      cw.Put(ct[cbl]);
      if constexpr (Symbols::kScaled) {
        cv.PutScaled(sym.ColorScaled(i, 2), sym.ColorScaled(i, 1), sym.ColorScaled(i, 0), cbl);
      } else {
        cv.Put(sym.Color(i, 2), sym.Color(i, 1), sym.Color(i, 0), cbl);
      }
    }
  }
  *position_bytes = pw.Finish();
  *color_bytes = cw.Finish();
}

// EncodeStreams for the codings at hand: tags have precision 2^12, raw streams 2^12 to 2^20.
// Precisions of 12 to 14 bits get their own instances (their division is cheaper), 15 and 16
// one (fewer renormalization bytes); above, raw streams have more than 2^15 distinct symbols.
template <bool kPositionRaw, bool kColorRaw, int kPositionPrecision, typename Symbols>
void EncodeStreamsForColor(const Symbols sym, std::size_t n, const Coding& pc, const Coding& cc,
                           const SymbolStats& ps, const SymbolStats& cs, Scratch* s,
                           std::size_t* pbytes, std::size_t* cbytes) {
  auto run = [&](auto precision) {
    EncodeStreams<kPositionRaw, kColorRaw, kPositionPrecision, decltype(precision)::value>(
        sym, n, pc, cc, ps, cs, s, pbytes, cbytes);
  };
  switch (cc.precision_bits) {
    case 12:
      return run(std::integral_constant<int, 12>{});
    case 13:
      if constexpr (kColorRaw) return run(std::integral_constant<int, 13>{});
      break;
    case 14:
      if constexpr (kColorRaw) return run(std::integral_constant<int, 14>{});
      break;
    case 15:
    case 16:
      if constexpr (kColorRaw) return run(std::integral_constant<int, 16>{});
      break;
  }
  return run(std::integral_constant<int, 0>{});
}

template <bool kPositionRaw, bool kColorRaw, typename Symbols>
void EncodeStreamsFor(const Symbols sym, std::size_t n, const Coding& pc, const Coding& cc,
                      const SymbolStats& ps, const SymbolStats& cs, Scratch* s, std::size_t* pbytes,
                      std::size_t* cbytes) {
  auto run = [&](auto precision) {
    EncodeStreamsForColor<kPositionRaw, kColorRaw, decltype(precision)::value>(
        sym, n, pc, cc, ps, cs, s, pbytes, cbytes);
  };
  switch (pc.precision_bits) {
    case 12:
      return run(std::integral_constant<int, 12>{});
    case 13:
      if constexpr (kPositionRaw) return run(std::integral_constant<int, 13>{});
      break;
    case 14:
      if constexpr (kPositionRaw) return run(std::integral_constant<int, 14>{});
      break;
    case 15:
    case 16:
      if constexpr (kPositionRaw) return run(std::integral_constant<int, 16>{});
      break;
  }
  return run(std::integral_constant<int, 0>{});
}

template <typename Symbols>
void EncodeStreamsFor(const Symbols sym, std::size_t n, const Coding& pc, const Coding& cc,
                      const SymbolStats& ps, const SymbolStats& cs, Scratch* s, std::size_t* pbytes,
                      std::size_t* cbytes) {
  if (pc.raw) {
    if (cc.raw) {
      EncodeStreamsFor<true, true>(sym, n, pc, cc, ps, cs, s, pbytes, cbytes);
    } else {
      EncodeStreamsFor<true, false>(sym, n, pc, cc, ps, cs, s, pbytes, cbytes);
    }
  } else if (cc.raw) {
    EncodeStreamsFor<false, true>(sym, n, pc, cc, ps, cs, s, pbytes, cbytes);
  } else {
    EncodeStreamsFor<false, false>(sym, n, pc, cc, ps, cs, s, pbytes, cbytes);
  }
}

// Values without entropy coding: as many bytes per value as the largest needs, in Draco's
// component order; `symbol(i, k)` is point i's k-th.
template <typename SymbolAt>
void PutStoredValues(SymbolAt symbol, std::size_t n, const SymbolStats& st, std::string* out) {
  const int bytes = 1 + (st.max_bit_length - 1) / 8;
  PutU8(out, kPredictionDifference);
  PutU8(out, kTransformWrap);
  PutU8(out, 0);  // not entropy coded
  PutU8(out, static_cast<std::uint8_t>(bytes));
  const std::size_t at = out->size();
  out->resize(at + 3 * n * bytes + 4);
  auto* dst = reinterpret_cast<std::uint8_t*>(&(*out)[at]);
  for (std::size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k, dst += bytes) Store32(dst, symbol(i, k));
  }
  out->resize(at + 3 * n * bytes);
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

// One per thread: it keeps the largest cloud's capacity, so a warm encoder allocates nothing.
Scratch& ThreadScratch() {
  thread_local Scratch scratch;
  return scratch;
}

// Steps 2 to 4, with the narrow or the wide symbol layout.
template <bool kNarrow>
bool EncodeWith(const Point* points, std::size_t n, const DracoCloudExtent& extent,
                const DracoSequentialOptions& options, const PositionQuantizer& pq, const Wrap& wp,
                const Wrap& wc, float range, std::string* out) {
  Scratch* const s = &ThreadScratch();
  AttributeScratch& pa = s->position;
  AttributeScratch& ca = s->color;
  if constexpr (kNarrow) {
    if (s->records.size() < 8 * n) s->records.resize(8 * n);
  } else {
    if (s->wide_positions.size() < 3 * n + 1) s->wide_positions.resize(3 * n + 1);
    if (s->wide_colors.size() < 3 * n + 1) s->wide_colors.resize(3 * n + 1);
  }
  if (s->bit_lengths.size() < n) s->bit_lengths.resize(n);

  SymbolStats ps, cs;
  const bool stats = options.entropy_coding;
  // Histograms of up to 2^18 entries (the raw scheme's limit) are filled during the pass; for
  // larger ranges the symbols' bit lengths tell first whether the raw scheme can apply at all.
  const bool position_histogram = stats && wp.HistogramSize() <= (1u << kMaxRawEncodingBitLength);
  // The histograms are zero on entry; whatever this call counts in is cleared when it returns.
  struct HistogramCleaner {
    AttributeScratch* a[2];
    ~HistogramCleaner() {
      for (AttributeScratch* x : a) {
        std::fill_n(x->histogram.begin(), x->histogram_used, 0u);
        x->histogram_used = 0;
      }
    }
  } cleaner{{&pa, &ca}};
  auto prepare = [](AttributeScratch* a, std::size_t entries) {
    if (a->histogram.size() < entries) a->histogram.resize(entries);
  };
  if (position_histogram) prepare(&pa, kHistogramLanes * wp.HistogramSize());
  if (stats) prepare(&ca, kHistogramLanes * wc.HistogramSize());
  const std::uint8_t* lut = options.color_lut;
  auto run = [&](auto lut_tag, auto stats_tag, auto histogram_tag) {
    constexpr bool kLut = decltype(lut_tag)::value, kStats = decltype(stats_tag)::value;
    if constexpr (kNarrow) {
      ComputeNarrowSymbols<kLut, kStats>(points, n, pq, wp, wc, lut, s, &ps, &cs);
    } else {
      ComputeWideSymbols<kLut, kStats, decltype(histogram_tag)::value>(points, n, pq, wp, wc, lut,
                                                                       s, &ps, &cs);
    }
  };
  using T = std::true_type;
  using F = std::false_type;
  if (lut != nullptr) {
    if (!stats) {
      run(T{}, F{}, F{});
    } else if (position_histogram) {
      run(T{}, T{}, T{});
    } else {
      run(T{}, T{}, F{});
    }
  } else {
    if (!stats) {
      run(F{}, F{}, F{});
    } else if (position_histogram) {
      run(F{}, T{}, T{});
    } else {
      run(F{}, T{}, F{});
    }
  }
  const std::pair<AttributeScratch*, SymbolStats*> counted[] = {
      {position_histogram ? &pa : nullptr, &ps}, {stats ? &ca : nullptr, &cs}};
  for (auto [a, st] : counted) {
    if (a == nullptr) continue;
    // Sum the per-component counts of the symbols there are (below 2^max_bit_length; the reads
    // run ahead of the writes).
    const Wrap& wrap = a == &pa ? wp : wc;
    const std::size_t entries =
        std::min<std::size_t>(wrap.HistogramSize(), std::size_t{1} << st->max_bit_length);
    std::uint32_t* h = a->histogram.data();
    std::size_t v = 0;
    for (; v + 4 <= entries; v += 4) {  // four groups of four at a time (lane 3 stays 0)
      __m128i g0 = _mm_loadu_si128(reinterpret_cast<const __m128i*>(h + 4 * v));
      __m128i g1 = _mm_loadu_si128(reinterpret_cast<const __m128i*>(h + 4 * v + 4));
      __m128i g2 = _mm_loadu_si128(reinterpret_cast<const __m128i*>(h + 4 * v + 8));
      __m128i g3 = _mm_loadu_si128(reinterpret_cast<const __m128i*>(h + 4 * v + 12));
      const __m128i t0 = _mm_unpacklo_epi32(g0, g1), t1 = _mm_unpackhi_epi32(g0, g1);
      const __m128i t2 = _mm_unpacklo_epi32(g2, g3), t3 = _mm_unpackhi_epi32(g2, g3);
      g0 = _mm_unpacklo_epi64(t0, t2);  // lane 0 of each group
      g1 = _mm_unpackhi_epi64(t0, t2);
      g2 = _mm_unpacklo_epi64(t1, t3);
      g3 = _mm_unpackhi_epi64(t1, t3);
      const __m128i sum = _mm_add_epi32(_mm_add_epi32(g0, g1), _mm_add_epi32(g2, g3));
      _mm_storeu_si128(reinterpret_cast<__m128i*>(h + v), sum);  // on groups already read
    }
    for (; v < entries; ++v) {
      h[v] = h[kHistogramLanes * v] + h[kHistogramLanes * v + 1] + h[kHistogramLanes * v + 2];
    }
    a->histogram_used = kHistogramLanes * entries;
    st->histogram_ready = true;
    st->histogram_entries = entries;
  }

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

  using Symbols = std::conditional_t<kNarrow, NarrowSymbols, WideSymbols>;
  Symbols sym;
  if constexpr (kNarrow) {
    sym = NarrowSymbols{s->records.data()};
  } else {
    sym = WideSymbols{s->wide_positions.data(), s->wide_colors.data()};
  }
  if (!stats) {
    PutStoredValues([&](std::size_t i, int k) { return sym.Position(i, k); }, n, ps, out);
    PutLe<std::int32_t>(out, wp.min);
    PutLe<std::int32_t>(out, wp.max);
    PutStoredValues([&](std::size_t i, int k) { return sym.Color(i, 2 - k); }, n, cs, out);
    PutLe<std::int32_t>(out, wc.min);
    PutLe<std::int32_t>(out, wc.max);
  } else {
    Coding pc, cc;
    const std::uint32_t* wide = kNarrow ? nullptr : s->wide_positions.data();
    if (!PlanSymbols(n, wide, &ps, &pa, s, &pc) || !PlanSymbols(n, nullptr, &cs, &ca, s, &cc)) {
      return false;
    }
    std::size_t pbytes = 0, cbytes = 0;
    EncodeStreamsFor(sym, n, pc, cc, ps, cs, s, &pbytes, &cbytes);
    const struct {
      const AttributeScratch* a;
      const Coding* coding;
      const SymbolStats* stats;
      const Wrap* wrap;
      std::size_t rans_bytes;
    } attributes[] = {{&pa, &pc, &ps, &wp, pbytes}, {&ca, &cc, &cs, &wc, cbytes}};
    for (const auto& at : attributes) {
      out->append(at.a->prefix);
      PutVarint(out, at.rans_bytes);  // RAnsSymbolEncoder::EndEncoding: the size, the bytes
      out->append(reinterpret_cast<const char*>(at.a->rans.data()), at.rans_bytes);
      if (!at.coding->raw) {
        out->append(reinterpret_cast<const char*>(at.a->values.data()),
                    TaggedValueBytes(*at.stats));
      }
      PutLe<std::int32_t>(out, at.wrap->min);
      PutLe<std::int32_t>(out, at.wrap->max);
    }
  }

  // The quantization parameters follow all values.
  for (int c = 0; c < 3; ++c) PutLe<float>(out, extent.lo[c]);
  PutLe<float>(out, range);
  PutU8(out, static_cast<std::uint8_t>(options.position_bits));
  return true;
}

// The common case of the scan: all points finite, no coordinate bound at +-0.0. It keeps the
// bounds with minps(lo, v), which on equal values takes v: only +-0.0 tell equal floats apart,
// so a bound at zero is left to the careful scan, which keeps Draco's first. Any NaN or
// infinity turns v * 0 into NaN, and the sum of those with it.
bool ScanCommonCase(const Point* points, std::size_t n, DracoCloudExtent* e) {
  const float inf = std::numeric_limits<float>::infinity();
  __m128 lo0 = _mm_set1_ps(inf), hi0 = _mm_set1_ps(-inf), lo1 = lo0, hi1 = hi0;
  __m128 bad0 = _mm_setzero_ps(), bad1 = bad0;
  const __m128 zero = _mm_setzero_ps();
  __m128i clo0 = _mm_set1_epi8(-1), chi0 = _mm_setzero_si128(), clo1 = clo0, chi1 = chi0;
  std::size_t i = 0;
  for (; i + 2 <= n; i += 2) {  // two sets of bounds: twice the independent work per step
    const __m128 a = _mm_loadu_ps(&points[i].x), b = _mm_loadu_ps(&points[i + 1].x);
    lo0 = _mm_min_ps(lo0, a);
    lo1 = _mm_min_ps(lo1, b);
    hi0 = _mm_max_ps(hi0, a);
    hi1 = _mm_max_ps(hi1, b);
    bad0 = _mm_add_ps(bad0, _mm_mul_ps(a, zero));
    bad1 = _mm_add_ps(bad1, _mm_mul_ps(b, zero));
    clo0 = _mm_min_epu8(clo0, _mm_castps_si128(a));  // bytes 12..14 are B, G, R
    clo1 = _mm_min_epu8(clo1, _mm_castps_si128(b));
    chi0 = _mm_max_epu8(chi0, _mm_castps_si128(a));
    chi1 = _mm_max_epu8(chi1, _mm_castps_si128(b));
  }
  if (i < n) {
    const __m128 a = _mm_loadu_ps(&points[i].x);
    lo0 = _mm_min_ps(lo0, a);
    hi0 = _mm_max_ps(hi0, a);
    bad0 = _mm_add_ps(bad0, _mm_mul_ps(a, zero));
    clo0 = _mm_min_epu8(clo0, _mm_castps_si128(a));
    chi0 = _mm_max_epu8(chi0, _mm_castps_si128(a));
  }
  const __m128 lo = _mm_min_ps(lo0, lo1), hi = _mm_max_ps(hi0, hi1);
  const __m128 bad = _mm_add_ps(bad0, bad1);
  // Lane 3 is the colour word seen as a float: ignored.
  if ((_mm_movemask_ps(_mm_cmpunord_ps(bad, bad)) & 7) != 0) return false;
  if ((_mm_movemask_ps(_mm_or_ps(_mm_cmpeq_ps(lo, zero), _mm_cmpeq_ps(hi, zero))) & 7) != 0) {
    return false;
  }
  alignas(16) float l[4], h[4];
  _mm_store_ps(l, lo);
  _mm_store_ps(h, hi);
  alignas(16) std::uint8_t cl[16], ch[16];
  _mm_store_si128(reinterpret_cast<__m128i*>(cl), _mm_min_epu8(clo0, clo1));
  _mm_store_si128(reinterpret_cast<__m128i*>(ch), _mm_max_epu8(chi0, chi1));
  for (int c = 0; c < 3; ++c) {
    e->lo[c] = l[c];
    e->hi[c] = h[c];
  }
  e->color_lo = std::min({cl[12], cl[13], cl[14]});
  e->color_hi = std::max({ch[12], ch[13], ch[14]});
  e->finite = n;
  return true;
}

}  // namespace

DracoCloudExtent ScanForDraco(const Point* points, std::size_t n) {
  DracoCloudExtent e;
  if (n == 0 || ScanCommonCase(points, n, &e)) return e;
  // Some point is not finite (an organized cloud's holes: skipped), or a bound is +-0.0.
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
    color_lo = _mm_min_epu8(color_lo, bits);
    color_hi = _mm_max_epu8(color_hi, bits);
    ++finite;
  }
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

  // Positions: the range is the largest side, computed as Draco computes it (1 for a point).
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
  // The smallest value is 0 (the minimum's) and the largest that of an axis maximum: the float
  // operations are monotonic. (Truncation is Draco's floor here: the values are positive.)
  std::int32_t q_max = 0;
  for (int c = 0; c < 3; ++c) {
    q_max = std::max(q_max, static_cast<std::int32_t>((extent.hi[c] - extent.lo[c]) * inv + 0.5f));
  }
  const Wrap wp(0, q_max);
  const PositionQuantizer pq{_mm_setr_ps(extent.lo[0], extent.lo[1], extent.lo[2], 0.0f),
                             _mm_set1_ps(inv)};
  // Colours: the level table is non-decreasing, so it maps the extent's bounds to the values'.
  const std::uint8_t* lut = options.color_lut;
  const Wrap wc(lut ? lut[extent.color_lo] : extent.color_lo,
                lut ? lut[extent.color_hi] : extent.color_hi);
  if (wp.FitsNarrow()) return EncodeWith<true>(points, n, extent, options, pq, wp, wc, range, out);
  return EncodeWith<false>(points, n, extent, options, pq, wp, wc, range, out);
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
