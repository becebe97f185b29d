#include <algorithm>
#include <cmath>
#include <string>
#include <type_traits>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/filters.h"
#include "kernels.h"

namespace cloudcast {
namespace internal {

namespace {

constexpr std::uint64_t kHashMultiplier = 0x9E3779B97F4A7C15ull;
// A 32-bit-key slot: key << 32 | tag << 25 | voxel + 1. The tag is the cloud's (1 to 127): slots
// of earlier clouds are stale, so the table is not cleared between clouds. Voxel + 1 <= 2^24 + 1
// (Limits::max_pixels points at most) fits in 25 bits.
constexpr int kVoxelBits = 25;
constexpr std::uint64_t kVoxelMask = (std::uint64_t{1} << kVoxelBits) - 1;
constexpr std::uint64_t kTagMask = std::uint64_t{0x7F} << kVoxelBits;
constexpr std::uint32_t kLastTag = 127;
constexpr std::size_t kMinSlots = 1024;

// Voxel indices from four-float SSE points: floor(v * inv) per lane, as int32 (the caller has
// checked that the bounding box keeps them in range), made relative to the box's corner and
// packed into one key.
struct SimdKeys {
  __m128 inv;      // (1/leaf_x, 1/leaf_y, 1/leaf_z, 0)
  __m128i corner;  // the indices of the box's low corner
  int shift_y, shift_z;

  std::uint64_t operator()(__m128 v) const {
    const __m128 t = _mm_mul_ps(v, inv);    // lane 3: colour bits * 0, cleared by the caller
    const __m128i i = _mm_cvttps_epi32(t);  // truncates toward zero ...
    // ... and subtracting 1 where truncation rounded up makes it floor.
    const __m128i floor = _mm_add_epi32(i, _mm_castps_si128(_mm_cmplt_ps(t, _mm_cvtepi32_ps(i))));
    const __m128i rel = _mm_sub_epi32(floor, corner);  // < 2^32 apart: exact as unsigned
    const auto rx = static_cast<std::uint32_t>(_mm_cvtsi128_si32(rel));
    const auto ry = static_cast<std::uint32_t>(_mm_cvtsi128_si32(_mm_shuffle_epi32(rel, 1)));
    const auto rz = static_cast<std::uint32_t>(_mm_cvtsi128_si32(_mm_shuffle_epi32(rel, 2)));
    return std::uint64_t{rx} | (std::uint64_t{ry} << shift_y) | (std::uint64_t{rz} << shift_z);
  }
};

// The same for indices beyond int32 (fine leaves far from the origin), in scalar int64.
struct WideKeys {
  float inv[3];
  std::int64_t corner[3];
  int shift_y, shift_z;

