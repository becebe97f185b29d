#include "diagnostics_msg.h"

namespace cloudcast::ros_bridge {

diagnostic_msgs::DiagnosticArray ToDiagnosticArray(const DiagnosticReport& report,
                                                   const ros::Time& stamp) {
  diagnostic_msgs::DiagnosticArray array;
  array.header.stamp = stamp;
  diagnostic_msgs::DiagnosticStatus s;
  s.level = report.level;
  s.name = report.name;
  s.message = report.message;
  s.hardware_id = report.hardware_id;
  for (const auto& [key, value] : report.values) {
    diagnostic_msgs::KeyValue kv;
    kv.key = key;
    kv.value = value;
    s.values.push_back(std::move(kv));
  }
  array.status.push_back(std::move(s));
  return array;
}

}  // namespace cloudcast::ros_bridge
