// The Draco speed/bits table: what each (speed, position bits) pair costs in bytes and time on
// real clouds, and the position error it actually produces, to choose the service's defaults.
#pragma once

#include <iosfwd>
#include <nlohmann/json.hpp>
#include <vector>

#include "cloudcast/core/point.h"

namespace cloudcast::bench {

// For encode speeds {0, 3, 5, 7, 10} (decode speed = encode speed) and position bits
// {10, 11, 12, 14, 16} (colour 8 bits), encodes and decodes every cloud `iterations` times after
// one warm-up pass, and prints one row per pair to `out`: bytes per point, KB per cloud (median
// over clouds), encode and decode ms (medians over clouds x iterations), the largest measured
// per-coordinate position error and the codec's reported bound (largest over clouds).
// Returns a JSON array of rows {"speed", "position_bits", "bytes_per_point", "kb_per_cloud",
// "encode_ms", "decode_ms", "max_error", "error_bound"}; max_error is null for clouds of more
// than 2^24 points (the exact measurement numbers points through the 24-bit colour).
nlohmann::json RunDracoTable(const std::vector<PointCloud>& clouds, int iterations,
                             std::ostream& out);

}  // namespace cloudcast::bench
