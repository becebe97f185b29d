// Stock PCL 1.13, the reference cloudcast must reproduce: thin wrappers that run PCL's own
// OrganizedConversion, PassThrough and VoxelGrid on our inputs. Tests and benchmarks only.
#pragma once

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <cstdint>
#include <memory>
#include <vector>

#include "cloudcast/core/filters.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/point.h"

namespace cloudcast::reference {

using PclCloud = pcl::PointCloud<pcl::PointXYZRGBA>;

// A frame in the form PCL's OrganizedConversion takes: 16-bit disparities and RGB (or mono)
// bytes, tightly packed.
struct PclFrame {
  std::vector<std::uint16_t> disparity;
  std::vector<std::uint8_t> colour;
  bool mono = false;
  std::size_t width = 0;
  std::size_t height = 0;
};
// From our views (8 or 16-bit disparity; BGR8, RGB8, RGBA8 or mono8 colour).
PclFrame MakePclFrame(const DisparityView& disparity, const ColorView& colour);

// pcl::io::OrganizedConversion<PointXYZRGBA>::convert(disparity, rgb, mono, w, h, focal,
// disparity_offset, disparity_scale, cloud).
void PclConvert(PclFrame& frame, float focal, float disparity_offset, float disparity_scale,
                PclCloud& out);
// The float-depth overload of the same (depth per pixel instead of disparity).
void PclConvertDepth(std::vector<float>& depth, PclFrame& frame, float focal, PclCloud& out);

// pcl::PassThrough<PointXYZRGBA> with our parameters.
void PclPassThrough(const PclCloud::ConstPtr& in, const PassThroughParams& params, PclCloud& out);
// pcl::VoxelGrid<PointXYZRGBA> (downsample all data) with our parameters.
void PclVoxelGrid(const PclCloud::ConstPtr& in, const VoxelGridParams& params, PclCloud& out);

// The same three stages with their filter objects kept from call to call (PCL's best case: no
// per-call allocation of the filters' index vectors).
class PclStages {
 public:
  PclStages();
  ~PclStages();
  void PassThrough(const PclCloud::ConstPtr& in, const PassThroughParams& params, PclCloud& out);
  void VoxelGrid(const PclCloud::ConstPtr& in, const VoxelGridParams& params, PclCloud& out);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

PclCloud::Ptr ToPcl(const PointCloud& cloud);
PointCloud FromPcl(const PclCloud& cloud);

}  // namespace cloudcast::reference
