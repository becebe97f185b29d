#include "qos.h"

#include "absl/strings/str_cat.h"

namespace cloudcast::ros2_bridge {

QosProfile DefaultQos() { return QosProfile{true, 10, false}; }

QosProfile SensorDataQos() { return QosProfile{false, 5, false}; }

absl::StatusOr<QosProfile> ParseQosProfile(std::string_view name, std::string_view parameter) {
  if (name == "default") return DefaultQos();
  if (name == "sensor_data") return SensorDataQos();
  return absl::InvalidArgumentError(absl::StrCat(
      std::string(parameter), " is '", std::string(name), "'; must be default (reliable, keep last 10) or sensor_data "
                                "(best effort, keep last 5)"));
}

std::string TypeHashUserData(std::string_view type_hash) {
  return "typehash=" + std::string(type_hash) + ";";
}

DdsQos EndpointQos(const QosProfile& profile, std::string_view type_hash) {
  DdsQos qos(dds_create_qos());
  dds_qset_reliability(qos.get(), profile.reliable ? DDS_RELIABILITY_RELIABLE
                                                   : DDS_RELIABILITY_BEST_EFFORT,
                       DDS_SECS(1));
  dds_qset_history(qos.get(), DDS_HISTORY_KEEP_LAST, profile.depth);
  dds_qset_durability(qos.get(),
                      profile.transient_local ? DDS_DURABILITY_TRANSIENT_LOCAL
                                              : DDS_DURABILITY_VOLATILE);
  dds_data_representation_id_t xcdr1 = DDS_DATA_REPRESENTATION_XCDR1;
  dds_qset_data_representation(qos.get(), 1, &xcdr1);
  const std::string user_data = TypeHashUserData(type_hash);
  dds_qset_userdata(qos.get(), user_data.data(), user_data.size());
  return qos;
}

DdsQos ParticipantQos(std::string_view enclave) {
  DdsQos qos(dds_create_qos());
  const std::string user_data = "enclave=" + std::string(enclave) + ";";
  dds_qset_userdata(qos.get(), user_data.data(), user_data.size());
  return qos;
}

}  // namespace cloudcast::ros2_bridge
