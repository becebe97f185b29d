// A cloudcast cloud as a sensor_msgs/PointCloud2.
#pragma once

#include <sensor_msgs/PointCloud2.h>
#include <std_msgs/Header.h>

#include "cloudcast/core/point.h"

namespace cloudcast::ros_bridge {

// `cloud` (unorganized, finite points) as a PointCloud2 with `header`: height 1, dense, little
// endian, fields x y z rgb (FLOAT32 at offsets 0 4 8 12, point_step 16: cloudcast's own point,
// and the layout of stereo_image_proc's point_cloud2). rgb is PCL's packed colour, 0x00RRGGBB as
// the float's bits (the alpha byte zero, as stereo_image_proc and depth_image_proc write it, so
// the field never holds a NaN pattern).
void ToPointCloud2(const PointCloud& cloud, const std_msgs::Header& header,
                   sensor_msgs::PointCloud2* out);

}  // namespace cloudcast::ros_bridge
