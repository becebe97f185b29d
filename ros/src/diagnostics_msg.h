// The shared core's diagnostics report (bridge/diagnostics.h) as ROS 1's message.
#pragma once

#include <diagnostic_msgs/DiagnosticArray.h>
#include <ros/time.h>

#include "diagnostics.h"

namespace cloudcast::ros_bridge {

diagnostic_msgs::DiagnosticArray ToDiagnosticArray(const DiagnosticReport& report,
                                                   const ros::Time& stamp);

}  // namespace cloudcast::ros_bridge
