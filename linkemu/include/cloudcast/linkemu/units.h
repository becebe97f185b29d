// The emulator's quantities as people write them: rates ("10mbit", "3.5Mbit/s"), durations
// ("40ms", "1.5s") and queue bounds ("150kB", "100p"). Each error names the field.
#pragma once

#include <cstdint>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "cloudcast/linkemu/clock.h"

namespace cloudcast::linkemu {

// Bits per second. Units: bit, kbit, mbit, gbit (case-insensitive, an optional "/s" or "ps");
// a bare number is bits per second. 0 is allowed (the link carries nothing).
absl::StatusOr<double> ParseRate(absl::string_view field, absl::string_view text);
// A duration >= 0: ns, us, ms, s (a unit is required).
absl::StatusOr<Nanos> ParseDuration(absl::string_view field, absl::string_view text);

// A drop-tail queue's bound: bytes (B, kB, KB = 1000, KiB = 1024, MB, MiB) or packets ("p").
struct QueueLimit {
  std::int64_t bytes = 0;    // 0 = no byte bound
  std::int64_t packets = 0;  // 0 = no packet bound
};
absl::StatusOr<QueueLimit> ParseQueueLimit(absl::string_view field, absl::string_view text);

}  // namespace cloudcast::linkemu
