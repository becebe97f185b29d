// A rate limit on log lines that every call writes (a stream opened, done, refused), so that a
// flood of calls cannot flood the log: a rapid reset wrote 26 MB of "stream opened" lines in 20 s.
// Up to `per_second` lines a second go out; the rest are counted, and the first line let through
// after some were left out says how many. Thread-safe.
//
// The time comes from a clock the limiter is handed, the steady clock unless told otherwise: a
// test hands it a fake one and moves it past the second instead of sleeping through it.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <mutex>
#include <utility>

namespace cloudcast::server {

class LogLimiter {
 public:
  using Clock = std::chrono::steady_clock;
  // Returns the current time; called once per Allow, outside the limiter's lock, so it must be
  // safe to call from any thread.
  using Now = std::function<Clock::time_point()>;

  explicit LogLimiter(std::uint32_t per_second, Now now = &Clock::now)
      : per_second_(per_second), now_(std::move(now)) {}

  // Whether this line may go out. `suppressed`, when it may, gets the lines left out since the
  // last one that went out (to be said in it), and 0 otherwise.
  bool Allow(std::uint64_t* suppressed) {
    const Clock::time_point now = now_();
    std::lock_guard<std::mutex> lock(mu_);
    // The first line opens the first window; a window lasts one second from its first line.
    if (!window_open_ || now - window_start_ >= std::chrono::seconds(1)) {
      window_open_ = true;
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
  const Now now_;
  mutable std::mutex mu_;
  bool window_open_ = false;
  Clock::time_point window_start_{};
  std::uint32_t in_window_ = 0;
  std::uint64_t suppressed_ = 0;
  std::uint64_t total_suppressed_ = 0;
};

}  // namespace cloudcast::server
