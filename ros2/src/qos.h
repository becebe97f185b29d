// ROS 2's QoS profiles (rmw's qos_profile_default and qos_profile_sensor_data) as DDS QoS, with
// what rmw_cyclonedds adds to every reader and writer: XCDR1 only (every ROS 2 reader takes plain
// CDR; an XCDR2 writer matches none), and USER_DATA "typehash=RIHS01_...;" (Iron and later).
#pragma once

#include <dds/dds.h>

#include <memory>
#include <string>
#include <string_view>

#include "absl/status/statusor.h"

namespace cloudcast::ros2_bridge {

struct QosProfile {
  bool reliable = true;         // RELIABLE, else BEST_EFFORT
  int depth = 10;               // KEEP_LAST depth
  bool transient_local = false; // TRANSIENT_LOCAL, else VOLATILE
};

// Reliable, keep last 10, volatile: what rclcpp's publishers and subscriptions get unless told.
QosProfile DefaultQos();
// Best effort, keep last 5, volatile: rclcpp::SensorDataQoS(), what camera drivers often publish
// with. A reliable subscription does not match such a writer; a best-effort one matches both.
QosProfile SensorDataQos();

// "default" or "sensor_data"; errors name `parameter`.
absl::StatusOr<QosProfile> ParseQosProfile(std::string_view name, std::string_view parameter);

struct QosDeleter {
  void operator()(dds_qos_t* q) const { dds_delete_qos(q); }
};
using DdsQos = std::unique_ptr<dds_qos_t, QosDeleter>;

// The DDS QoS of a reader or writer of `profile` for a type whose hash is `type_hash`.
DdsQos EndpointQos(const QosProfile& profile, std::string_view type_hash);
// The endpoint USER_DATA: "typehash=RIHS01_...;".
std::string TypeHashUserData(std::string_view type_hash);

// The participant's QoS: USER_DATA "enclave=/;" (rmw's security enclave; "/" when none).
DdsQos ParticipantQos(std::string_view enclave = "/");

}  // namespace cloudcast::ros2_bridge
