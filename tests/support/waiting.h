// Waiting in tests without sleeping. A test waits on the event it needs (a condition variable, a
// future, a gRPC call returning, a child's exit); these helpers cover what has no event:
//
//   PauseUntil  a simulated client's own pace (a camera's period), never a wait for another
//               thread: it is a timer on the steady clock.
//   Eventually  a state that nothing announces (a server counter, a thread's kernel state),
//               checked about every millisecond until it holds or a generous deadline passes.
//               Every call site says why there is no event to wait on.
//   ThreadIsBlocked  whether a thread sleeps in the kernel: how a test sees that a call really
//               blocks before it acts to unblock it.
#pragma once

#include <sys/syscall.h>
#include <sys/types.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <fstream>
#include <functional>
#include <mutex>
#include <sstream>
#include <string>

namespace cloudcast::testing {

using SteadyClock = std::chrono::steady_clock;

// Blocks the calling thread until `deadline`. Nothing notifies it: only for pacing.
inline void PauseUntil(SteadyClock::time_point deadline) {
  std::mutex mu;
  std::condition_variable never_notified;
  std::unique_lock<std::mutex> lock(mu);
  never_notified.wait_until(lock, deadline, [deadline] { return SteadyClock::now() >= deadline; });
}

inline void PauseFor(SteadyClock::duration period) { PauseUntil(SteadyClock::now() + period); }

// Checks `condition` about every millisecond until it holds (true) or `timeout` passes (false:
// the deadline only turns a hang into a failure, it is no statement about speed).
inline bool Eventually(const std::function<bool()>& condition,
                       std::chrono::milliseconds timeout = std::chrono::seconds(30)) {
  const SteadyClock::time_point deadline = SteadyClock::now() + timeout;
  while (!condition()) {
    if (SteadyClock::now() >= deadline) return false;
    PauseFor(std::chrono::milliseconds(1));
  }
  return true;
}

// The kernel's id of the calling thread, for ThreadIsBlocked.
inline pid_t CurrentThreadId() { return static_cast<pid_t>(::syscall(SYS_gettid)); }

// True when thread `tid` of this process sleeps in the kernel (state S or D in
// /proc/self/task/<tid>/stat): waiting on a condition variable, a lock, a poll or I/O.
inline bool ThreadIsBlocked(pid_t tid) {
  std::ifstream file("/proc/self/task/" + std::to_string(tid) + "/stat");
  std::stringstream ss;
  ss << file.rdbuf();
  const std::string stat = ss.str();
  // "tid (comm) S ...": the state follows the last ')' (comm may hold spaces and parentheses).
  const std::size_t paren = stat.rfind(')');
  if (paren == std::string::npos || paren + 2 >= stat.size()) return false;
  const char state = stat[paren + 2];
  return state == 'S' || state == 'D';
}

}  // namespace cloudcast::testing
