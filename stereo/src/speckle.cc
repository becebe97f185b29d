#include "speckle.h"

#include <cstdlib>

namespace cloudcast::stereo {

std::int32_t SpeckleFilter::Find(std::int32_t r) {
  while (parent_[r] != r) {
    parent_[r] = parent_[parent_[r]];  // path halving
    r = parent_[r];
  }
  return r;
}

void SpeckleFilter::Join(std::int32_t a, std::int32_t b) {
  a = Find(a);
  b = Find(b);
  if (a == b) return;
  if (size_[a] < size_[b]) std::swap(a, b);
  parent_[b] = a;
  size_[a] += size_[b];
}

void SpeckleFilter::Apply(std::uint16_t* values, int width, int height, int max_size,
                          int max_diff) {
  runs_.clear();
  parent_.clear();
  size_.clear();
  run_of_.assign(2 * static_cast<std::size_t>(width), -1);
  for (int y = 0; y < height; ++y) {
    const std::uint16_t* row = values + static_cast<std::size_t>(y) * width;
    const std::uint16_t* above = row - width;
    std::int32_t* mine = run_of_.data() + (y % 2) * width;
    const std::int32_t* theirs = run_of_.data() + ((y + 1) % 2) * width;
    int x = 0;
    while (x < width) {
      if (row[x] == 0) {
        mine[x++] = -1;
        continue;
      }
      // A run: alike horizontal neighbours, all non-zero.
      const std::int32_t id = static_cast<std::int32_t>(runs_.size());
      const int begin = x;
      mine[x] = id;
      for (++x; x < width && row[x] != 0 && std::abs(row[x] - row[x - 1]) <= max_diff; ++x) {
        mine[x] = id;
      }
      runs_.push_back({begin, x, y});
      parent_.push_back(id);
      size_.push_back(x - begin);
      // Joined to the runs above it through alike vertical neighbours (a run above met twice in a
      // row is joined once).
      if (y > 0) {
        std::int32_t last = -1;
        for (int c = begin; c < x; ++c) {
          const std::int32_t up = theirs[c];
          if (up < 0 || up == last || std::abs(row[c] - above[c]) > max_diff) continue;
          Join(id, up);
          last = up;
        }
      }
    }
  }
  for (const Run& r : runs_) {
    const std::int32_t id = static_cast<std::int32_t>(&r - runs_.data());
    if (size_[Find(id)] > max_size) continue;
    std::uint16_t* row = values + static_cast<std::size_t>(r.row) * width;
    for (int c = r.begin; c < r.end; ++c) row[c] = 0;
  }
}

}  // namespace cloudcast::stereo
