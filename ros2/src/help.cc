#include "help.h"

#include <sstream>

#include "absl/strings/str_replace.h"
#include "bridge_options.h"

namespace cloudcast::ros2_bridge {

std::string HelpText() {
  std::ostringstream os;
  os << "cloudcast-ros2-bridge: a ROS 2 node (CycloneDDS, ROS 2's DDS conventions; no rclcpp)\n"
        "that turns a camera's disparity, depth image or stereo pair into point clouds on a\n"
        "cloudcast server and publishes them as sensor_msgs/msg/PointCloud2.\n\n"
        "Usage: cloudcast-ros2-bridge [--ros-args [-p name:=value] [--params-file FILE]\n"
        "                              [-r from:=to] [-r __ns:=/namespace] [-r __node:=name]]\n\n"
        "The node: cloudcast_bridge in the namespace of -r __ns (default /), on DDS domain\n"
        "ROS_DOMAIN_ID (default 0); readers and writers as rmw_cyclonedds and rmw_fastrtps make\n"
        "them (topics rt/<name>, XCDR1, type hashes in USER_DATA), so Humble and Jazzy nodes on\n"
        "either rmw see its topics. CYCLONEDDS_URI, when set, configures Cyclone; unset, the\n"
        "bridge asks for a 10 MB socket receive buffer (megabyte images; the kernel caps it at\n"
        "net.core.rmem_max).\n\n"
        "Subscribes (exact-time synchronized on header.stamp; QoS by input_qos):\n"
        "  input disparity: disparity (stereo_msgs/msg/DisparityImage, 32FC1),\n"
        "                   left/image_rect_color (sensor_msgs/msg/Image), left/camera_info\n"
        "  input depth:     depth_registered/image_rect (16UC1 mm or 32FC1 m),\n"
        "                   rgb/image_rect_color, rgb/camera_info\n"
        "  input stereo:    left/image_rect_color, right/image_rect, left/camera_info,\n"
        "                   right/camera_info (the server matches the pair)\n"
        "  Colour images: rgb8, bgr8, rgba8, bgra8 or mono8, the same size as the depth or\n"
        "  disparity.\n"
        "Publishes (reliable, keep last 10, volatile: what default subscribers take):\n"
        "  points2       sensor_msgs/msg/PointCloud2: x y z rgb (FLOAT32 at 0 4 8 12), the\n"
        "                input's frame_id and stamp\n"
        "  /diagnostics  diagnostic_msgs/msg/DiagnosticArray: per-stage times, counters, and\n"
        "                the last input error naming the message and field\n"
        "  ros_discovery_info (DDS topic; reliable, transient local, keep last 1)\n"
        "                rmw_dds_common/msg/ParticipantEntitiesInfo: the node and its readers'\n"
        "                and writers' GIDs, so that `ros2 node list` shows it\n\n"
        "Parameters (-p name:=value or a --params-file, ROS 2 names with '.'):\n"
        "  input_qos (string, default sensor_data)\n"
        "      the inputs' QoS: sensor_data (best effort, keep last 5; matches reliable and\n"
        "      best-effort cameras) or default (reliable, keep last 10; a best-effort camera is\n"
        "      then reported on /diagnostics as incompatible)\n"
        "  ros_discovery_info (string, default jazzy)\n"
        "      the robot's ROS 2, for the ros_discovery_info entry's Gid: jazzy (Iron, Jazzy,\n"
        "      Kilted, Rolling: 16 bytes), humble (24 bytes) or off (no entry; the topics are\n"
        "      still seen, the node is not)\n"
        "  use_sim_time (bool, default false)\n"
        "      accepted for launch files; the clouds carry their input's stamp either way\n";
  for (const cloudcast::ros_bridge::ParamDoc& d : cloudcast::ros_bridge::ParamDocs()) {
    if (d.name == "stereo/publish_disparity") continue;  // not on ROS 2 yet
    os << "  " << absl::StrReplaceAll(d.name, {{"/", "."}}) << " (" << d.type << ", default "
       << (d.default_value.empty() ? "none" : d.default_value) << ")\n"
       << cloudcast::ros_bridge::WrapText(absl::StrReplaceAll(d.help, {{"~", ""}}), 84, "      ");
  }
  os << "\nExamples:\n"
        "  cloudcast-ros2-bridge --ros-args -p server:=10.0.0.2:50051 -r __ns:=/stereo\n"
        "  cloudcast-ros2-bridge --ros-args -p input:=depth -r __ns:=/camera \\\n"
        "      -r points2:=/camera/cloudcast/points\n"
        "  cloudcast-ros2-bridge --ros-args --params-file cloudcast.yaml\n"
        "  ros2 launch cloudcast.launch.py   (docs/ros2.md: an ExecuteProcess launch file)\n"
        "Documentation: docs/ros2.md\n";
  return os.str();
}

}  // namespace cloudcast::ros2_bridge
