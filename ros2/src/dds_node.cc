#include "dds_node.h"

#include <cstdlib>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "ros_names.h"

namespace cloudcast::ros2_bridge {
namespace {

absl::Status DdsError(const std::string& what, dds_return_t rc) {
  return absl::UnavailableError(absl::StrCat(what, ": ", dds_strretcode(rc)));
}

}  // namespace

absl::StatusOr<dds_domainid_t> DomainIdFromEnv() {
  const char* env = std::getenv("ROS_DOMAIN_ID");
  if (env == nullptr || *env == '\0') return dds_domainid_t{0};
  int id = 0;
  if (!absl::SimpleAtoi(env, &id) || id < 0 || id > 232) {
    return absl::InvalidArgumentError(
        absl::StrCat("ROS_DOMAIN_ID is '", env, "'; must be an integer in 0..232"));
  }
  return static_cast<dds_domainid_t>(id);
}

absl::StatusOr<std::unique_ptr<DdsNode>> DdsNode::Create(dds_domainid_t domain) {
  // Megabyte images arrive as hundreds of fragments: with Cyclone's default socket receive
  // buffer a busy machine drops some, and the reliable protocol's repairs then delay whole sets
  // by hundreds of milliseconds (measured: 10 to 30 % of frames lost to the sync queue and the
  // server's latest-frame delivery at 10 Hz). ROS 2's docs advise the same for large messages;
  // the kernel caps the size at net.core.rmem_max. CYCLONEDDS_URI, when set, decides instead.
  dds_entity_t own_domain = 0;
  const char* uri = std::getenv("CYCLONEDDS_URI");
  if (uri == nullptr || *uri == '\0') {
    own_domain = dds_create_domain(domain, kLargeMessageConfig);
    if (own_domain < 0) own_domain = 0;  // already made in this process (the tests' peers)
  }
  DdsQos qos = ParticipantQos();
  const dds_entity_t p = dds_create_participant(domain, qos.get(), nullptr);
  if (p < 0) {
    if (own_domain > 0) dds_delete(own_domain);
    return DdsError(absl::StrCat("DDS participant in domain ", domain), p);
  }
  return std::unique_ptr<DdsNode>(new DdsNode(p, own_domain));
}

DdsNode::~DdsNode() {
  dds_delete(participant_);
  if (own_domain_ > 0) dds_delete(own_domain_);
}

absl::StatusOr<dds_entity_t> DdsNode::Topic(const MessageType& type, const std::string& topic) {
  const std::string name = DdsTopicName(topic);
  const dds_entity_t t = dds_create_topic(participant_, type.descriptor, name.c_str(), nullptr,
                                          nullptr);
  if (t < 0) return DdsError(absl::StrCat("DDS topic ", name, " (", type.ros_name, ")"), t);
  return t;
}

absl::StatusOr<dds_entity_t> DdsNode::CreateWriter(const MessageType& type,
                                                   const std::string& topic,
                                                   const QosProfile& qos) {
  auto t = Topic(type, topic);
  if (!t.ok()) return t.status();
  DdsQos q = EndpointQos(qos, type.type_hash());
  const dds_entity_t w = dds_create_writer(participant_, *t, q.get(), nullptr);
  if (w < 0) return DdsError(absl::StrCat("DDS writer on ", topic), w);
  return w;
}

absl::StatusOr<dds_entity_t> DdsNode::CreateReader(const MessageType& type,
                                                   const std::string& topic,
                                                   const QosProfile& qos) {
  auto t = Topic(type, topic);
  if (!t.ok()) return t.status();
  DdsQos q = EndpointQos(qos, type.type_hash());
  const dds_entity_t r = dds_create_reader(participant_, *t, q.get(), nullptr);
  if (r < 0) return DdsError(absl::StrCat("DDS reader on ", topic), r);
  // The bridge polls the incompatible-QoS status for /diagnostics (a best-effort camera against
  // input_qos default).
  dds_set_status_mask(r, DDS_DATA_AVAILABLE_STATUS | DDS_REQUESTED_INCOMPATIBLE_QOS_STATUS);
  return r;
}

}  // namespace cloudcast::ros2_bridge
