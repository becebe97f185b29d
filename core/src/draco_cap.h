// The downlink cap (DracoOptions::max_cloud_bytes): choosing the position and colour bits that
// bring a cloud under a byte cap without passing the bounds the client stated. Internal to core:
// EncodeDraco (draco_codec.cc) calls it when a cap is set.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "cloudcast/core/draco_codec.h"
#include "cloudcast/core/point.h"

namespace cloudcast::internal {

// One encode with the options' bits as given (raised for max_position_error, cap ignored).
// `info` must not be null.
absl::Status EncodeDracoOnce(const PointCloud& cloud, const DracoOptions& options, std::string* out,
                             DracoEncodeInfo* info);

// The fewest position bits that keep `max_position_error` (> 0) on a cloud with this bounding
// box; INVALID_ARGUMENT when more than 30 would be needed.
absl::Status PositionBitsFloor(const float lo[3], const float hi[3], float max_position_error,
                               int* bits);

// One candidate of the cap's ladder: the bits to encode at.
struct CapStep {
  int position_bits;
  int color_bits;
};

// The candidates from finest to coarsest: position bits from `position_top` down to
// `position_floor` at `color_top` colour bits, then colour bits down to `color_floor`. Each
// step is smaller than the one before it (a bit fewer of either never grows Draco's sequential
// coding of deltas by more than noise), so the finest step under the cap is the one to send.
std::vector<CapStep> CapLadder(int position_top, int position_floor, int color_top,
                               int color_floor);

// Predicts a cloud's encoded size at a ladder step, from its point count. The model, measured on
// New Tsukuba clouds at speed 10 (docs/links.md, "Downlink"): each position bit costs about 0.25
// bytes a point and colour bits cost the table in draco_cap.cc, added to a per-cloud base. The
// base starts pessimistic and is replaced by what each encode measures (Calibrate), so a second
// guess is within a few percent.
class CapSizeModel {
 public:
  explicit CapSizeModel(std::size_t points);
  double Predict(const CapStep& step) const;
  // An encode at `step` gave `bytes`: fits the base to it, and with a second step measured the
  // cost a step has on this cloud.
  void Calibrate(const CapStep& step, std::size_t bytes);

 private:
  double PerPoint(const CapStep& step) const;  // without the base
  std::size_t points_;
  double base_;         // bytes a point at 10 position bits and 1 colour bit
  double slope_ = 1.0;  // this cloud's cost of a step against the table's
  bool measured_ = false;
  CapStep last_step_{0, 0};
  double last_per_point_ = 0;
};

// EncodeDraco with options.max_cloud_bytes > 0: picks the finest ladder step predicted to fit,
// encodes, calibrates and tries again, at most 3 encodes in all; the last, when nothing fitted
// yet, is the coarsest step (the floors). `info` must not be null.
absl::Status EncodeDracoCapped(const PointCloud& cloud, const DracoOptions& options,
                               std::string* out, DracoEncodeInfo* info);

}  // namespace cloudcast::internal
