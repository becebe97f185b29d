// What one direction of the link can carry over time: a rate that changes on a schedule (steps,
// outages), or a Mahimahi packet-delivery trace. Both serve packets first in, first out, without
// preemption, so a packet's finish time is known when it arrives (the queue needs no timer).
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "cloudcast/linkemu/clock.h"

namespace cloudcast::linkemu {

class Capacity {
 public:
  virtual ~Capacity() = default;
  // A packet of `bytes` whose transmission may start at `start` (the link is free from then on,
  // and start is never before the previous call's start): the time its last byte has left, or
  // kNever when the link carries nothing from some time on.
  virtual Nanos Finish(Nanos start, std::int64_t bytes) = 0;
};

// A rate that holds from `at` (since the emulator started) until the next step.
struct RateStep {
  Nanos at = 0;
  double bits_per_second = 0;  // 0: an outage (packets wait in the queue)
};

// Piecewise-constant rate. The last step holds for ever.
class RateSchedule : public Capacity {
 public:
  // `steps` sorted by time, the first at 0 (Make checks it).
  static absl::StatusOr<std::unique_ptr<RateSchedule>> Make(std::vector<RateStep> steps);
  Nanos Finish(Nanos start, std::int64_t bytes) override;
  const std::vector<RateStep>& steps() const { return steps_; }

 private:
  explicit RateSchedule(std::vector<RateStep> steps) : steps_(std::move(steps)) {}
  std::vector<RateStep> steps_;
  std::size_t segment_ = 0;  // where the last call ended: calls move forward in time
};

// Parses a schedule: entries "TIME=RATE" separated by commas, semicolons or new lines, RATE a rate
// (ParseRate) or "down" (0); '#' starts a comment. `base` is the rate before the first entry.
// Times must increase. Errors name `field` and the entry.
absl::StatusOr<std::vector<RateStep>> ParseSchedule(absl::string_view field, absl::string_view text,
                                                    double base);
// Puts an outage (rate 0) over [at, at + length) and the rate in force at its end back after it.
std::vector<RateStep> WithOutage(const std::vector<RateStep>& steps, Nanos at, Nanos length);

// Mahimahi's trace format: one integer per line, a time in milliseconds at which the link may
// deliver one 1504-byte "packet's worth" (a delivery opportunity); several lines with the same time
// give that many opportunities. The trace repeats, its period being its last time. A packet uses
// as many opportunities as its size needs; what is left of the last one serves the next packet
// only when that packet was already waiting (as mm-link does: an opportunity meeting an empty
// queue is lost).
class DeliveryTrace : public Capacity {
 public:
  static constexpr std::int64_t kBytesPerOpportunity = 1504;
  static absl::StatusOr<std::unique_ptr<DeliveryTrace>> Parse(absl::string_view field,
                                                              absl::string_view text);
  Nanos Finish(Nanos start, std::int64_t bytes) override;
  Nanos period() const { return period_; }
  std::size_t opportunities() const { return times_.size(); }
  // The trace's mean rate, bits per second.
  double MeanRate() const;

 private:
  DeliveryTrace(std::vector<Nanos> times, Nanos period)
      : times_(std::move(times)), period_(period) {}
  Nanos TimeOf(std::int64_t index) const;
  std::int64_t FirstAtOrAfter(Nanos t) const;

  std::vector<Nanos> times_;  // within one period, non-decreasing
  Nanos period_;
  std::int64_t last_ = -1;     // the last opportunity used (an index over all repeats)
  std::int64_t leftover_ = 0;  // bytes of it not used
};

}  // namespace cloudcast::linkemu
