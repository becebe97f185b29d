// The ROS 2 bridge's log lines, in rclcpp's console format: "[INFO] [<unix time>] [<node>]: ...".
#pragma once

#include <string>

#include "ros_names.h"

namespace cloudcast::ros2_bridge {

void LogInfo(const NodeNames& node, const std::string& message);
void LogWarn(const NodeNames& node, const std::string& message);
// Errors of the same text are printed at most once every five seconds (bad input every frame).
void LogError(const NodeNames& node, const std::string& message);

}  // namespace cloudcast::ros2_bridge
