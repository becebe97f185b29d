// Open3D 0.16's VoxelDownSample on our clouds, for the voxel-stage comparison. Open3D's headers
// stay in open3d_voxel.cc.
#pragma once

#include <cstddef>
#include <memory>

#include "cloudcast/core/point.h"

namespace cloudcast::bench {

class Open3dVoxel {
 public:
  Open3dVoxel();
  ~Open3dVoxel();
  // Converts `cloud` to an open3d::geometry::PointCloud (positions and colours), untimed.
  void SetInput(const PointCloud& cloud);
  // Runs VoxelDownSample(leaf) on the input; returns the number of points out.
  std::size_t Run(double leaf);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace cloudcast::bench
