// Stage parameters and the stand-alone stages: organized conversion, passthrough, voxel grid.
// Each reproduces stock PCL 1.13 (see tests/pcl_equivalence_test.cc); the fused pipeline in
// pipeline.h gives the same result without materialising the intermediate clouds.
#pragma once

#include <cstdint>
#include <memory>
#include <string_view>

#include "absl/status/status.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/limits.h"
#include "cloudcast/core/point.h"

namespace cloudcast {

enum class Axis : std::uint8_t { kX = 0, kY = 1, kZ = 2 };
std::string_view Name(Axis axis);
bool ParseAxis(std::string_view name, Axis* out);  // "x", "y" or "z"

// pcl::PassThrough on one coordinate. Non-finite points are always removed. Limits are
// inclusive: a point is kept when min <= value <= max, or, with `negative`, when it is outside.
struct PassThroughParams {
  bool enabled = true;  // false: only remove the non-finite points
  Axis axis = Axis::kZ;
  float min = 3.0f;  // the paper's depth range
  float max = 12.0f;
  bool negative = false;

  // Finite limits, min <= max; errors name the member under `field`.
  absl::Status Validate(std::string_view field = "passthrough") const;
};

// pcl::VoxelGrid with downsample-all-data: one point per occupied voxel at the centroid of its
// points, colour the truncated mean of theirs. Voxel i along x holds floor(x * (1 / leaf_x)) == i,
// computed in float as PCL does. Voxel keys are 64 bits wide, so a fine leaf over a large extent
// is filtered correctly where PCL's 32-bit indices give up and return the input unfiltered.
struct VoxelGridParams {
  bool enabled = true;
  float leaf_x = 0.03f;  // the paper's 3 cm leaf
  float leaf_y = 0.03f;
  float leaf_z = 0.03f;
  // Voxels with fewer points produce nothing (PCL's setMinimumPointsNumberPerVoxel; 0 and 1 keep
  // every occupied voxel).
  std::uint32_t min_points_per_voxel = 0;
  // Emit the voxels in PCL's order (by voxel index: z, then y, then x, as pcl::VoxelGrid's sort
  // leaves them) instead of the order in which they were first met. Draco's sequential coder
  // (speed 10) predicts each point from the previous one, so the order changes the bytes: on the
  // ten New Tsukuba frames key order takes 14% fewer bytes at the codec's defaults (4% to 33% per
  // frame), for a sort of about 90 instructions a voxel (cloudcast-chain-bench --key-order).
  bool key_order = false;

  void SetLeaf(float leaf) { leaf_x = leaf_y = leaf_z = leaf; }
  // Finite positive leaves when enabled; errors name the member under `field`.
  absl::Status Validate(std::string_view field = "voxel") const;
};

// Disparity + colour -> organized cloud (width x height points, NaN where invalid), as
// pcl::io::OrganizedConversion<PointXYZRGBA>::convert does for even sizes with the PCL preset.
absl::Status ConvertToOrganized(const CameraModel& camera, const DisparityView& disparity,
                                const ColorView& colour, PointCloud* out,
                                const Limits& limits = Limits{});
// Depth + colour -> organized cloud, as ROS depth_image_proc's point_cloud_xyzrgb computes it
// (camera.h), with NaN points where there is no measurement.
absl::Status ConvertToOrganized(const CameraModel& camera, const DepthView& depth,
                                const ColorView& colour, PointCloud* out,
                                const Limits& limits = Limits{});

// Keeps the points of `in` that pass; `out` becomes an unorganized cloud in input order.
// `out` must not alias `in`.
absl::Status PassThrough(const PointCloud& in, const PassThroughParams& params, PointCloud* out);

// Voxel-grid downsampling with reusable scratch memory. Not thread-safe: one per thread.
class VoxelGrid {
 public:
  VoxelGrid();
  ~VoxelGrid();
  VoxelGrid(VoxelGrid&&) noexcept;
  VoxelGrid& operator=(VoxelGrid&&) noexcept;

  // Non-finite points of `in` are skipped. `out` gets one point per voxel, unorganized, in the
  // order the voxels were first met (or PCL's order: params.key_order). `out` must not alias
  // `in`.
  absl::Status Filter(const PointCloud& in, const VoxelGridParams& params, PointCloud* out);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace cloudcast
