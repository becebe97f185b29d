// The sensor_msgs/PointCloud2 both bridges publish: unorganized (height 1), dense, little endian,
// x y z rgb as FLOAT32 at offsets 0 4 8 12 (point_step 16, PCL's packed rgb with alpha 0): the
// layout of cloudcast's Point and of stereo_image_proc's point_cloud2. rgb is 0x00RRGGBB as the
// float's bits (alpha zero, as stereo_image_proc and depth_image_proc write it: never a NaN).
#pragma once

#include <array>
#include <cstdint>

#include "cloudcast/core/point.h"

namespace cloudcast::ros_bridge {

struct PointFieldSpec {
  const char* name;
  std::uint32_t offset;
  std::uint8_t datatype;  // sensor_msgs/PointField's FLOAT32 = 7
  std::uint32_t count;
};
inline constexpr std::uint8_t kPointFieldFloat32 = 7;
inline constexpr std::array<PointFieldSpec, 4> kPointFields = {{{"x", 0, kPointFieldFloat32, 1},
                                                               {"y", 4, kPointFieldFloat32, 1},
                                                               {"z", 8, kPointFieldFloat32, 1},
                                                               {"rgb", 12, kPointFieldFloat32, 1}}};
inline constexpr std::uint32_t kPointStep = 16;

// Writes the cloud's points, cloud.size() * kPointStep bytes, at `out`.
void WritePointData(const PointCloud& cloud, std::uint8_t* out);

}  // namespace cloudcast::ros_bridge
