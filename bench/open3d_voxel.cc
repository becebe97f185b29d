#include "open3d_voxel.h"

#include <open3d/geometry/PointCloud.h>

namespace cloudcast::bench {

struct Open3dVoxel::Impl {
  open3d::geometry::PointCloud input;
};

Open3dVoxel::Open3dVoxel() : impl_(std::make_unique<Impl>()) {}
Open3dVoxel::~Open3dVoxel() = default;

void Open3dVoxel::SetInput(const PointCloud& cloud) {
  impl_->input.points_.clear();
  impl_->input.colors_.clear();
  impl_->input.points_.reserve(cloud.size());
  impl_->input.colors_.reserve(cloud.size());
  for (const Point& p : cloud.points) {
    impl_->input.points_.emplace_back(p.x, p.y, p.z);
    impl_->input.colors_.emplace_back(RedOf(p.rgba) / 255.0, GreenOf(p.rgba) / 255.0,
                                      BlueOf(p.rgba) / 255.0);
  }
}

std::size_t Open3dVoxel::Run(double leaf) {
  return impl_->input.VoxelDownSample(leaf)->points_.size();
}

}  // namespace cloudcast::bench
