// A ROS 2 node's presence on DDS without rmw: one participant in domain ROS_DOMAIN_ID with
// USER_DATA "enclave=/;", and readers and writers on "rt/<topic>" with the type's DDS name, XCDR1
// and the type hash in their USER_DATA, as rmw_cyclonedds creates them.
#pragma once

#include <dds/dds.h>

#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "message_types.h"
#include "qos.h"

namespace cloudcast::ros2_bridge {

// The Cyclone configuration the bridge runs with unless CYCLONEDDS_URI says otherwise: a socket
// receive buffer of up to 10 MB for its megabyte input images (dds_node.cc says why).
inline constexpr const char* kLargeMessageConfig =
    "<CycloneDDS><Domain><Internal><SocketReceiveBufferSize min=\"default\" max=\"10MB\"/>"
    "</Internal></Domain></CycloneDDS>";

// ROS_DOMAIN_ID (unset or empty: 0); DDS domains 0..232 (RTPS's port mapping), errors name it.
absl::StatusOr<dds_domainid_t> DomainIdFromEnv();

class DdsNode {
 public:
  static absl::StatusOr<std::unique_ptr<DdsNode>> Create(dds_domainid_t domain);
  ~DdsNode();  // deletes the participant and every reader and writer
  DdsNode(const DdsNode&) = delete;
  DdsNode& operator=(const DdsNode&) = delete;

  // `topic` is the fully qualified ROS name ("/camera/points").
  absl::StatusOr<dds_entity_t> CreateWriter(const MessageType& type, const std::string& topic,
                                            const QosProfile& qos);
  absl::StatusOr<dds_entity_t> CreateReader(const MessageType& type, const std::string& topic,
                                            const QosProfile& qos);
  dds_entity_t participant() const { return participant_; }

 private:
  DdsNode(dds_entity_t participant, dds_entity_t own_domain)
      : participant_(participant), own_domain_(own_domain) {}
  absl::StatusOr<dds_entity_t> Topic(const MessageType& type, const std::string& topic);
  dds_entity_t participant_;
  dds_entity_t own_domain_;  // 0 when the domain is CYCLONEDDS_URI's (or made elsewhere)
};

}  // namespace cloudcast::ros2_bridge
