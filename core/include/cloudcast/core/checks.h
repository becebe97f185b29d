// Field checks: each kind of check words its message once, here, and names the field the caller
// passes. The core's own Validate() methods use them with core names ("camera.fx"); the proto
// boundary (proto/convert) uses them with proto paths ("config.camera.fx") as it reads each
// field, so a client hears about the field it set.
//
// Status codes, one per condition everywhere (see the table in cloudcast.proto):
//   INVALID_ARGUMENT    a value is malformed or out of its range;
//   RESOURCE_EXHAUSTED  a well-formed value is over one of this server's limits (Limits).
#pragma once

#include <cstdint>
#include <string_view>

#include "absl/status/status.h"
#include "cloudcast/core/limits.h"

namespace cloudcast::check {

// The smallest magnitude Positive and NonZero accept: the pipeline computes in float, where a
// value finite in double (1e-300, 5e-324) is 0 or denormal and every point vanishes. 1e-9 keeps
// the products of two such values (fx * baseline) normal floats too.
inline constexpr double kMinMagnitude = 1e-9;
// Finite and in [1e-9, 1e9] (0 and negatives named as such): focal lengths, baselines.
absl::Status Positive(std::string_view field, double value);
// Finite and within +-1e9: principal points, scales, offsets.
absl::Status Finite(std::string_view field, double value);
// Finite (any float): passthrough limits.
absl::Status FiniteFloat(std::string_view field, float value);
// Finite and non-zero, its magnitude in [1e-9, 1e9]: a disparity scale.
absl::Status NonZero(std::string_view field, double value);
// A voxel leaf: finite, > 0, and 1 / leaf a finite float (the grid multiplies by it, as PCL does).
absl::Status Leaf(std::string_view field, float value);
// An integer in [lo, hi].
absl::Status InRange(std::string_view field, std::int64_t value, std::int64_t lo, std::int64_t hi);
// min <= max, naming both fields; a note (e.g. "the server default") is added beside a value.
absl::Status Ordered(std::string_view min_field, double min, std::string_view max_field, double max,
                     std::string_view min_note = "", std::string_view max_note = "");
// At most `limit` entries in a repeated field.
absl::Status AtMost(std::string_view field, std::size_t count, std::size_t limit);
// An image's size: at least 1x1 (INVALID_ARGUMENT, naming `field`.width or `field`.height), and
// within `limits` (RESOURCE_EXHAUSTED, naming the limit).
absl::Status ImageSize(std::string_view field, std::uint32_t width, std::uint32_t height,
                       const Limits& limits);

}  // namespace cloudcast::check
