// Stereo pairs on a worker: rectified (when the stream sent a calibration), turned grey, matched
// into a disparity map, which the core pipeline then reads like any other (FrameProcessor).
#pragma once

#include <chrono>
#include <cstddef>
#include <list>
#include <memory>
#include <mutex>

#include "absl/status/status.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/settings.h"
#include "cloudcast/core/stereo.h"
#include "cloudcast/io/image_io.h"
#include "cloudcast/stereo/grey.h"
#include "cloudcast/stereo/matcher.h"
#include "cloudcast/stereo/rectifier.h"

namespace cloudcast::server {

// Rectification maps, built once per calibration and shared by every worker: a stream sends its
// calibration once, its frames run on any worker. Holds the few most recently used calibrations
// (building maps costs milliseconds; holding them costs about 12 bytes a pixel). Thread-safe.
class RectifierCache {
 public:
  explicit RectifierCache(std::size_t capacity = 4) : capacity_(capacity) {}

  // The rectifier of `calibration` (checked when the stream's config was resolved).
  absl::StatusOr<std::shared_ptr<const stereo::Rectifier>> Get(
      const StereoCalibration& calibration);

  std::size_t size() const;

 private:
  struct Entry {
    StereoCalibration calibration;
    std::shared_ptr<const stereo::Rectifier> rectifier;
  };
  const std::size_t capacity_;
  mutable std::mutex mu_;
  std::list<Entry> entries_;  // most recently used first
};

// What StereoStage::Match gives the pipeline.
struct MatchedPair {
  DisparityView disparity;  // 1/16 px, 0: no match; valid until the next Match
  ColorView colour;         // the (rectified) left image: the points' colour
  CameraModel camera;       // reads `disparity`: the rectified camera with the matcher's scale
  double rectify_seconds = 0;
  double match_seconds = 0;
};

// Not thread-safe: one per worker (its matcher keeps scratch from frame to frame).
class StereoStage {
 public:
  explicit StereoStage(RectifierCache* rectifiers) : rectifiers_(rectifiers) {}

  // `left` and `right` as the frame brought them (same size, checked); `settings.stereo` says how
  // to match; `camera` is the stream's camera for this frame size (unless a calibration gives
  // the rectified one). Errors name the field: RESOURCE_EXHAUSTED when width x height x
  // num_disparities exceeds `max_volume`.
  absl::Status Match(const ColorView& left, const ColorView& right, const FrameSettings& settings,
                     const CameraModel& camera, std::uint64_t max_volume, MatchedPair* out);

 private:
  RectifierCache* const rectifiers_;
  std::unique_ptr<stereo::Matcher> matcher_;
  StereoParams matcher_params_;
  OwnedColor rectified_left_, rectified_right_;
  stereo::GreyImage grey_left_, grey_right_;
  stereo::DisparityMap16 disparity_;
};

}  // namespace cloudcast::server
