// A process's memory figures from /proc/<pid>/status (VmRSS, VmPeak, VmHWM, ...), in bytes: the
// tests that bound a server's or a matcher's memory read them here.
#pragma once

#include <sys/types.h>
#include <unistd.h>

#include <cstdint>
#include <fstream>
#include <string>

namespace cloudcast::testing {

// `key` with its colon, e.g. "VmRSS:"; 0 when the process or the key is not there.
inline std::uint64_t ProcStatusBytes(const std::string& key, pid_t pid = getpid()) {
  std::ifstream status("/proc/" + std::to_string(pid) + "/status");
  std::string k;
  while (status >> k) {
    if (k == key) {
      std::uint64_t kb = 0;
      status >> kb;
      return kb * 1024;
    }
    status.ignore(1 << 20, '\n');
  }
  return 0;
}

// The resident memory of a process.
inline std::uint64_t ResidentBytes(pid_t pid) { return ProcStatusBytes("VmRSS:", pid); }

}  // namespace cloudcast::testing
