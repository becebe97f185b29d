#include "memory_housekeeping.h"

#include <malloc.h>

namespace cloudcast::server {

void MemoryHousekeeping::Tick(bool idle, std::chrono::milliseconds tick) {
  if (idle && ++idle_ticks_ * tick >= std::chrono::seconds(1) && !scratch_released_) {
    release_scratch_();
    scratch_released_ = true;
    trimmed_ = false;
  }
  if (!idle) {
    idle_ticks_ = 0;
    scratch_released_ = false;
  }
  if (idle) {
    const std::size_t free_bytes = mallinfo2().fordblks;
    if (!trimmed_ || free_bytes > free_at_trim_ + (std::size_t{1} << 20)) {
      malloc_trim(0);
      free_at_trim_ = free_bytes;
    }
  }
  trimmed_ = idle;
}

}  // namespace cloudcast::server
