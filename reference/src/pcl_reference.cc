#include "cloudcast/reference/pcl_reference.h"

#include <pcl/compression/organized_pointcloud_conversion.h>
#include <pcl/filters/passthrough.h>
#include <pcl/filters/voxel_grid.h>

#include <cstring>

namespace cloudcast::reference {

PclFrame MakePclFrame(const DisparityView& disparity, const ColorView& colour) {
  PclFrame f;
  f.width = disparity.width;
  f.height = disparity.height;
  f.disparity.resize(f.width * f.height);
  f.mono = colour.encoding == ColorEncoding::kMono8;
  f.colour.resize(f.width * f.height * (f.mono ? 1 : 3));
  for (std::size_t v = 0; v < f.height; ++v) {
    const std::uint8_t* drow = disparity.row(static_cast<std::uint32_t>(v));
    const std::uint8_t* crow = colour.row(static_cast<std::uint32_t>(v));
    for (std::size_t u = 0; u < f.width; ++u) {
      const std::size_t i = v * f.width + u;
      if (disparity.encoding == DisparityEncoding::kU8) {
        f.disparity[i] = drow[u];
      } else {
        std::memcpy(&f.disparity[i], drow + 2 * u, 2);
      }
      switch (colour.encoding) {
        case ColorEncoding::kBGR8:
          f.colour[3 * i + 0] = crow[3 * u + 2];
          f.colour[3 * i + 1] = crow[3 * u + 1];
          f.colour[3 * i + 2] = crow[3 * u + 0];
          break;
        case ColorEncoding::kRGB8:
          std::memcpy(&f.colour[3 * i], crow + 3 * u, 3);
          break;
        case ColorEncoding::kRGBA8:
          std::memcpy(&f.colour[3 * i], crow + 4 * u, 3);
          break;
        case ColorEncoding::kMono8:
          f.colour[i] = crow[u];
          break;
      }
    }
  }
  return f;
}

void PclConvert(PclFrame& frame, float focal, float disparity_offset, float disparity_scale,
                PclCloud& out) {
  pcl::io::OrganizedConversion<pcl::PointXYZRGBA>::convert(
      frame.disparity, frame.colour, frame.mono, frame.width, frame.height, focal, disparity_offset,
      disparity_scale, out);
}

void PclConvertDepth(std::vector<float>& depth, PclFrame& frame, float focal, PclCloud& out) {
  pcl::io::OrganizedConversion<pcl::PointXYZRGBA>::convert(depth, frame.colour, frame.mono,
                                                           frame.width, frame.height, focal, out);
}

void PclPassThrough(const PclCloud::ConstPtr& in, const PassThroughParams& params, PclCloud& out) {
  pcl::PassThrough<pcl::PointXYZRGBA> pass;
  pass.setInputCloud(in);
  if (params.enabled) {
    pass.setFilterFieldName(std::string(Name(params.axis)));
    pass.setFilterLimits(params.min, params.max);
    pass.setNegative(params.negative);
  }
  pass.filter(out);
}

void PclVoxelGrid(const PclCloud::ConstPtr& in, const VoxelGridParams& params, PclCloud& out) {
  pcl::VoxelGrid<pcl::PointXYZRGBA> grid;
  grid.setInputCloud(in);
  grid.setLeafSize(params.leaf_x, params.leaf_y, params.leaf_z);
  grid.setDownsampleAllData(true);
  grid.setMinimumPointsNumberPerVoxel(params.min_points_per_voxel);
  grid.filter(out);
}

struct PclStages::Impl {
  pcl::PassThrough<pcl::PointXYZRGBA> pass;
  pcl::VoxelGrid<pcl::PointXYZRGBA> grid;
};
PclStages::PclStages() : impl_(std::make_unique<Impl>()) {}
PclStages::~PclStages() = default;

void PclStages::PassThrough(const PclCloud::ConstPtr& in, const PassThroughParams& params,
                            PclCloud& out) {
  impl_->pass.setInputCloud(in);
  impl_->pass.setFilterFieldName(params.enabled ? std::string(Name(params.axis)) : "");
  impl_->pass.setFilterLimits(params.min, params.max);
  impl_->pass.setNegative(params.negative);
  impl_->pass.filter(out);
}

void PclStages::VoxelGrid(const PclCloud::ConstPtr& in, const VoxelGridParams& params,
                          PclCloud& out) {
  impl_->grid.setInputCloud(in);
  impl_->grid.setLeafSize(params.leaf_x, params.leaf_y, params.leaf_z);
  impl_->grid.setDownsampleAllData(true);
  impl_->grid.setMinimumPointsNumberPerVoxel(params.min_points_per_voxel);
  impl_->grid.filter(out);
}

PclCloud::Ptr ToPcl(const PointCloud& cloud) {
  auto out = std::make_shared<PclCloud>();
  out->resize(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const Point& p = cloud.points[i];
    auto& q = (*out)[i];
    q.x = p.x;
    q.y = p.y;
    q.z = p.z;
    q.rgba = p.rgba;
  }
  out->width = cloud.width;
  out->height = cloud.height;
  out->is_dense = false;
  return out;
}

PointCloud FromPcl(const PclCloud& cloud) {
  PointCloud out;
  out.points.resize(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const auto& q = cloud[i];
    out.points[i] = Point{q.x, q.y, q.z, q.rgba};
  }
  out.width = cloud.width;
  out.height = cloud.height;
  return out;
}

}  // namespace cloudcast::reference
