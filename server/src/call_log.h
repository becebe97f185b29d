// The log lines every call writes (a stream opened, done, refused), within
// --log-calls-per-second (LogLimiter): the lines left out are counted in a metric, and the first
// line let through after some were says how many.
#pragma once

#include <cstdint>
#include <utility>

#include "log_limiter.h"
#include "prometheus/counter.h"
#include "spdlog/spdlog.h"

namespace cloudcast::server {

class CallLog {
 public:
  // `suppressed` counts the lines left out; it must outlive the log.
  CallLog(std::uint32_t per_second, prometheus::Counter* suppressed)
      : limiter_(per_second), per_second_(per_second), suppressed_(suppressed) {}

  template <typename... Args>
  void Log(spdlog::level::level_enum level, spdlog::format_string_t<Args...> format,
           Args&&... args) {
    if (!spdlog::should_log(level)) return;
    std::uint64_t left_out = 0;
    if (!limiter_.Allow(&left_out)) {
      suppressed_->Increment();
      return;
    }
    if (left_out > 0) {
      spdlog::log(level, "({} per-call log lines left out: over --log-calls-per-second {})",
                  left_out, per_second_);
    }
    spdlog::log(level, format, std::forward<Args>(args)...);
  }

 private:
  LogLimiter limiter_;
  const std::uint32_t per_second_;
  prometheus::Counter* const suppressed_;
};

}  // namespace cloudcast::server
