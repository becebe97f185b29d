// Giving memory back to the OS once a burst of frames is over. Frame buffers stay on the heap
// (main.cc raises glibc's mmap and trim thresholds), and glibc keeps freed pages in its arenas:
// without this a server stays at its peak resident size after a burst.
//
// Idle is no call open; but a departed stream's buffers may still be freed after that (its
// connection's transport buffers go with the connection), so while idle it trims again whenever
// the arenas' free bytes have grown by a megabyte since the last trim. Trimming does not shrink
// that figure (the pages stay on the free lists, only unmapped), so an idle server trims once and
// rests. A server idle for a second gives its workers' scratch back first: after a burst of big
// frames (each at most --large-frame-pixels keeps its scratch) it would stay resident.
#pragma once

#include <chrono>
#include <cstddef>
#include <functional>

namespace cloudcast::server {

class MemoryHousekeeping {
 public:
  // `release_scratch` gives the idle workers' scratch back (FrameRunner::ReleaseIdleScratch).
  explicit MemoryHousekeeping(std::function<void()> release_scratch)
      : release_scratch_(std::move(release_scratch)) {}

  // Once per housekeeping tick, `tick` apart; `idle`: no call is open.
  void Tick(bool idle, std::chrono::milliseconds tick);

 private:
  const std::function<void()> release_scratch_;
  bool trimmed_ = true;
  std::size_t free_at_trim_ = 0;
  int idle_ticks_ = 0;
  bool scratch_released_ = true;  // nothing to give back before the first frame
};

}  // namespace cloudcast::server