  std::uint64_t operator()(__m128 v) const {
    alignas(16) float p[4];
    _mm_store_ps(p, v);
    std::uint64_t r[3];
    for (int a = 0; a < 3; ++a) {
      const double t = std::floor(static_cast<double>(p[a] * inv[a]));  // float product, as PCL
      r[a] = static_cast<std::uint64_t>(static_cast<std::int64_t>(t) - corner[a]);
    }
    return r[0] | (r[1] << shift_y) | (r[2] << shift_z);
  }
};

int BitWidth(std::uint64_t v) {
  int bits = 0;
  while (bits < 64 && (v >> bits) != 0) ++bits;
  return bits;
}

inline bool Finite(__m128 v) {
  const float big = std::numeric_limits<float>::max();
  const __m128 ok =
      _mm_and_ps(_mm_cmple_ps(_mm_set1_ps(-big), v), _mm_cmple_ps(v, _mm_set1_ps(big)));
  return (_mm_movemask_ps(ok) & 7) == 7;
}

}  // namespace

void VoxelAccumulator::ResizeTable(std::size_t slots) {
  // Rehash from the old table's own live (key, voxel) entries.
  std::vector<std::uint64_t> old;
  old.swap(table_);
  const bool had_entries = voxel_count_ > 0;
  table_.assign(wide_ ? 2 * slots : slots, 0);
  table_wide_ = wide_;
  mask_ = slots - 1;
  shift_ = 64 - BitWidth(slots - 1);
  if (!had_entries) return;
  auto insert = [&](std::uint64_t key, std::uint64_t tagged_voxel) {
    std::uint64_t h = (key * kHashMultiplier) >> shift_;
    if (wide_) {
      while (table_[2 * h + 1] != 0) h = (h + 1) & mask_;
      table_[2 * h] = key;
      table_[2 * h + 1] = tagged_voxel;
    } else {
      while (table_[h] != 0) h = (h + 1) & mask_;
      table_[h] = (key << 32) | tagged_voxel;
    }
  };
  if (wide_) {
    const std::uint64_t tag = std::uint64_t{tag_} << 32;
    for (std::size_t i = 0; i + 1 < old.size(); i += 2) {
      if ((old[i + 1] >> 32 << 32) == tag) insert(old[i], old[i + 1]);
    }
  } else {
    const std::uint64_t tag = std::uint64_t{tag_} << kVoxelBits;
    for (std::uint64_t e : old) {
      if ((e & kTagMask) == tag) insert(e >> 32, e & 0xFFFFFFFFu);
    }
  }
}

VoxelAccumulator::Cursor VoxelAccumulator::MakeCursor() {
  const std::uint64_t tag = std::uint64_t{tag_} << (wide_ ? 32 : kVoxelBits);
  return Cursor{table_.data(), voxels_.data(), keys_.data(), tag,
                mask_,         shift_,         voxel_count_, (mask_ + 1) / 2};
}

void VoxelAccumulator::Grow(Cursor* cursor) {
  voxel_count_ = cursor->count;
  ResizeTable(2 * (mask_ + 1));
  *cursor = MakeCursor();
}

// Colour bytes (b, g, r, a) of one point as four 32-bit lanes.
inline __m128i WidenColour(std::uint32_t rgba) {
  const __m128i zero = _mm_setzero_si128();
  const __m128i bytes = _mm_cvtsi32_si128(static_cast<int>(rgba));
  return _mm_unpacklo_epi16(_mm_unpacklo_epi8(bytes, zero), zero);
}

template <bool kWide, bool kKeys>
inline void VoxelAccumulator::AddSums(Cursor& c, std::uint64_t key, const Sums& s) {
  std::uint64_t h = (key * kHashMultiplier) >> c.shift;
  std::uint64_t found;  // voxel + 1, or 0 for a slot that is empty or an earlier cloud's
  bool match;
  for (;;) {  // almost always one round: the table is at most half full
    if constexpr (kWide) {
      const std::uint64_t e = c.table[2 * h + 1];
      const std::uint64_t live = 0 - static_cast<std::uint64_t>((e >> 32 << 32) == c.tag);
      found = e & 0xFFFFFFFFu & live;
      match = found != 0 && c.table[2 * h] == key;
    } else {
      const std::uint64_t e = c.table[h];
      // This cloud's slot: voxel + 1 (< 2^25) once the tag is xor-ed out; anything else is more.
      const std::uint64_t x = (e & 0xFFFFFFFFu) ^ c.tag;
      found = x & (0 - static_cast<std::uint64_t>(x <= kVoxelMask));
      match = found != 0 && (e >> 32) == key;
    }
    if (match || found == 0) break;
    h = (h + 1) & c.mask;
  }
  // Seen before: its voxel. New: the next free one, whose old contents the masks below zero.
  const std::size_t index = match ? found - 1 : c.count;
  c.count += match ? 0 : 1;
  if constexpr (kWide) {
    c.table[2 * h] = key;
    c.table[2 * h + 1] = c.tag | (index + 1);
  } else {
    c.table[h] = (key << 32) | c.tag | (index + 1);
    if constexpr (kKeys) c.keys[index] = static_cast<std::uint32_t>(key);
  }
  Voxel& voxel = c.voxels[index];
  const __m128i keep = _mm_set1_epi64x(-static_cast<std::int64_t>(match));
  const __m128d keep_d = _mm_castsi128_pd(keep);
  voxel.sum_xy = _mm_add_pd(_mm_and_pd(voxel.sum_xy, keep_d), s.xy);
  voxel.sum_z_n = _mm_add_pd(_mm_and_pd(voxel.sum_z_n, keep_d), s.zn);
  voxel.sum_bgra = _mm_add_epi32(_mm_and_si128(voxel.sum_bgra, keep), s.bgra);
}

// One point as sums: (x, y) and (z, 1) in double (the count rides along with z), colour as is.
// Only lanes 0 to 2 of `v` are read.
inline VoxelAccumulator::Sums OnePoint(__m128 v, __m128i bgra32) {
  const __m128 z1 = _mm_unpacklo_ps(_mm_movehl_ps(v, v), _mm_set1_ps(1.0f));
  return {_mm_cvtps_pd(v), _mm_cvtps_pd(z1), bgra32};
}
inline void AddTo(VoxelAccumulator::Sums& s, __m128 v, __m128i bgra32) {
  const VoxelAccumulator::Sums one = OnePoint(v, bgra32);
  s.xy = _mm_add_pd(s.xy, one.xy);
  s.zn = _mm_add_pd(s.zn, one.zn);
  s.bgra = _mm_add_epi32(s.bgra, one.bgra);
}

template <bool kWide, bool kKeys>
inline void VoxelAccumulator::AddPoint(Cursor& c, std::uint64_t key, __m128 v, __m128i bgra32) {
  AddSums<kWide, kKeys>(c, key, OnePoint(v, bgra32));
}

template <typename KeyPolicy>
void VoxelAccumulator::Accumulate(const Point* points, std::size_t n, const KeyPolicy& keys) {
  const __m128 xyz_mask = _mm_castsi128_ps(_mm_setr_epi32(-1, -1, -1, 0));
  Cursor c = MakeCursor();
  for (std::size_t i = 0; i < n; ++i) {
    const __m128 v = _mm_and_ps(_mm_loadu_ps(&points[i].x), xyz_mask);
    if (!Finite(v)) continue;
    if (wide_) {
      AddPoint<true, false>(c, keys(v), v, WidenColour(points[i].rgba));
    } else if (keep_keys_) {
      AddPoint<false, true>(c, keys(v), v, WidenColour(points[i].rgba));
    } else {
      AddPoint<false, false>(c, keys(v), v, WidenColour(points[i].rgba));
    }
    if (c.count >= c.grow_at) Grow(&c);
  }
  voxel_count_ = c.count;
}

// The common case, finite points and 32-bit keys: four points at a time, transposed so that the
// voxel keys and colours of all four come out of a few SSE instructions.
template <bool kKeys, typename KeyPolicy>
void VoxelAccumulator::AccumulateFiniteNarrow(const Point* points, std::size_t n,
                                              const KeyPolicy& keys) {
  const __m128 inv_x = _mm_set1_ps(_mm_cvtss_f32(keys.inv));
  const __m128 inv_y = _mm_set1_ps(_mm_cvtss_f32(_mm_shuffle_ps(keys.inv, keys.inv, 0x55)));
  const __m128 inv_z = _mm_set1_ps(_mm_cvtss_f32(_mm_shuffle_ps(keys.inv, keys.inv, 0xAA)));
  const __m128i corner_x = _mm_shuffle_epi32(keys.corner, 0x00);
  const __m128i corner_y = _mm_shuffle_epi32(keys.corner, 0x55);
  const __m128i corner_z = _mm_shuffle_epi32(keys.corner, 0xAA);
  const __m128i shift_y = _mm_cvtsi32_si128(keys.shift_y);
  const __m128i shift_z = _mm_cvtsi32_si128(keys.shift_z);
  auto relative = [](__m128 coord, __m128 inv, __m128i corner) {
    const __m128 t = _mm_mul_ps(coord, inv);
    const __m128i i = _mm_cvttps_epi32(t);  // truncation, minus 1 where it rounded up: floor
    return _mm_sub_epi32(_mm_add_epi32(i, _mm_castps_si128(_mm_cmplt_ps(t, _mm_cvtepi32_ps(i)))),
                         corner);
  };
  const __m128i zero = _mm_setzero_si128();
  Cursor c = MakeCursor();
  std::size_t i = 0;
  // Consecutive points (neighbouring pixels) often share a voxel: a run of them is summed in
  // registers and added to its voxel once, with one hash look-up.
  std::uint64_t run_key = ~std::uint64_t{0};  // no 32-bit key
  Sums run{_mm_setzero_pd(), _mm_setzero_pd(), _mm_setzero_si128()};
  auto add = [&](std::uint32_t k, __m128 v, __m128i bgra) {
    if (k == run_key) {
      AddTo(run, v, bgra);
    } else {
      if (run_key != ~std::uint64_t{0}) AddSums<false, kKeys>(c, run_key, run);
      run_key = k;
      run = OnePoint(v, bgra);
    }
  };
  auto block_keys = [&](std::size_t at) {
    const __m128 p0 = _mm_loadu_ps(&points[at].x), p1 = _mm_loadu_ps(&points[at + 1].x);
    const __m128 p2 = _mm_loadu_ps(&points[at + 2].x), p3 = _mm_loadu_ps(&points[at + 3].x);
    // Transpose to the x, y and z of the four points.
    const __m128 t0 = _mm_unpacklo_ps(p0, p1), t1 = _mm_unpacklo_ps(p2, p3);
    const __m128 t2 = _mm_unpackhi_ps(p0, p1), t3 = _mm_unpackhi_ps(p2, p3);
    const __m128 x = _mm_movelh_ps(t0, t1), y = _mm_movehl_ps(t1, t0);
    const __m128 z = _mm_movelh_ps(t2, t3);
    return _mm_or_si128(relative(x, inv_x, corner_x),
                        _mm_or_si128(_mm_sll_epi32(relative(y, inv_y, corner_y), shift_y),
                                     _mm_sll_epi32(relative(z, inv_z, corner_z), shift_z)));
  };
  // The keys of the points kLookahead blocks ahead are made early and their table slots
  // prefetched: a new voxel's slot is a random line of the table, whose miss would stall.
  constexpr std::size_t kLookahead = 8, kRing = 16;  // kRing: a power of two > kLookahead
  alignas(16) std::uint32_t ring[kRing][4];
  const std::size_t blocks = n / 4;
  auto prepare = [&](std::size_t b) {
    std::uint32_t* k = ring[b & (kRing - 1)];
    _mm_store_si128(reinterpret_cast<__m128i*>(k), block_keys(4 * b));
    for (int j = 0; j < 4; ++j) {
      const std::uint64_t h = (std::uint64_t{k[j]} * kHashMultiplier) >> c.shift;
      _mm_prefetch(reinterpret_cast<const char*>(c.table + h), _MM_HINT_T0);
    }
  };
  for (std::size_t b = 0; b < kLookahead && b < blocks; ++b) prepare(b);
  for (std::size_t b = 0; b < blocks; ++b, i += 4) {
    if (b + kLookahead < blocks) prepare(b + kLookahead);
    const std::uint32_t* key = ring[b & (kRing - 1)];
    const __m128 p0 = _mm_loadu_ps(&points[i].x), p1 = _mm_loadu_ps(&points[i + 1].x);
    const __m128 p2 = _mm_loadu_ps(&points[i + 2].x), p3 = _mm_loadu_ps(&points[i + 3].x);
    const __m128 t2 = _mm_unpackhi_ps(p0, p1), t3 = _mm_unpackhi_ps(p2, p3);
    const __m128i colour = _mm_castps_si128(_mm_movehl_ps(t3, t2));
    const __m128i c16lo = _mm_unpacklo_epi8(colour, zero), c16hi = _mm_unpackhi_epi8(colour, zero);
    // Lane 3 (the colour's bits) never reaches the sums: OnePoint converts lanes 0 to 2 only.
    add(key[0], p0, _mm_unpacklo_epi16(c16lo, zero));
    add(key[1], p1, _mm_unpackhi_epi16(c16lo, zero));
    add(key[2], p2, _mm_unpacklo_epi16(c16hi, zero));
    add(key[3], p3, _mm_unpackhi_epi16(c16hi, zero));
    // Checked every four points: the table has room for four more beyond half full.
    if (c.count >= c.grow_at) Grow(&c);
  }
  if (run_key != ~std::uint64_t{0}) AddSums<false, kKeys>(c, run_key, run);
  voxel_count_ = c.count;
  Accumulate(points + i, n - i, keys);
}

const std::uint64_t* VoxelAccumulator::KeyOrder() {
  if (wide_) {  // 64-bit keys (rare): a comparison sort of (key, voxel) pairs
    std::vector<std::pair<std::uint64_t, std::uint64_t>> pairs;
    pairs.reserve(voxel_count_);
    const std::uint64_t tag = std::uint64_t{tag_} << 32;
    for (std::size_t i = 0; i + 1 < table_.size(); i += 2) {
      const std::uint64_t e = table_[i + 1];
      if ((e >> 32 << 32) == tag) pairs.emplace_back(table_[i], (e & 0xFFFFFFFFu) - 1);
    }
    std::sort(pairs.begin(), pairs.end());
    sort_a_.resize(voxel_count_);
    for (std::size_t i = 0; i < pairs.size(); ++i) sort_a_[i] = pairs[i].second;
    return sort_a_.data();
  }
  // 32-bit keys: (key << 32 | voxel) sorted as numbers. Least significant digit first, over the
  // bits the keys use, in as few passes of at most 11 bits (2048 buckets: few enough for the
  // scattered stores to stay in cache) as those bits need.
  if (voxel_count_ == 0) return nullptr;
  switch ((key_bits_ + 10) / 11) {
    case 0:
    case 1:
      return RadixSortKeys<1>();
    case 2:
      return RadixSortKeys<2>();
    default:
      return RadixSortKeys<3>();
  }
}

template <int kPasses>
const std::uint64_t* VoxelAccumulator::RadixSortKeys() {
  const std::size_t m = voxel_count_;
  sort_a_.resize(m + 1);
  sort_b_.resize(m + 1);
  // (key << 32 | voxel) from the keys kept per voxel while accumulating.
  std::uint64_t* packed = sort_b_.data();
  for (std::size_t i = 0; i < m; ++i) packed[i] = (std::uint64_t{keys_[i]} << 32) | i;
  const int digit = std::max(1, (key_bits_ + kPasses - 1) / kPasses);
  const std::uint64_t digit_mask = (std::uint64_t{1} << digit) - 1;
  const std::size_t buckets = std::size_t{1} << digit;
  std::uint32_t* const counts = sort_counts_;
  std::fill(counts, counts + kPasses * buckets, 0u);
  for (std::size_t i = 0; i < m; ++i) {
    for (int p = 0; p < kPasses; ++p) {
      ++counts[p * buckets + ((packed[i] >> (32 + p * digit)) & digit_mask)];
    }
  }
  for (int p = 0; p < kPasses; ++p) {  // counts become each bucket's first position
    std::uint32_t* offset = counts + p * buckets;
    std::uint32_t sum = 0;
    for (std::size_t d = 0; d < buckets; ++d) {
      const std::uint32_t k = offset[d];
      offset[d] = sum;
      sum += k;
    }
  }
  std::uint64_t* from = packed;
  std::uint64_t* to = sort_a_.data();
  for (int p = 0; p < kPasses; ++p) {
    std::uint32_t* offset = counts + p * buckets;
    const int shift = 32 + p * digit;
    for (std::size_t i = 0; i < m; ++i) to[offset[(from[i] >> shift) & digit_mask]++] = from[i];
    std::swap(from, to);
  }
  return from;
}

void VoxelAccumulator::Emit(std::uint32_t min_points, const std::uint64_t* order,
                            PointVector* out) const {
  const std::size_t first = out->size();
  out->resize(first + voxel_count_);  // not initialised (PointVector)
  Point* o = out->data() + first;
  // One division per voxel: integer divisions of the colour sums would cost more than the rest
  // of the voxel together. floor(sum / n) == floor(sum * (1/n) * (1 + 2^-40)): the nudge lifts
  // results that should be whole numbers over their rounding, and is far smaller than the gap
  // (>= 1/n >= 2^-24) between a fraction and the next integer.
  constexpr double kNudge = 1.0 + 1.0 / (1ull << 40);
  // Locals: the stores of points could alias the members, which would be reloaded per voxel.
  const Voxel* const voxels = voxels_.data();
  const std::size_t count = voxel_count_;
  auto emit = [&](auto ordered_tag) {
    constexpr bool kOrdered = decltype(ordered_tag)::value;
    for (std::size_t i = 0; i < count; ++i) {
      // In key order the voxels are read in a random order: fetch them a few ahead.
      if (kOrdered && i + 8 < count) {
        _mm_prefetch(reinterpret_cast<const char*>(&voxels[order[i + 8] & kVoxelMask]),
                     _MM_HINT_T0);
      }
      const Voxel& v = voxels[kOrdered ? order[i] & kVoxelMask : i];
      const double n = _mm_cvtsd_f64(_mm_unpackhi_pd(v.sum_z_n, v.sum_z_n));
      if (n < min_points) continue;
      const __m128d inv = _mm_set1_pd(1.0 / n);
      const __m128d xy = _mm_mul_pd(v.sum_xy, inv);
      const __m128d zn = _mm_mul_pd(v.sum_z_n, inv);
      std::uint32_t rgba;
      if (n < (1 << 23)) {  // sums < 2^31: exact as signed 32-bit
        const __m128d scale = _mm_set1_pd((1.0 / n) * kNudge);
        const __m128i bg = _mm_cvttpd_epi32(_mm_mul_pd(_mm_cvtepi32_pd(v.sum_bgra), scale));
        const __m128i ra = _mm_cvttpd_epi32(
            _mm_mul_pd(_mm_cvtepi32_pd(_mm_unpackhi_epi64(v.sum_bgra, v.sum_bgra)), scale));
        // (b, g, r, a), each 0..255, narrowed to bytes in that order: PCL's packing.
        const __m128i bgra = _mm_packs_epi32(_mm_unpacklo_epi64(bg, ra), _mm_setzero_si128());
        rgba = static_cast<std::uint32_t>(
            _mm_cvtsi128_si32(_mm_packus_epi16(bgra, _mm_setzero_si128())));
      } else {
        alignas(16) std::uint32_t sums[4];
        _mm_store_si128(reinterpret_cast<__m128i*>(sums), v.sum_bgra);
        const auto points = static_cast<std::uint32_t>(n);
        rgba = PackRgba(static_cast<std::uint8_t>(sums[2] / points),
                        static_cast<std::uint8_t>(sums[1] / points),
                        static_cast<std::uint8_t>(sums[0] / points),
                        static_cast<std::uint8_t>(sums[3] / points));
      }
      // PCL: the centroid of the points, and the truncated mean of each colour channel. One
      // 16-byte store: (x, y) and (z, colour).
      const __m128 z_rgba = _mm_unpacklo_ps(
          _mm_cvtpd_ps(zn), _mm_castsi128_ps(_mm_cvtsi32_si128(static_cast<int>(rgba))));
      _mm_storeu_ps(&o->x, _mm_movelh_ps(_mm_cvtpd_ps(xy), z_rgba));
      ++o;
    }
  };
  if (order != nullptr) {
    emit(std::true_type{});
  } else {
    emit(std::false_type{});
  }
  out->resize(static_cast<std::size_t>(o - out->data()));
}

absl::Status VoxelAccumulator::Layout(const Bounds& bounds, const VoxelGridParams& params) {
  const float inv[3] = {1.0f / params.leaf_x, 1.0f / params.leaf_y, 1.0f / params.leaf_z};
  alignas(16) float lo[4], hi[4];
  _mm_store_ps(lo, bounds.lo);
  _mm_store_ps(hi, bounds.hi);
  // Float products and floor are monotonic, so the box's corners bound every point's index.
  int bits[3];
  int32_indices_ = true;
  for (int a = 0; a < 3; ++a) {
    const double tlo = std::floor(static_cast<double>(lo[a] * inv[a]));
    const double thi = std::floor(static_cast<double>(hi[a] * inv[a]));
    if (!(std::fabs(tlo) < 4e18) || !(std::fabs(thi) < 4e18)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "voxel grid: the cloud reaches ", std::fabs(tlo) > std::fabs(thi) ? lo[a] : hi[a],
          " on axis ", std::string(Name(static_cast<Axis>(a))),
          ", more than 2^62 leaves from the origin; use a larger voxel.leaf"));
    }
    inv_[a] = inv[a];
    corner_[a] = static_cast<std::int64_t>(tlo);
    bits[a] = BitWidth(static_cast<std::uint64_t>(static_cast<std::int64_t>(thi) - corner_[a]));
    int32_indices_ &= std::fabs(tlo) < 2e9 && std::fabs(thi) < 2e9;
  }
  const int total_bits = bits[0] + bits[1] + bits[2];
  if (total_bits > 64) {
    return absl::InvalidArgumentError(
        absl::StrCat("voxel grid: the cloud spans 2^", bits[0], " x 2^", bits[1], " x 2^", bits[2],
                     " voxels, more than 64-bit keys hold; use a larger voxel.leaf"));
  }
  shift_y_ = bits[0];
  shift_z_ = bits[0] + bits[1];
  wide_ = total_bits > 32 || !int32_indices_;
  key_bits_ = total_bits;
  return absl::OkStatus();
}

