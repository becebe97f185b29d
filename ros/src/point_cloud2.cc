#include "point_cloud2.h"

#include <sensor_msgs/PointField.h>

#include <cstring>

namespace cloudcast::ros_bridge {

void ToPointCloud2(const PointCloud& cloud, const std_msgs::Header& header,
                   sensor_msgs::PointCloud2* out) {
  out->header = header;
  out->height = 1;
  out->width = static_cast<std::uint32_t>(cloud.size());
  out->is_bigendian = false;
  out->is_dense = true;  // the server's clouds hold finite points only
  out->fields.resize(4);
  const char* names[] = {"x", "y", "z", "rgb"};
  for (int i = 0; i < 4; ++i) {
    out->fields[i].name = names[i];
    out->fields[i].offset = static_cast<std::uint32_t>(4 * i);
    out->fields[i].datatype = sensor_msgs::PointField::FLOAT32;
    out->fields[i].count = 1;
  }
  static_assert(sizeof(Point) == 16, "the PointCloud2 layout is cloudcast's point");
  out->point_step = sizeof(Point);
  out->row_step = out->point_step * out->width;
  out->data.resize(cloud.size() * sizeof(Point));
  std::uint8_t* dst = out->data.data();
  for (const Point& p : cloud.points) {
    Point q = p;
    q.rgba &= 0x00FFFFFFu;
    std::memcpy(dst, &q, sizeof q);
    dst += sizeof q;
  }
}

}  // namespace cloudcast::ros_bridge
