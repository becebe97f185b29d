// Near-lossless disparity and depth for the uplink: the client bounds how far any point may move.
//
// Disparity and depth travel losslessly by default (a 1 px error at d = 50 is 2% of the depth).
// A client that can accept a known error, for example a quarter of the server's voxel leaf, sets
// `max_point_error`: the largest distance, in the units of the cloud (metres with a baseline in
// metres or REP 118 depth), between the 3D point the server makes from a quantized pixel and the
// one it makes from the original pixel, in the camera's REP 103 optical frame (x right, y down,
// z forward). It is a bound per point, before any filter or voxel grid.
//
// How: the server's point of pixel (u, v) lies on the ray through (u, v), so a value that moves the
// point's z by dz moves the point by |dz| * sqrt(1 + ((u - cx) / fx)^2 + ((v - cy) / fy)^2),
// most at the image's corners. For each valid value the quantizer takes the interval of raw
// values whose point stays within the bound on that longest ray, and replaces the value by the
// "roundest" value of the interval: the one with the most trailing zero bits (for floats: in its
// bit pattern, i.e. the shortest mantissa). The choice depends on the value alone, so equal
// values stay equal and neighbours of similar values take the very same value: the row deltas +
// zstd coder that follows (frame_codec.h) finds longer runs of zeros (and 8- and 16-bit samples
// go through a table). Every replacement is checked against the bound in double precision, with a
// margin for the server's float arithmetic (1% of the bound and 1e-6 of the point's distance); a
// value whose check fails is kept. Invalid pixels (by the server's own test: an invalid disparity
// value, a non-finite value, a depth that is not a positive normal float) are copied bit for bit,
// and a valid pixel never becomes invalid. The server decodes the result as any lossless frame:
// no contract change.
//
// Measured on New Tsukuba (cloudcast-nearlossless-bench, docs/client.md).
#pragma once

#include <cstdint>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/core/image.h"

namespace cloudcast {

// What the last Quantize did.
struct QuantizeStats {
  std::uint64_t valid = 0;    // pixels that give a point
  std::uint64_t changed = 0;  // of those, pixels whose value was replaced
};

// Quantizes views into a buffer it owns and reuses. Not thread-safe: one per sending thread.
class PointErrorQuantizer {
 public:
  // `camera` is the one the server converts with, principal point included (the stream's
  // settings resolved for the frame's size: FrameSettings::PipelineFor). `max_point_error` >= 0,
  // finite; 0 copies the view unchanged. On success `*out` views the quantized pixels (packed
  // rows, same size and encoding), valid until the next call. Errors name `field` (the view,
  // "field.stride_bytes", ...), "camera.fx", ..., or "max_point_error".
  absl::Status Quantize(const DisparityView& in, const CameraModel& camera, double max_point_error,
                        std::string_view field, DisparityView* out);
  absl::Status Quantize(const DepthView& in, const CameraModel& camera, double max_point_error,
                        std::string_view field, DepthView* out);

  const QuantizeStats& stats() const { return stats_; }

 private:
  std::vector<std::uint8_t> buffer_;
  std::vector<std::uint32_t> table_;  // 8- and 16-bit samples: value -> replacement
  QuantizeStats stats_;
};

// The value of [lo, hi] (lo <= hi) with the most trailing zero bits; exposed for tests.
std::uint32_t RoundestInRange(std::uint32_t lo, std::uint32_t hi);

}  // namespace cloudcast
