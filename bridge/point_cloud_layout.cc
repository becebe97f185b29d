#include "point_cloud_layout.h"

#include <cstring>

namespace cloudcast::ros_bridge {

static_assert(sizeof(Point) == kPointStep, "the PointCloud2 layout is cloudcast's point");

void WritePointData(const PointCloud& cloud, std::uint8_t* out) {
  for (const Point& p : cloud.points) {
    Point q = p;
    q.rgba &= 0x00FFFFFFu;
    std::memcpy(out, &q, sizeof q);
    out += sizeof q;
  }
}

}  // namespace cloudcast::ros_bridge
