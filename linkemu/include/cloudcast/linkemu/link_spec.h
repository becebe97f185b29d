// A link direction as the command line describes it (text, as typed), merged from the flags for
// both directions and those for one, then checked and built into a LinkDirection.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "cloudcast/linkemu/direction.h"
#include "nlohmann/json.hpp"

namespace cloudcast::linkemu {

struct DirectionSpec {
  std::optional<std::string> rate;      // ParseRate; none: no rate limit
  std::optional<std::string> schedule;  // ParseSchedule, or @FILE
  std::optional<std::string> trace;     // a Mahimahi trace file
  std::vector<std::string> outages;     // "AT:LENGTH", e.g. 5s:300ms
  std::optional<std::string> delay, jitter, loss, burst_loss, queue;

  // `specific`'s fields where it has them, else this one's.
  DirectionSpec OverriddenBy(const DirectionSpec& specific) const;
};

struct BuiltDirection {
  std::unique_ptr<LinkDirection> link;
  nlohmann::json description;  // what was built, in numbers (for the ready line and reports)
};

// `name` ("up", "down") prefixes the flags named in errors (--up-rate ...).
absl::StatusOr<BuiltDirection> BuildDirection(absl::string_view name, const DirectionSpec& spec,
                                              std::uint64_t seed);

// The queue bound used when --queue is not given: 200 ms at the direction's first (or the
// trace's mean) rate, at least 10 full-size packets.
QueueLimit DefaultQueueLimit(double bits_per_second);

nlohmann::json StatsJson(const DirectionStats& stats);

}  // namespace cloudcast::linkemu
