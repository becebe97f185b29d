// cloudcast-ros-bridge: a ROS 1 node that turns a camera's disparity (and colour) into point
// clouds on a cloudcast server and publishes them as sensor_msgs/PointCloud2. --help prints its
// topics and parameters; docs/ros.md has the same with examples.
#include <ros/ros.h>

#include <cstdio>
#include <cstring>

#include "bridge.h"
#include "ros_params.h"

int main(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--help") == 0 || std::strcmp(argv[i], "-h") == 0) {
      std::fputs(cloudcast::ros_bridge::HelpText().c_str(), stdout);
      return 0;
    }
  }
  ros::init(argc, argv, "cloudcast_bridge");
  for (int i = 1; i < argc; ++i) {
    // ros::init has taken the remappings (name:=value) out of argv; anything left is a mistake.
    std::fprintf(stderr,
                 "cloudcast-ros-bridge: unexpected argument '%s' (remap topics with "
                 "name:=topic, set parameters with _name:=value; see --help)\n",
                 argv[i]);
    return 2;
  }
  ros::NodeHandle nh;
  ros::NodeHandle private_nh("~");
  auto bridge = cloudcast::ros_bridge::Bridge::Create(nh, private_nh);
  if (!bridge.ok()) {
    std::fprintf(stderr, "cloudcast-ros-bridge: %s\n",
                 std::string(bridge.status().message()).c_str());
    return 2;
  }
  ros::spin();
  return 0;
}
