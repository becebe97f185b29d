// The fused pipeline: disparity (or depth) + colour -> passthrough -> voxel grid in one pass over
// the pixels, without materialising the organized or the passthrough cloud. Its output equals the
// three stand-alone stages (and stock PCL's three-stage chain) up to point order. A depth image
// becomes points by ROS depth_image_proc's formula (camera.h), then takes the same filters.
#pragma once

#include <cstdint>
#include <memory>
#include <string_view>

#include "absl/status/status.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/core/filters.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/limits.h"
#include "cloudcast/core/point.h"

namespace cloudcast {

struct PipelineOptions {
  CameraModel camera;  // default: the PCL-compatible preset at 640x480, focal 615
  PassThroughParams passthrough;
  VoxelGridParams voxel;
  Limits limits;

  // Errors name the member: "camera.fx", or "<field>.camera.fx" with a non-empty `field`.
  absl::Status Validate(std::string_view field = "") const;
};

// Points left after each stage.
struct StageCounts {
  std::uint64_t pixels = 0;             // width x height
  std::uint64_t valid_points = 0;       // finite points after conversion
  std::uint64_t after_passthrough = 0;  // == valid_points when the passthrough is off
  std::uint64_t after_voxel = 0;        // == after_passthrough when the voxel grid is off
};

// Reusable scratch for the fused pipeline. Not thread-safe: one per worker thread.
class Pipeline {
 public:
  Pipeline();
  ~Pipeline();
  Pipeline(Pipeline&&) noexcept;
  Pipeline& operator=(Pipeline&&) noexcept;

  // Validates everything, then runs. On error `out` is left empty and nothing else changes.
  absl::Status Run(const PipelineOptions& options, const DisparityView& disparity,
                   const ColorView& colour, PointCloud* out, StageCounts* counts = nullptr);
  absl::Status Run(const PipelineOptions& options, const DepthView& depth, const ColorView& colour,
                   PointCloud* out, StageCounts* counts = nullptr);

  // The last successful Run's voxels again, keeping only those of at least `min_points` points:
  // the cloud that Run gives with voxel.min_points_per_voxel = min_points (PCL's
  // setMinimumPointsNumberPerVoxel), point for point, without reading the pixels again. For a
  // reply that must shrink (the server's downlink cap). FAILED_PRECONDITION unless the last Run
  // succeeded with the voxel grid on; `out` is replaced.
  absl::Status RefilterVoxels(std::uint32_t min_points, PointCloud* out);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace cloudcast
