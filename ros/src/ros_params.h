// The ROS 1 bridge's parameters: the node's private parameters (~server, ~voxel/leaf, ...) read
// through the shared core's ReadBridgeOptions, and its --help.
#pragma once

#include <ros/ros.h>

#include <string>

#include "absl/status/statusor.h"
#include "bridge_options.h"

namespace cloudcast::ros_bridge {

// Reads the private parameters of `private_nh` (a "~" handle); errors name the parameter
// ("~voxel/leaf is -0.5; must be finite and > 0").
absl::StatusOr<BridgeOptions> ReadBridgeOptions(const ros::NodeHandle& private_nh);

// The text `cloudcast-ros-bridge --help` prints: usage, topics, parameters, examples.
std::string HelpText();

}  // namespace cloudcast::ros_bridge