void VoxelAccumulator::Reserve(std::size_t voxels) {
  if (voxels_.size() >= voxels) return;
  // Left uninitialised; grows geometrically, so batches of a large cloud copy little.
  const std::size_t size = std::max(voxels, 2 * voxels_.size());
  voxels_.resize(size);
  keys_.resize(size);
}

void VoxelAccumulator::StartCloud(std::size_t max_points) {
  voxel_count_ = 0;
  std::size_t slots = kMinSlots;
  std::size_t recent = 256;
  for (std::size_t v : recent_voxels_) recent = std::max(recent, v);
  const std::size_t expected = std::min(max_points, recent);
  while (slots < 2 * expected) slots *= 2;
  // A new tag makes every slot stale: no clearing, but once every 127 clouds.
  if (++tag_ > kLastTag) {
    tag_ = 1;
    std::fill(table_.begin(), table_.end(), 0);
  }
  if (slots != mask_ + 1 || table_wide_ != wide_ || table_.empty()) ResizeTable(slots);
}

void VoxelAccumulator::Finish(const VoxelGridParams& params, PointVector* out) {
  recent_voxels_[clouds_++ % 8] = voxel_count_;
  Emit(params.min_points_per_voxel, params.key_order ? KeyOrder() : nullptr, out);
}

