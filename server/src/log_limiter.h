// A rate limit on log lines that every call writes (a stream opened, done, refused), so that a
// flood of calls cannot flood the log: a rapid reset wrote 26 MB of "stream opened" lines in 20 s.
// Up to `per_second` lines a second go out; the rest are counted, and the first line let through
// after some were left out says how many. Thread-safe.
#pragma once

#include <chrono>
#include <cstdint>
#include <mutex>

namespace cloudcast::server {

class LogLimiter {
 public:
  explicit LogLimiter(std::uint32_t per_second) : per_second_(per_second) {}

  // Whether this line may go out. `suppressed`, when it may, gets the lines left out since the
  // last one that went out (to be said in it), and 0 otherwise.
  bool Allow(std::uint64_t* suppressed) {
    const auto now = std::chrono::steady_clock::now();
    std::lock_guard<std::mutex> lock(mu_);
    if (now - window_start_ >= std::chrono::seconds(1)) {
      window_start_ = now;
      in_window_ = 0;
    }
    if (in_window_ >= per_second_) {
      ++suppressed_;
      ++total_suppressed_;
      *suppressed = 0;
      return false;
    }
    ++in_window_;
    *suppressed = suppressed_;
    suppressed_ = 0;
    return true;
  }

  std::uint64_t total_suppressed() const {
    std::lock_guard<std::mutex> lock(mu_);
    return total_suppressed_;
  }

 private:
  const std::uint32_t per_second_;
  mutable std::mutex mu_;
  std::chrono::steady_clock::time_point window_start_{};
  std::uint32_t in_window_ = 0;
  std::uint64_t suppressed_ = 0;
  std::uint64_t total_suppressed_ = 0;
};

}  // namespace cloudcast::server
