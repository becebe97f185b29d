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
// per-coordinate position error and the codec's reported bound (largest over clouds). At speed
// 10, where EncodeDraco runs cloudcast's own encoder, libdraco encodes the same clouds in the
// same passes (interleaved, force_libdraco): its median is printed beside ours, with the
// speed-up per frame (libdraco's time summed over the clouds, each cloud's median, over ours),
// and a row is flagged if the two ever wrote different bytes. Then the first cloud alone, at
// the service's settings (speed 10, 10 bits, max error 0.0075), ours against libdraco.
// Returns a JSON array of rows {"speed", "position_bits", "bytes_per_point", "kb_per_cloud",
// "encode_ms", "libdraco_encode_ms", "encode_speedup", "bytes_identical", "decode_ms",
// "max_error", "error_bound"}, then one {"first_cloud": {"points", "bytes", "runs",
// "encode_ms", "libdraco_encode_ms", "encode_speedup", "encode_speedup_median_of_pairs",
// "encode_min_ms", "libdraco_encode_min_ms", "bytes_identical", "cloudcast_encoder_ran"}}.
// max_error is null for clouds of more than 2^24 points (the exact measurement numbers points
// through the 24-bit colour); libdraco_encode_ms and encode_speedup are null below speed 10.
nlohmann::json RunDracoTable(const std::vector<PointCloud>& clouds, int iterations,
                             std::ostream& out);

}  // namespace cloudcast::bench