void VoxelAccumulator::EmitAgain(const VoxelGridParams& params, std::uint32_t min_points,
                                 PointVector* out) {
  out->clear();
  Emit(min_points, params.key_order ? KeyOrder() : nullptr, out);
}

bool VoxelAccumulator::BeginNarrow(const Bounds& box, const VoxelGridParams& params,
                                   std::size_t max_points) {
  voxel_count_ = 0;
  if (max_points >= kVoxelMask || box.empty() || !Layout(box, params).ok() || wide_) return false;
  keep_keys_ = params.key_order;
  StartCloud(max_points);
  return true;
}

void VoxelAccumulator::AddNarrow(const Point* points, std::size_t n) {
  Reserve(voxel_count_ + n);  // every point may be a voxel of its own
  const SimdKeys keys{_mm_setr_ps(inv_[0], inv_[1], inv_[2], 0.0f),
                      _mm_setr_epi32(static_cast<int>(corner_[0]), static_cast<int>(corner_[1]),
                                     static_cast<int>(corner_[2]), 0),
                      shift_y_, shift_z_};
  if (keep_keys_) {
    AccumulateFiniteNarrow<true>(points, n, keys);
  } else {
    AccumulateFiniteNarrow<false>(points, n, keys);
  }
}

absl::Status VoxelAccumulator::Run(const Point* points, std::size_t n,
                                   const VoxelGridParams& params, PointVector* out,
                                   const Bounds* known_bounds) {
  Bounds bounds;
  bool all_finite = true;
  if (known_bounds != nullptr) {
    bounds = *known_bounds;
  } else {
    const __m128 xyz_mask = _mm_castsi128_ps(_mm_setr_epi32(-1, -1, -1, 0));
    for (std::size_t i = 0; i < n; ++i) {
      const __m128 v = _mm_and_ps(_mm_loadu_ps(&points[i].x), xyz_mask);
      if (Finite(v)) {
        bounds.Add(v);
      } else {
        all_finite = false;
      }
    }
  }
  voxel_count_ = 0;
  if (n == 0 || bounds.empty()) return absl::OkStatus();
  if (auto s = Layout(bounds, params); !s.ok()) return s;
  // More voxels than a 32-bit key's slot numbers (beyond Limits' default): 64-bit slots.
  if (n >= kVoxelMask) wide_ = true;
  keep_keys_ = params.key_order && !wide_;
  StartCloud(n);
  Reserve(n);  // every finite point may be a voxel of its own
  if (int32_indices_) {
    const SimdKeys keys{_mm_setr_ps(inv_[0], inv_[1], inv_[2], 0.0f),
                        _mm_setr_epi32(static_cast<int>(corner_[0]), static_cast<int>(corner_[1]),
                                       static_cast<int>(corner_[2]), 0),
                        shift_y_, shift_z_};
    if (all_finite && !wide_ && keep_keys_) {
      AccumulateFiniteNarrow<true>(points, n, keys);
    } else if (all_finite && !wide_) {
      AccumulateFiniteNarrow<false>(points, n, keys);
    } else {
      Accumulate(points, n, keys);
    }
  } else {
    const WideKeys keys{
        {inv_[0], inv_[1], inv_[2]}, {corner_[0], corner_[1], corner_[2]}, shift_y_, shift_z_};
    Accumulate(points, n, keys);
  }
  Finish(params, out);
  return absl::OkStatus();
}

}  // namespace internal

