// ROS 2's names on DDS (design.ros2.org "Topic and Service name mapping to DDS"): a topic's
// fully qualified name resolved as rcl resolves it (relative to the node's namespace, "~" the
// node's own name, remapped), then "rt" + that name as the DDS topic; the DDS type name of a
// message "<package>::msg::dds_::<Name>_".
#pragma once

#include <map>
#include <string>
#include <string_view>

#include "absl/status/statusor.h"

namespace cloudcast::ros2_bridge {

// A node's namespace and name, and its remappings (from --ros-args -r from:=to): both sides are
// resolved before they are compared, as rcl does.
struct NodeNames {
  std::string node_namespace = "/";  // absolute
  std::string node_name;
  std::map<std::string, std::string> remaps;  // resolved name -> resolved name
};

// Checks a node name (letters, digits and '_', not starting with a digit) and a namespace
// (absolute, tokens of the same characters separated by single '/').
absl::Status ValidateNodeName(std::string_view name);
absl::Status ValidateNamespace(std::string_view ns);

// `name` ("points", "/diagnostics", "~/points", "left/camera_info") as a fully qualified name
// ("/camera/points"), before remapping. Errors name the topic ("topic 'a//b': ...").
absl::StatusOr<std::string> ExpandTopicName(std::string_view name, const NodeNames& node);

// ExpandTopicName, then the node's remappings.
absl::StatusOr<std::string> ResolveTopicName(std::string_view name, const NodeNames& node);

// "/camera/points" -> "rt/camera/points" (ROS topics; services are rq/ and rr/).
std::string DdsTopicName(std::string_view fully_qualified_name);

// "sensor_msgs/msg/PointCloud2" -> "sensor_msgs::msg::dds_::PointCloud2_".
std::string DdsTypeName(std::string_view ros_type_name);

}  // namespace cloudcast::ros2_bridge
