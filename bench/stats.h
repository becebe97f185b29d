// Order statistics for the benchmark tables: PERFORMANCE.md asks for medians, since these shared
// cores make means and single runs drift.
#pragma once

#include <algorithm>
#include <vector>

namespace cloudcast::bench {

// The median; the mean of the middle two for an even count, 0 for none.
inline double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  const std::size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + mid, v.end());
  if (v.size() % 2 == 1) return v[mid];
  return 0.5 * (v[mid] + *std::max_element(v.begin(), v.begin() + mid));
}

}  // namespace cloudcast::bench
