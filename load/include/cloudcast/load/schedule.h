// When each frame of a stream is meant to be sent: the open-loop schedule, fixed before the run.
//
// A stream's frame i has an intended send time that depends only on the schedule, the stream's
// random phase and i, never on when earlier frames actually went or were answered. That is what
// keeps the latency free of coordinated omission (wrk2, HdrHistogram): a sender held up by the
// server cannot slow its own clock down, and the wait counts as latency.
//
// The rate is per stream, in frames per second (a camera's frame rate):
//   const  rate = start
//   step   rate = start + step * floor(t / step_duration), until it reaches end
//   line   rate = start + step * t / 1 s (a slope per second), until it reaches end
// as ghz's --load-schedule, --load-start, --load-step, --load-end and --load-step-duration name
// them (ghz counts the whole load in requests per second; here each stream has the rate).
#pragma once

#include <chrono>
#include <cstdint>
#include <string>
#include <string_view>

#include "absl/status/statusor.h"

namespace cloudcast::load {

using Nanos = std::chrono::nanoseconds;

enum class ScheduleKind { kConst, kStep, kLine };
std::string_view Name(ScheduleKind kind);  // "const", "step", "line"
bool ParseScheduleKind(std::string_view name, ScheduleKind* out);

struct ScheduleOptions {
  ScheduleKind kind = ScheduleKind::kConst;
  double start = 30;  // frames per second per stream
  double step = 0;    // per step (step) or per second (line); may be negative
  double end = 0;     // the rate where a ramp stops changing; 0: no end
  Nanos step_duration = std::chrono::seconds(1);
};

class Schedule {
 public:
  // Errors name the flag: a rate that is not positive, a step duration under 1 ms, a ramp whose
  // step leads away from its end.
  static absl::StatusOr<Schedule> Create(const ScheduleOptions& options);

  // The rate at `t` since the run's start, in frames per second per stream (always > 0).
  double RateAt(Nanos t) const;

  // The intended time of the frame after one intended at `previous` (both since the run's
  // start): one period of the rate in force at `previous` later. Deterministic, so every
  // intended time is fixed before the run.
  Nanos Next(Nanos previous) const;

  // The first frame's intended time for a stream with `phase` in [0, 1): a fraction of the first
  // period, so that streams do not all send at the same instant.
  Nanos First(double phase) const;

  // A short description, e.g. "step 10 -> 60 fps, +10 every 5 s".
  std::string Describe() const;
  const ScheduleOptions& options() const { return options_; }

 private:
  explicit Schedule(const ScheduleOptions& options) : options_(options) {}
  ScheduleOptions options_;
};

}  // namespace cloudcast::load
