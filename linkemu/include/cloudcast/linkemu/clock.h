// Time in the link model: nanoseconds on one monotonic clock, passed in by the caller. The model
// never reads a clock itself, so tests drive it with made-up times (an injected clock) and the
// packet path drives it with CLOCK_MONOTONIC.
#pragma once

#include <cstdint>
#include <limits>

namespace cloudcast::linkemu {

using Nanos = std::int64_t;

inline constexpr Nanos kMillisecond = 1'000'000;
inline constexpr Nanos kSecond = 1'000'000'000;
// "Never": a link whose rate stays 0 from some time on delivers nothing after it.
inline constexpr Nanos kNever = std::numeric_limits<Nanos>::max();

}  // namespace cloudcast::linkemu
