// A cloudcast cloud as a sensor_msgs/PointCloud2.
#pragma once

#include <sensor_msgs/PointCloud2.h>
#include <std_msgs/Header.h>

#include "cloudcast/core/point.h"

namespace cloudcast::ros_bridge {

// `cloud` (unorganized, finite points) as a PointCloud2 with `header`: height 1, dense, little
// endian, the fields of bridge/point_cloud_layout.h (x y z rgb, FLOAT32 at 0 4 8 12, PCL's
// packed rgb).
void ToPointCloud2(const PointCloud& cloud, const std_msgs::Header& header,
                   sensor_msgs::PointCloud2* out);

}  // namespace cloudcast::ros_bridge
