// Accuracy of disparity maps against ground truth, the way docs/stereo.md reports it (the
// benchmark and the accuracy tests share it).
#pragma once

#include <cstdint>
#include <vector>

#include "absl/status/status.h"
#include "cloudcast/core/image.h"
#include "cloudcast/stereo/matcher.h"

namespace cloudcast::stereo {

// Accumulates, over frames, the signed error d - truth (in 1/16 px) of every pixel with a known
// truth (8-bit, px, 0 = unknown) and a match (d != 0), and how many such pixels had no match.
class DisparityScore {
 public:
  // `truth` is kU8 and the map's size; `x_from` skips the columns left of it (e.g. to score only
  // where OpenCV's matchers can answer).
  absl::Status Add(const DisparityMap16& map, const DisparityView& truth, std::uint32_t x_from = 0);

  std::uint64_t known() const { return known_; }      // pixels with a truth
  std::uint64_t matched() const { return matched_; }  // ... and a match
  // matched / known.
  double Density() const;
  // Percent of matched pixels with |d - (truth + offset)| > threshold px (bad-1.0: threshold 1).
  double Bad(double threshold, int offset = 0) const;
  // The same, over every known pixel: a pixel without a match counts as bad.
  double BadCountingMisses(double threshold, int offset = 0) const;
  // The median of d - truth over matched pixels, px.
  double MedianError() const;

 private:
  static constexpr int kRange = 4096 * 16;  // errors beyond +-4096 px are clamped
  std::uint64_t Over(double threshold, int offset) const;
  std::vector<std::uint64_t> errors_ = std::vector<std::uint64_t>(2 * kRange + 1, 0);
  std::uint64_t known_ = 0, matched_ = 0;
};

}  // namespace cloudcast::stereo
