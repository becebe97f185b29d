#include "discovery_info.h"

#include <algorithm>
#include <cstring>

#include "absl/strings/str_cat.h"

namespace cloudcast::ros2_bridge {
namespace {

constexpr std::size_t kNameBound = 256;  // string<=256 in NodeEntitiesInfo.msg

// Humble's layout under the real DDS type name. idlc names it after its IDL module
// (cloudcast_humble::...); the copy keeps its marshalling ops and drops the XTypes type
// information, which names the module (rmw's own endpoints carry none: they match by name).
const dds_topic_descriptor_t kHumbleDescriptor = {
    cloudcast_humble_rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc.m_size,
    cloudcast_humble_rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc.m_align,
    cloudcast_humble_rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc.m_flagset &
        ~DDS_TOPIC_XTYPES_METADATA,
    cloudcast_humble_rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc.m_nkeys,
    rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc.m_typename,
    cloudcast_humble_rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc.m_keys,
    cloudcast_humble_rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc.m_nops,
    cloudcast_humble_rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc.m_ops,
    cloudcast_humble_rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc.m_meta,
    {nullptr, 0},
    {nullptr, 0},
    cloudcast_humble_rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc
        .restrict_data_representation,
};

template <std::size_t N>
void FillGid(const std::vector<std::uint8_t>& gid, std::uint8_t (&out)[N]) {
  std::memset(out, 0, N);
  std::memcpy(out, gid.data(), std::min(N, gid.size()));
}

void FillName(const std::string& name, char (&out)[kNameBound + 1]) {
  const std::size_t n = std::min(name.size(), kNameBound);
  std::memcpy(out, name.data(), n);
  out[n] = '\0';
}

// Fills one layout's structs (Msg, Node and Gid are that layout's C types).
template <typename Msg, typename Node, typename Gid>
void Fill(const ParticipantEntities& in, std::vector<Gid>* gids, std::vector<Node>* nodes,
          Msg* msg) {
  std::size_t total = 0;
  for (const NodeEntities& n : in.nodes) total += n.reader_gids.size() + n.writer_gids.size();
  gids->assign(total, Gid{});  // not reallocated below: the nodes point into it
  nodes->assign(in.nodes.size(), Node{});
  std::size_t g = 0;
  for (std::size_t i = 0; i < in.nodes.size(); ++i) {
    const NodeEntities& n = in.nodes[i];
    Node& out = (*nodes)[i];
    FillName(n.node_namespace, out.node_namespace);
    FillName(n.node_name, out.node_name);
    auto fill_seq = [&](const std::vector<std::vector<std::uint8_t>>& from, auto* seq) {
      seq->_buffer = gids->data() + g;
      seq->_length = seq->_maximum = static_cast<std::uint32_t>(from.size());
      seq->_release = false;
      for (const auto& gid : from) FillGid(gid, (*gids)[g++].data);
      if (from.empty()) seq->_buffer = nullptr;
    };
    fill_seq(n.reader_gids, &out.reader_gid_seq);
    fill_seq(n.writer_gids, &out.writer_gid_seq);
  }
  FillGid(in.gid, msg->gid.data);
  msg->node_entities_info_seq._buffer = nodes->empty() ? nullptr : nodes->data();
  msg->node_entities_info_seq._length = msg->node_entities_info_seq._maximum =
      static_cast<std::uint32_t>(nodes->size());
  msg->node_entities_info_seq._release = false;
}

template <typename Msg>
ParticipantEntities Read(const Msg& msg) {
  ParticipantEntities out;
  out.gid.assign(std::begin(msg.gid.data), std::end(msg.gid.data));
  for (std::uint32_t i = 0; i < msg.node_entities_info_seq._length; ++i) {
    const auto& n = msg.node_entities_info_seq._buffer[i];
    NodeEntities node;
    node.node_namespace = n.node_namespace;
    node.node_name = n.node_name;
    for (std::uint32_t j = 0; j < n.reader_gid_seq._length; ++j) {
      const auto& d = n.reader_gid_seq._buffer[j].data;
      node.reader_gids.emplace_back(std::begin(d), std::end(d));
    }
    for (std::uint32_t j = 0; j < n.writer_gid_seq._length; ++j) {
      const auto& d = n.writer_gid_seq._buffer[j].data;
      node.writer_gids.emplace_back(std::begin(d), std::end(d));
    }
    out.nodes.push_back(std::move(node));
  }
  return out;
}

}  // namespace

const MessageType kParticipantEntitiesInfoType{
    "rmw_dds_common/msg/ParticipantEntitiesInfo",
    &rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc};
const MessageType kParticipantEntitiesInfoHumbleType{"rmw_dds_common/msg/ParticipantEntitiesInfo",
                                                     &kHumbleDescriptor};

const MessageType& ParticipantEntitiesInfoType(GidLayout layout) {
  return layout == GidLayout::kHumble ? kParticipantEntitiesInfoHumbleType
                                      : kParticipantEntitiesInfoType;
}

absl::StatusOr<std::optional<GidLayout>> ParseDiscoveryInfo(std::string_view value,
                                                            std::string_view parameter) {
  if (value == "jazzy" || value == "iron") return GidLayout::kIronAndLater;
  if (value == "humble") return GidLayout::kHumble;
  if (value == "off") return std::optional<GidLayout>();
  return absl::InvalidArgumentError(absl::StrCat(
      std::string(parameter), " is '", std::string(value),
      "'; must be jazzy (Iron, Jazzy and later: 16-byte Gid), humble (24-byte Gid) or off"));
}

std::string_view Name(GidLayout layout) {
  return layout == GidLayout::kHumble ? "humble" : "jazzy";
}

std::size_t GidSize(GidLayout layout) { return layout == GidLayout::kHumble ? 24 : 16; }

std::vector<std::uint8_t> EntityGid(dds_entity_t entity, GidLayout layout) {
  dds_guid_t guid;
  if (dds_get_guid(entity, &guid) != DDS_RETCODE_OK) return {};
  std::vector<std::uint8_t> gid(GidSize(layout), 0);
  std::memcpy(gid.data(), guid.v, sizeof(guid.v));
  return gid;
}

ParticipantEntitiesInfoSample::ParticipantEntitiesInfoSample(GidLayout layout,
                                                             const ParticipantEntities& entities)
    : layout_(layout) {
  if (layout == GidLayout::kHumble) {
    Fill(entities, &gids24_, &nodes24_, &msg24_);
  } else {
    Fill(entities, &gids16_, &nodes16_, &msg16_);
  }
}

const void* ParticipantEntitiesInfoSample::sample() const {
  if (layout_ == GidLayout::kHumble) return &msg24_;
  return &msg16_;
}

ParticipantEntities FromSample(GidLayout layout, const void* sample) {
  if (layout == GidLayout::kHumble) {
    return Read(*static_cast<const cloudcast_humble_rmw_dds_common_msg_dds__ParticipantEntitiesInfo_*>(
        sample));
  }
  return Read(*static_cast<const rmw_dds_common_msg_dds__ParticipantEntitiesInfo_*>(sample));
}

DdsQos DiscoveryInfoQos(GidLayout layout) {
  const MessageType& type = ParticipantEntitiesInfoType(layout);
  DdsQos qos = EndpointQos(QosProfile{true, 1, true}, type.type_hash());
  if (layout == GidLayout::kHumble) dds_qset_userdata(qos.get(), nullptr, 0);
  return qos;
}

absl::StatusOr<dds_entity_t> PublishDiscoveryInfo(dds_entity_t participant, GidLayout layout,
                                                  const NodeNames& node,
                                                  const std::vector<dds_entity_t>& readers,
                                                  const std::vector<dds_entity_t>& writers) {
  const MessageType& type = ParticipantEntitiesInfoType(layout);
  const dds_entity_t topic =
      dds_create_topic(participant, type.descriptor, kDiscoveryInfoTopic, nullptr, nullptr);
  if (topic < 0) {
    return absl::InternalError(
        absl::StrCat("DDS topic ", kDiscoveryInfoTopic, ": ", dds_strretcode(topic)));
  }
  DdsQos qos = DiscoveryInfoQos(layout);
  const dds_entity_t writer = dds_create_writer(participant, topic, qos.get(), nullptr);
  if (writer < 0) {
    return absl::InternalError(
        absl::StrCat("DDS writer on ", kDiscoveryInfoTopic, ": ", dds_strretcode(writer)));
  }
  ParticipantEntities entities;
  entities.gid = EntityGid(participant, layout);
  NodeEntities n;
  n.node_namespace = node.node_namespace;
  n.node_name = node.node_name;
  for (dds_entity_t r : readers) n.reader_gids.push_back(EntityGid(r, layout));
  for (dds_entity_t w : writers) n.writer_gids.push_back(EntityGid(w, layout));
  entities.nodes.push_back(std::move(n));
  ParticipantEntitiesInfoSample sample(layout, entities);
  if (const dds_return_t rc = dds_write(writer, sample.sample()); rc != DDS_RETCODE_OK) {
    return absl::InternalError(
        absl::StrCat("writing ", kDiscoveryInfoTopic, ": ", dds_strretcode(rc)));
  }
  return writer;
}

}  // namespace cloudcast::ros2_bridge
