// The calling thread's CPU time: what an encoder costs the core it runs on, apart from whatever
// else the machine runs (the load generator's streams share its cores with each other).
#pragma once

#include <time.h>

namespace cloudcast::load {

inline double ThreadCpuMs() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) / 1e6;
}

}  // namespace cloudcast::load
