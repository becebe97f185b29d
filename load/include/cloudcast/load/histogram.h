// A log-linear latency histogram in the manner of HdrHistogram: exact below 2^kSubBucketBits,
// then every power of two split into 2^(kSubBucketBits - 1) equal buckets, so a recorded value is
// known to within 1/1024 of itself (three significant digits) over 1 ns .. 2^42 ns (73 minutes).
// Constant memory (270 KB), O(1) recording; percentiles walk the buckets. Debian packages no
// HdrHistogram for C or C++, hence this one.
#pragma once

#include <cstdint>
#include <vector>

namespace cloudcast::load {

class Histogram {
 public:
  static constexpr int kSubBucketBits = 11;
  static constexpr int kMaxValueBits = 42;  // larger values are clamped to the top bucket

  Histogram();

  void Record(std::int64_t value_ns);  // negative values count as 0
  void Add(const Histogram& other);
  void Reset();

  std::uint64_t count() const { return count_; }
  std::int64_t min() const { return count_ ? min_ : 0; }
  std::int64_t max() const { return count_ ? max_ : 0; }
  double mean() const { return count_ ? static_cast<double>(sum_) / count_ : 0; }
  // Sum of every recorded value (exact, not bucketed).
  std::int64_t sum() const { return sum_; }

  // The value at `percentile` (0..100) by nearest rank: the smallest recorded value that at least
  // that share of the values do not exceed, reported as the upper end of its bucket (as
  // HdrHistogram's highestEquivalentValue) and clamped to the exact max. 0 when empty.
  std::int64_t Percentile(double percentile) const;

  // Counts of the values in [lo, hi) for consecutive bounds (bounds.size() - 1 bins), bucketed
  // values placed by their bucket's lower end.
  std::vector<std::uint64_t> CountBetween(const std::vector<std::int64_t>& bounds) const;

  // Bucket arithmetic, public for the tests.
  static int IndexOf(std::int64_t value);
  static std::int64_t LowestOf(int index);
  static std::int64_t HighestOf(int index);
  static int BucketCount();

 private:
  std::vector<std::uint64_t> counts_;
  std::uint64_t count_ = 0;
  std::int64_t min_ = 0, max_ = 0, sum_ = 0;
};

}  // namespace cloudcast::load
