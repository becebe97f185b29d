#include "point_cloud2.h"

#include "point_cloud_layout.h"

namespace cloudcast::ros_bridge {

void ToPointCloud2(const PointCloud& cloud, const std_msgs::Header& header,
                   sensor_msgs::PointCloud2* out) {
  out->header = header;
  out->height = 1;
  out->width = static_cast<std::uint32_t>(cloud.size());
  out->is_bigendian = false;
  out->is_dense = true;  // the server's clouds hold finite points only
  out->fields.resize(kPointFields.size());
  for (std::size_t i = 0; i < kPointFields.size(); ++i) {
    out->fields[i].name = kPointFields[i].name;
    out->fields[i].offset = kPointFields[i].offset;
    out->fields[i].datatype = kPointFields[i].datatype;
    out->fields[i].count = kPointFields[i].count;
  }
  out->point_step = kPointStep;
  out->row_step = out->point_step * out->width;
  out->data.resize(cloud.size() * kPointStep);
  WritePointData(cloud, out->data.data());
}

}  // namespace cloudcast::ros_bridge