struct VoxelGrid::Impl {
  internal::VoxelAccumulator accumulator;
};

VoxelGrid::VoxelGrid() : impl_(std::make_unique<Impl>()) {}
VoxelGrid::~VoxelGrid() = default;
VoxelGrid::VoxelGrid(VoxelGrid&&) noexcept = default;
VoxelGrid& VoxelGrid::operator=(VoxelGrid&&) noexcept = default;

absl::Status VoxelGrid::Filter(const PointCloud& in, const VoxelGridParams& params,
                               PointCloud* out) {
  if (out == nullptr) return absl::InvalidArgumentError("output cloud is null");
  if (out == &in) return absl::InvalidArgumentError("voxel grid output must not alias its input");
  if (auto s = params.Validate(); !s.ok()) return s;
  if (!params.enabled) {
    return absl::InvalidArgumentError("voxel grid is disabled (voxel.enabled = false)");
  }
  const Limits limits;
  if (in.size() > limits.max_pixels) {
    return absl::InvalidArgumentError(absl::StrCat("voxel grid input has ", in.size(),
                                                   " points; the limit is ", limits.max_pixels));
  }
  out->points.clear();
  const absl::Status status =
      impl_->accumulator.Run(in.points.data(), in.points.size(), params, &out->points);
  if (!status.ok()) out->points.clear();
  out->width = static_cast<std::uint32_t>(out->points.size());
  out->height = 1;
  return status;
}

}  // namespace cloudcast
