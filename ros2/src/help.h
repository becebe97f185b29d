// The text `cloudcast-ros2-bridge --help` prints: usage, the DDS conventions, topics, every
// parameter (the shared ones in ROS 2's dotted names, then the ROS 2 bridge's own), examples.
#pragma once

#include <string>

namespace cloudcast::ros2_bridge {

std::string HelpText();

}  // namespace cloudcast::ros2_bridge
