#include "cloudcast/load/schedule.h"

#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <cmath>

#include "absl/status/status.h"

namespace cloudcast::load {

std::string_view Name(ScheduleKind kind) {
  switch (kind) {
    case ScheduleKind::kConst:
      return "const";
    case ScheduleKind::kStep:
      return "step";
    case ScheduleKind::kLine:
      return "line";
  }
  return "const";
}

bool ParseScheduleKind(std::string_view name, ScheduleKind* out) {
  for (ScheduleKind k : {ScheduleKind::kConst, ScheduleKind::kStep, ScheduleKind::kLine}) {
    if (name == Name(k)) {
      *out = k;
      return true;
    }
  }
  return false;
}

absl::StatusOr<Schedule> Schedule::Create(const ScheduleOptions& o) {
  auto bad = [](const std::string& m) { return absl::InvalidArgumentError(m); };
  if (!std::isfinite(o.start) || o.start <= 0) {
    return bad(
        fmt::format("--load-start (the rate, frames/s per stream) must be > 0, got {}", o.start));
  }
  if (o.kind == ScheduleKind::kConst) return Schedule(o);
  if (!std::isfinite(o.step) || o.step == 0) {
    return bad(fmt::format("--load-step must be a non-zero number for --schedule {}, got {}",
                           Name(o.kind), o.step));
  }
  if (!std::isfinite(o.end) || o.end < 0) {
    return bad(fmt::format("--load-end must be >= 0 (0: no end), got {}", o.end));
  }
  if (o.end > 0 && (o.end - o.start) * o.step < 0) {
    return bad(fmt::format("--load-step {} leads away from --load-end {} (start {})", o.step, o.end,
                           o.start));
  }
  if (o.end == 0 && o.step < 0) {
    return bad("--load-end must be set (> 0) when --load-step is negative");
  }
  if (o.kind == ScheduleKind::kStep && o.step_duration < std::chrono::milliseconds(1)) {
    return bad("--load-step-duration must be at least 1 ms");
  }
  return Schedule(o);
}

double Schedule::RateAt(Nanos t) const {
  const ScheduleOptions& o = options_;
  const double seconds = std::max<double>(0, t.count()) / 1e9;
  double rate = o.start;
  switch (o.kind) {
    case ScheduleKind::kConst:
      return o.start;
    case ScheduleKind::kStep:
      rate =
          o.start + o.step * std::floor(t.count() / static_cast<double>(o.step_duration.count()));
      break;
    case ScheduleKind::kLine:
      rate = o.start + o.step * seconds;
      break;
  }
  if (o.end > 0) rate = o.step > 0 ? std::min(rate, o.end) : std::max(rate, o.end);
  // A falling ramp without end stops at a trickle rather than at zero.
  return std::max(rate, 1e-3);
}

Nanos Schedule::Next(Nanos previous) const {
  const double period_ns = 1e9 / RateAt(previous);
  return previous + Nanos(static_cast<std::int64_t>(std::llround(period_ns)));
}

Nanos Schedule::First(double phase) const {
  phase = std::clamp(phase, 0.0, 1.0);
  return Nanos(static_cast<std::int64_t>(phase * 1e9 / RateAt(Nanos(0))));
}

std::string Schedule::Describe() const {
  const ScheduleOptions& o = options_;
  const std::string end = o.end > 0 ? fmt::format(" -> {:g}", o.end) : std::string(" (no end)");
  switch (o.kind) {
    case ScheduleKind::kConst:
      return fmt::format("const {:g} fps per stream", o.start);
    case ScheduleKind::kStep:
      return fmt::format("step {:g}{} fps per stream, {:+g} every {:g} s", o.start, end, o.step,
                         o.step_duration.count() / 1e9);
    case ScheduleKind::kLine:
      return fmt::format("line {:g}{} fps per stream, {:+g} per s", o.start, end, o.step);
  }
  return "";
}

}  // namespace cloudcast::load
