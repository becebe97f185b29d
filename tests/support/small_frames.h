// A few frames of the synthetic scene at 160x120: small, so that several server processes on two
// cores keep up, and different (one camera pose each), so that a test sees which frame came back.
#pragma once

#include <cstdint>
#include <mutex>
#include <vector>

#include "cloudcast/datasets/synthetic.h"

namespace cloudcast::testing {

// The first `count` poses, rendered once per count and kept.
// Safe to call from several robots' threads at once.
inline const std::vector<SyntheticFrame>& SmallFrames(int count) {
  static std::mutex mu;
  static std::vector<std::vector<SyntheticFrame>> by_count(16);
  std::lock_guard<std::mutex> lock(mu);
  std::vector<SyntheticFrame>& frames = by_count.at(static_cast<std::size_t>(count));
  if (frames.empty()) {
    for (int i = 0; i < count; ++i) {
      SyntheticOptions o;
      o.width = 160;
      o.height = 120;
      o.frame = static_cast<std::uint64_t>(i);
      frames.push_back(*SyntheticScene::Default().Render(o));
    }
  }
  return frames;
}

}  // namespace cloudcast::testing
