#include "cloudcast/load/histogram.h"

#include <algorithm>
#include <cmath>

namespace cloudcast::load {
namespace {

constexpr std::int64_t kSubBuckets = std::int64_t{1} << Histogram::kSubBucketBits;
constexpr std::int64_t kHalf = kSubBuckets / 2;
constexpr std::int64_t kMaxValue = (std::int64_t{1} << Histogram::kMaxValueBits) - 1;

int Log2(std::uint64_t v) { return 63 - __builtin_clzll(v); }

}  // namespace

int Histogram::BucketCount() {
  return static_cast<int>(kSubBuckets + (kMaxValueBits - kSubBucketBits) * kHalf);
}

int Histogram::IndexOf(std::int64_t value) {
  value = std::clamp<std::int64_t>(value, 0, kMaxValue);
  if (value < kSubBuckets) return static_cast<int>(value);
  // value in [2^e, 2^(e+1)), e >= kSubBucketBits: keep its top kSubBucketBits bits.
  const int shift = Log2(static_cast<std::uint64_t>(value)) - kSubBucketBits + 1;
  const std::int64_t sub = value >> shift;  // in [kHalf, kSubBuckets)
  return static_cast<int>(kSubBuckets + (shift - 1) * kHalf + (sub - kHalf));
}

std::int64_t Histogram::LowestOf(int index) {
  if (index < kSubBuckets) return index;
  const int shift = static_cast<int>((index - kSubBuckets) / kHalf) + 1;
  const std::int64_t sub = kHalf + (index - kSubBuckets) % kHalf;
  return sub << shift;
}

std::int64_t Histogram::HighestOf(int index) {
  if (index < kSubBuckets) return index;
  const int shift = static_cast<int>((index - kSubBuckets) / kHalf) + 1;
  return LowestOf(index) + (std::int64_t{1} << shift) - 1;
}

Histogram::Histogram() : counts_(static_cast<std::size_t>(BucketCount()), 0) {}

void Histogram::Record(std::int64_t value_ns) {
  value_ns = std::clamp<std::int64_t>(value_ns, 0, kMaxValue);
  ++counts_[static_cast<std::size_t>(IndexOf(value_ns))];
  if (count_ == 0) {
    min_ = max_ = value_ns;
  } else {
    min_ = std::min(min_, value_ns);
    max_ = std::max(max_, value_ns);
  }
  ++count_;
  sum_ += value_ns;
}

void Histogram::Add(const Histogram& other) {
  if (other.count_ == 0) return;
  for (std::size_t i = 0; i < counts_.size(); ++i) counts_[i] += other.counts_[i];
  min_ = count_ ? std::min(min_, other.min_) : other.min_;
  max_ = count_ ? std::max(max_, other.max_) : other.max_;
  count_ += other.count_;
  sum_ += other.sum_;
}

void Histogram::Reset() {
  std::fill(counts_.begin(), counts_.end(), 0);
  count_ = 0;
  min_ = max_ = sum_ = 0;
}

std::int64_t Histogram::Percentile(double percentile) const {
  if (count_ == 0) return 0;
  percentile = std::clamp(percentile, 0.0, 100.0);
  // Nearest rank, at least 1; the small epsilon keeps 99.9% of 1000 at rank 999, not 1000.
  std::uint64_t rank = static_cast<std::uint64_t>(std::ceil(percentile / 100.0 * count_ - 1e-9));
  rank = std::clamp<std::uint64_t>(rank, 1, count_);
  std::uint64_t seen = 0;
  for (std::size_t i = 0; i < counts_.size(); ++i) {
    seen += counts_[i];
    if (seen >= rank) {
      return std::clamp(HighestOf(static_cast<int>(i)), min_, max_);
    }
  }
  return max_;
}

std::vector<std::uint64_t> Histogram::CountBetween(const std::vector<std::int64_t>& bounds) const {
  std::vector<std::uint64_t> out(bounds.size() > 1 ? bounds.size() - 1 : 0, 0);
  if (out.empty()) return out;
  for (std::size_t i = 0; i < counts_.size(); ++i) {
    if (counts_[i] == 0) continue;
    const std::int64_t v = LowestOf(static_cast<int>(i));
    auto it = std::upper_bound(bounds.begin(), bounds.end(), v);
    std::size_t bin = it == bounds.begin() ? 0 : static_cast<std::size_t>(it - bounds.begin()) - 1;
    bin = std::min(bin, out.size() - 1);
    out[bin] += counts_[i];
  }
  return out;
}

}  // namespace cloudcast::load
