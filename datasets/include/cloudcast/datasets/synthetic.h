// A synthetic stereo scene with exactly known geometry: textured planes, boxes and spheres,
// seen by a camera that moves with the frame index. It renders exact disparity and colour at any
// resolution, is the default input on a fresh machine, and lets tests check converted points
// against the true surfaces.
#pragma once

#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/core/image.h"

namespace cloudcast {

struct SyntheticOptions {
  std::uint32_t width = 640;
  std::uint32_t height = 480;
  std::uint64_t frame = 0;  // the camera pose follows the frame index
  // kF32: exact disparities. kU16: fixed point with scale 1/16 (as stereo matchers output).
  // kU8: rounded to whole pixels, 0 (invalid) where the disparity exceeds 255.
  DisparityEncoding disparity_encoding = DisparityEncoding::kF32;
  // Render from a camera moved this far along its own x axis (the scene's unit): with a stereo
  // baseline, the right camera of a pair rectified by construction, whose colour is the right
  // image (and whose disparity is the right view's, for the frame's camera baseline of 1).
  double eye_x = 0;
};

// The baseline of the synthetic stereo pairs (eye_x of their right image): half the frames'
// camera baseline, so that at 640 px their disparities (at most 116 px, on the nearest floor)
// fit the matchers' default 128 disparities. The stream's camera needs this baseline for the
// points to land on the scene.
inline constexpr double kSyntheticStereoBaseline = 0.5;

struct SyntheticFrame;

// The truth of a synthetic stereo pair, as the stereo benchmarks and tests score it: for a left
// image rendered with exact (kF32) disparities at eye_x 0 and its right image
// kSyntheticStereoBaseline away, the left view's disparity in whole pixels (kU8 rows, tightly
// packed; 0 where unknown or over 255). Errors: a frame not rendered kF32.
absl::StatusOr<std::vector<std::uint8_t>> SyntheticStereoTruth(const SyntheticFrame& left);

// One rendered frame. It owns its pixels; the views point into them.
struct SyntheticFrame {
  // PCL-compatible preset with the focal scaled to the width (615 at 640 px): fx = fy =
  // 615 * width / 640, principal point (width/2, height/2), baseline 1, and for kU16 a
  // disparity scale of 1/16. Depths are in the same units as the paper's passthrough (3..12).
  CameraModel camera;
  std::vector<std::uint8_t> disparity;  // rows, tightly packed, in the requested encoding
  std::vector<std::uint8_t> colour;     // BGR8 rows, tightly packed
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  DisparityEncoding disparity_encoding = DisparityEncoding::kF32;

  DisparityView disparity_view() const;
  ColorView colour_view() const;
};

class SyntheticScene {
 public:
  // The default scene: a floor, a back wall beyond the paper's depth range, boxes and spheres.
  static SyntheticScene Default();

  // Errors: zero or over-limit sizes.
  absl::StatusOr<SyntheticFrame> Render(const SyntheticOptions& options) const;

  // Distance from `p`, given in the camera frame of frame `frame` (x right, y down, z forward),
  // to the nearest surface of the scene. Points converted from an exact render lie on surfaces.
  double DistanceToSurface(std::uint64_t frame, double x, double y, double z) const;

 private:
  struct Shape;
  std::vector<Shape> shapes_;
  SyntheticScene();

 public:
  ~SyntheticScene();
  SyntheticScene(const SyntheticScene&);
  SyntheticScene& operator=(const SyntheticScene&);
};

}  // namespace cloudcast
