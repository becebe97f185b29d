// The speckle filter our matcher ends with: what cv::filterSpeckles computes (tests/stereo_test.cc
// compares them on random and real maps), by runs instead of pixels. cv::filterSpeckles floods
// every region pixel by pixel; at 640x480 it cost about 3 ms, an eighth of our matcher with 4
// paths (docs/stereo.md). Here a row splits into runs of neighbours that are alike, runs of
// consecutive rows that touch through alike pixels are joined (union-find), and the runs of small
// regions cleared: well under a millisecond.
#pragma once

#include <cstdint>
#include <vector>

namespace cloudcast::stereo {

class SpeckleFilter {
 public:
  // Sets to 0 every region of at most max_size pixels: a region is a set of non-zero pixels
  // joined through 4-neighbours whose values differ by at most max_diff (cv::filterSpeckles with
  // newVal 0, which also skips 0 as "no value").
  void Apply(std::uint16_t* values, int width, int height, int max_size, int max_diff);

 private:
  struct Run {
    std::int32_t begin, end;  // columns [begin, end)
    std::int32_t row;
  };
  std::int32_t Find(std::int32_t r);
  void Join(std::int32_t a, std::int32_t b);

  std::vector<Run> runs_;
  std::vector<std::int32_t> parent_;
  std::vector<std::int32_t> size_;
  std::vector<std::int32_t> run_of_;  // the run of each pixel of the previous and this row
};

}  // namespace cloudcast::stereo
