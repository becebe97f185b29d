#include "draco_cap.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "draco_sequential_encoder.h"

namespace cloudcast::internal {
namespace {

// Measured on the New Tsukuba clouds at the paper's parameters (speed 10, sequential coding;
// docs/links.md, "Downlink"): bytes a point that colour bits 1..8 add over 1 bit (the mean of
// five frames; frames differ by up to 0.3), and that each position bit adds (0.12 to 0.33).
constexpr std::array<double, 9> kColorPerPoint = {0.0,  0.0,  0.08, 0.22, 0.35,
                                                  0.64, 0.88, 1.15, 1.26};
constexpr double kPerPositionBit = 0.25;
// Bytes a point at 10 position bits and 1 colour bit before any encode: the upper end of the
// frames measured (1.07 to 2.14), so that the first guess usually fits and the second refines.
constexpr double kFirstBase = 2.0;
// The header and the entropy coders' tables: about 100 bytes.
constexpr double kFixedBytes = 100.0;
constexpr int kMaxEncodes = 3;

}  // namespace

std::vector<CapStep> CapLadder(int position_top, int position_floor, int color_top,
                               int color_floor) {
  std::vector<CapStep> ladder;
  for (int p = position_top; p >= position_floor; --p) ladder.push_back({p, color_top});
  for (int c = color_top - 1; c >= color_floor; --c) ladder.push_back({position_floor, c});
  return ladder;
}

CapSizeModel::CapSizeModel(std::size_t points) : points_(points), base_(kFirstBase) {}

double CapSizeModel::PerPoint(const CapStep& step) const {
  return slope_ * (kPerPositionBit * (step.position_bits - 10) +
                   kColorPerPoint[static_cast<std::size_t>(std::clamp(step.color_bits, 1, 8))]);
}

double CapSizeModel::Predict(const CapStep& step) const {
  return kFixedBytes + static_cast<double>(points_) * (base_ + PerPoint(step));
}

void CapSizeModel::Calibrate(const CapStep& step, std::size_t bytes) {
  if (points_ == 0) return;
  const double per_point =
      (static_cast<double>(bytes) - kFixedBytes) / static_cast<double>(points_);
  if (measured_) {
    // Two steps measured: how much a step costs on this cloud, against the table's guess
    // (random colours cost more a bit than a camera's, smooth surfaces less).
    const double modelled = PerPoint(step) - PerPoint(last_step_);
    const double seen = per_point - last_per_point_;
    if (std::fabs(modelled) > 1e-9) slope_ *= std::clamp(seen / modelled, 0.25, 4.0);
  }
  base_ = per_point - PerPoint(step);
  measured_ = true;
  last_step_ = step;
  last_per_point_ = per_point;
}

absl::Status EncodeDracoCapped(const PointCloud& cloud, const DracoOptions& options,
                               std::string* out, DracoEncodeInfo* info) {
  const DracoCloudExtent extent = ScanForDraco(cloud.points.data(), cloud.size());
  if (extent.finite == 0) return EncodeDracoOnce(cloud, options, out, info);

  // The floors: the error bound's bits (or the requested bits when there is no bound), and
  // min_color_bits (or color_bits when it is lower).
  int position_floor = options.position_bits;
  if (options.max_position_error > 0.0f) {
    if (absl::Status s =
            PositionBitsFloor(extent.lo, extent.hi, options.max_position_error, &position_floor);
        !s.ok()) {
      return s;
    }
  }
  const int position_top = std::max(options.position_bits, position_floor);
  const int color_floor = std::min(options.min_color_bits, options.color_bits);
  const std::vector<CapStep> ladder =
      CapLadder(position_top, position_floor, options.color_bits, color_floor);
  const auto last = static_cast<int>(ladder.size()) - 1;
  const auto cap = static_cast<double>(options.max_cloud_bytes);

  CapSizeModel model(extent.finite);
  // The finest step in (after, before) predicted to fit; -1 when none is.
  const auto finest_predicted = [&](int after, int before) {
    for (int i = after + 1; i < before; ++i) {
      if (model.Predict(ladder[static_cast<std::size_t>(i)]) <= cap) return i;
    }
    return -1;
  };

  thread_local std::string trial;
  int fitted = -1;  // the finest step that fitted; its bytes are in *out
  int over = -1;    // the coarsest step that did not
  int encodes = 0;
  DracoEncodeInfo kept;
  int next = finest_predicted(-1, last + 1);
  if (next < 0) next = last;
  while (next >= 0) {
    const CapStep& step = ladder[static_cast<std::size_t>(next)];
    DracoOptions at = options;
    at.position_bits = step.position_bits;
    at.color_bits = step.color_bits;
    at.max_cloud_bytes = 0;
    DracoEncodeInfo got;
    if (absl::Status s = EncodeDracoOnce(cloud, at, &trial, &got); !s.ok()) return s;
    ++encodes;
    model.Calibrate(step, got.bytes);
    if (static_cast<double>(got.bytes) <= cap) {
      fitted = next;
      std::swap(*out, trial);
      kept = got;
    } else {
      over = next;
      // Nothing fitted yet: the coarsest tried so far is what goes out if nothing will.
      if (fitted < 0) {
        std::swap(*out, trial);
        kept = got;
      }
    }
    if (encodes == kMaxEncodes) break;
    if (fitted >= 0) {
      next = finest_predicted(over, fitted);  // something finer that may fit
    } else if (over == last) {
      next = -1;  // the floors are over the cap
    } else if (encodes == kMaxEncodes - 1) {
      next = last;  // the last encode goes to the floors
    } else {
      next = finest_predicted(over, last + 1);
      if (next < 0) next = last;
    }
  }
  *info = kept;
  info->encodes = encodes;
  info->over_cap = fitted < 0;
  return absl::OkStatus();
}

}  // namespace cloudcast::internal
