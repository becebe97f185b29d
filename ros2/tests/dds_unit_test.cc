// ROS 2's conventions on DDS as the bridge applies them: topic and type names, QoS, USER_DATA,
// the type hashes (rcl's test vector for PointCloud2), and the CDR round trip of the types.
#include <gtest/gtest.h>

#include <cstring>
#include <optional>
#include <string>
#include <vector>

#include "discovery_info.h"
#include "message_types.h"
#include "qos.h"
#include "ros_names.h"
#include "type_hash.h"

namespace cloudcast::ros2_bridge {
namespace {

TEST(Ros2Names, TopicsAreRtAndTheFullyQualifiedName) {
  NodeNames node;
  node.node_namespace = "/camera";
  node.node_name = "cloudcast_bridge";
  EXPECT_EQ(*ExpandTopicName("points", node), "/camera/points");
  EXPECT_EQ(*ExpandTopicName("/diagnostics", node), "/diagnostics");
  EXPECT_EQ(*ExpandTopicName("~/points", node), "/camera/cloudcast_bridge/points");
  EXPECT_EQ(*ExpandTopicName("left/camera_info", node), "/camera/left/camera_info");
  EXPECT_EQ(DdsTopicName("/camera/points"), "rt/camera/points");
  node.node_namespace = "/";
  EXPECT_EQ(*ExpandTopicName("points", node), "/points");
  node.remaps["/points"] = "/robot/cloud";
  EXPECT_EQ(*ResolveTopicName("points", node), "/robot/cloud");
  EXPECT_EQ(*ResolveTopicName("/points", node), "/robot/cloud");
  EXPECT_EQ(*ResolveTopicName("other", node), "/other");
}

TEST(Ros2Names, InvalidNamesAreRefusedNamingThem) {
  NodeNames node;
  node.node_name = "n";
  for (const char* bad : {"", "a//b", "1abc", "a b", "~x", "points/", "/"}) {
    auto r = ExpandTopicName(bad, node);
    EXPECT_FALSE(r.ok()) << bad;
  }
  EXPECT_NE(ExpandTopicName("a//b", node).status().message().find("a//b"), std::string::npos);
  EXPECT_FALSE(ValidateNodeName("9lives").ok());
  EXPECT_FALSE(ValidateNodeName("my-node").ok());
  EXPECT_TRUE(ValidateNodeName("cloudcast_bridge").ok());
  EXPECT_FALSE(ValidateNamespace("camera").ok());
  EXPECT_TRUE(ValidateNamespace("/robot/camera").ok());
}

TEST(Ros2Names, TypeNamesFollowRosidlsDdsMapping) {
  EXPECT_EQ(DdsTypeName("sensor_msgs/msg/PointCloud2"), "sensor_msgs::msg::dds_::PointCloud2_");
  // The generated descriptors carry the same names: what a ROS 2 reader's type must equal.
  for (const MessageType* t : AllMessageTypes()) {
    EXPECT_EQ(std::string(t->descriptor->m_typename), DdsTypeName(t->ros_name)) << t->ros_name;
  }
}

TEST(Ros2Qos, DefaultAndSensorDataProfiles) {
  const QosProfile d = DefaultQos();
  EXPECT_TRUE(d.reliable);
  EXPECT_EQ(d.depth, 10);
  EXPECT_FALSE(d.transient_local);
  const QosProfile s = SensorDataQos();
  EXPECT_FALSE(s.reliable);
  EXPECT_EQ(s.depth, 5);
  EXPECT_FALSE(s.transient_local);
  EXPECT_TRUE(ParseQosProfile("sensor_data", "qos").ok());
  auto bad = ParseQosProfile("fast", "input_qos");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("input_qos is 'fast'"), std::string::npos);
}

TEST(Ros2Qos, EndpointQosIsXcdr1WithTheTypeHash) {
  const std::string hash = kPointCloud2Type.type_hash();
  for (const QosProfile& p : {DefaultQos(), SensorDataQos()}) {
    DdsQos q = EndpointQos(p, hash);
    dds_reliability_kind_t rel;
    dds_duration_t blocking;
    ASSERT_TRUE(dds_qget_reliability(q.get(), &rel, &blocking));
    EXPECT_EQ(rel, p.reliable ? DDS_RELIABILITY_RELIABLE : DDS_RELIABILITY_BEST_EFFORT);
    dds_history_kind_t hist;
    int32_t depth;
    ASSERT_TRUE(dds_qget_history(q.get(), &hist, &depth));
    EXPECT_EQ(hist, DDS_HISTORY_KEEP_LAST);
    EXPECT_EQ(depth, p.depth);
    dds_durability_kind_t dur;
    ASSERT_TRUE(dds_qget_durability(q.get(), &dur));
    EXPECT_EQ(dur, DDS_DURABILITY_VOLATILE);
    uint32_t n = 0;
    dds_data_representation_id_t* reprs = nullptr;
    ASSERT_TRUE(dds_qget_data_representation(q.get(), &n, &reprs));
    ASSERT_EQ(n, 1u);
    EXPECT_EQ(reprs[0], DDS_DATA_REPRESENTATION_XCDR1);
    dds_free(reprs);
    void* ud = nullptr;
    size_t size = 0;
    ASSERT_TRUE(dds_qget_userdata(q.get(), &ud, &size));
    EXPECT_EQ(std::string(static_cast<char*>(ud), size), "typehash=" + hash + ";");
    dds_free(ud);
  }
  DdsQos pq = ParticipantQos();
  void* ud = nullptr;
  size_t size = 0;
  ASSERT_TRUE(dds_qget_userdata(pq.get(), &ud, &size));
  EXPECT_EQ(std::string(static_cast<char*>(ud), size), "enclave=/;");
  dds_free(ud);
}

// rcl's test vector (rcl/test/rcl/test_type_hash.cpp ... sensor_msgs/msg/PointCloud2), and
// builtin_interfaces/msg/Time's hash as every generated ROS 2 package embeds it.
TEST(Ros2TypeHash, PointCloud2MatchesRclsTestVector) {
  EXPECT_EQ(TypeHash("sensor_msgs/msg/PointCloud2"),
            "RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5");
  EXPECT_EQ(TypeHash("builtin_interfaces/msg/Time"),
            "RIHS01_b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197");
  EXPECT_EQ(kPointCloud2Type.type_hash(), TypeHash("sensor_msgs/msg/PointCloud2"));
  EXPECT_EQ(TypeHash("sensor_msgs/msg/Nope"), "");
}

TEST(Ros2TypeHash, JsonIsRosidlsLayout) {
  const std::string json = HashableTypeJson("builtin_interfaces/msg/Time");
  EXPECT_EQ(json,
            "{\"type_description\": {\"type_name\": \"builtin_interfaces/msg/Time\", \"fields\": "
            "[{\"name\": \"sec\", \"type\": {\"type_id\": 6, \"capacity\": 0, \"string_capacity\": "
            "0, \"nested_type_name\": \"\"}}, {\"name\": \"nanosec\", \"type\": {\"type_id\": 7, "
            "\"capacity\": 0, \"string_capacity\": 0, \"nested_type_name\": \"\"}}]}, "
            "\"referenced_type_descriptions\": []}");
  // Every type is described, with distinct hashes.
  std::vector<std::string> hashes;
  for (const MessageType* t : AllMessageTypes()) {
    ASSERT_NE(FindTypeDescription(t->ros_name), nullptr) << t->ros_name;
    hashes.push_back(t->type_hash());
    EXPECT_EQ(hashes.back().size(), 7u + 64u);
  }
  std::sort(hashes.begin(), hashes.end());
  EXPECT_EQ(std::unique(hashes.begin(), hashes.end()), hashes.end());
}

TEST(Ros2Cdr, CameraInfoRoundTripAndTruncationRefused) {
  sensor_msgs_msg_dds__CameraInfo_ info{};
  info.header.stamp.sec = 12;
  info.header.stamp.nanosec = 345;
  info.header.frame_id = const_cast<char*>("left_camera");
  info.height = 480;
  info.width = 640;
  info.distortion_model = const_cast<char*>("plumb_bob");
  double d[5] = {0.1, -0.2, 0.0, 0.0, 0.05};
  info.d._buffer = d;
  info.d._length = info.d._maximum = 5;
  for (int i = 0; i < 12; ++i) info.p[i] = i + 0.5;
  info.roi.do_rectify = true;
  const std::vector<std::uint8_t> bytes = SerializeCdr(kCameraInfoType, &info);
  ASSERT_GE(bytes.size(), 4u);
  EXPECT_EQ(bytes[0], 0x00);
  EXPECT_EQ(bytes[1], 0x01);  // CDR_LE
  sensor_msgs_msg_dds__CameraInfo_ back{};
  ASSERT_TRUE(DeserializeCdr(kCameraInfoType, bytes, &back).ok());
  EXPECT_EQ(back.header.stamp.sec, 12);
  EXPECT_STREQ(back.header.frame_id, "left_camera");
  EXPECT_STREQ(back.distortion_model, "plumb_bob");
  ASSERT_EQ(back.d._length, 5u);
  EXPECT_EQ(back.d._buffer[4], 0.05);
  EXPECT_EQ(back.p[11], 11.5);
  EXPECT_TRUE(back.roi.do_rectify);
  FreeSample(kCameraInfoType, &back);

  for (std::size_t cut : {std::size_t{0}, std::size_t{3}, std::size_t{20}, bytes.size() - 1}) {
    sensor_msgs_msg_dds__CameraInfo_ partial{};
    auto s = DeserializeCdr(kCameraInfoType, {bytes.data(), cut}, &partial);
    EXPECT_FALSE(s.ok()) << cut;
    EXPECT_NE(s.message().find("sensor_msgs/msg/CameraInfo"), std::string::npos);
  }
  std::vector<std::uint8_t> xcdr2 = bytes;
  xcdr2[1] = 0x07;  // D_CDR2_LE
  sensor_msgs_msg_dds__CameraInfo_ other{};
  EXPECT_FALSE(DeserializeCdr(kCameraInfoType, xcdr2, &other).ok());
  std::vector<std::uint8_t> bad_bool = bytes;
  bad_bool[bytes.size() - 1] = 2;  // roi.do_rectify, the last byte
  EXPECT_FALSE(DeserializeCdr(kCameraInfoType, bad_bool, &other).ok());
}

// ---- ros_discovery_info (rmw_dds_common/msg/ParticipantEntitiesInfo)

// The hashes rosidl_generator_c writes into rmw_dds_common's generated
// participant_entities_info__description.c (Iron and later: the 16-byte Gid), as a built
// ROS 2 workspace carries them.
TEST(Ros2DiscoveryInfo, TypeHashesMatchRosidlsForIronAndLater) {
  EXPECT_EQ(TypeHash("rmw_dds_common/msg/Gid"),
            "RIHS01_ab6f21cfbb0a6dbb837161e1110c2051a2850ed9f9c53944d7115d9bcebedf71");
  EXPECT_EQ(TypeHash("rmw_dds_common/msg/NodeEntitiesInfo"),
            "RIHS01_8ffef65ee2d088c63b1e8fcd31e800ba9fc8dbe0ee15ca60d1676de5218087a7");
  EXPECT_EQ(TypeHash("rmw_dds_common/msg/ParticipantEntitiesInfo"),
            "RIHS01_91a0593bacdcc50ea9bdcf849a938b128412cc1ea821245c663bcd26f83c295e");
  EXPECT_EQ(kParticipantEntitiesInfoType.type_hash(),
            TypeHash("rmw_dds_common/msg/ParticipantEntitiesInfo"));
}

TEST(Ros2DiscoveryInfo, BothLayoutsGoOnTheWireUnderRmwsTypeName) {
  EXPECT_STREQ(kParticipantEntitiesInfoType.descriptor->m_typename,
               "rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_");
  EXPECT_STREQ(kParticipantEntitiesInfoHumbleType.descriptor->m_typename,
               "rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_");
  EXPECT_EQ(GidSize(GidLayout::kHumble), 24u);
  EXPECT_EQ(GidSize(GidLayout::kIronAndLater), 16u);
}

TEST(Ros2DiscoveryInfo, TheParameterNamesTheDistribution) {
  EXPECT_EQ(*ParseDiscoveryInfo("jazzy", "ros_discovery_info"), GidLayout::kIronAndLater);
  EXPECT_EQ(*ParseDiscoveryInfo("iron", "ros_discovery_info"), GidLayout::kIronAndLater);
  EXPECT_EQ(*ParseDiscoveryInfo("humble", "ros_discovery_info"), GidLayout::kHumble);
  EXPECT_EQ(*ParseDiscoveryInfo("off", "ros_discovery_info"), std::nullopt);
  auto bad = ParseDiscoveryInfo("foxy", "ros_discovery_info");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("ros_discovery_info is 'foxy'"), std::string::npos)
      << bad.status();
}

// rmw's QoS for the topic: reliable, transient local, keep last 1, XCDR1; the type hash only
// where ROS 2 sends them (Iron and later).
TEST(Ros2DiscoveryInfo, QosIsRmwsReliableTransientLocalKeepLast1) {
  for (GidLayout layout : {GidLayout::kHumble, GidLayout::kIronAndLater}) {
    DdsQos q = DiscoveryInfoQos(layout);
    dds_reliability_kind_t rel;
    dds_duration_t block;
    ASSERT_TRUE(dds_qget_reliability(q.get(), &rel, &block));
    EXPECT_EQ(rel, DDS_RELIABILITY_RELIABLE);
    dds_durability_kind_t dur;
    ASSERT_TRUE(dds_qget_durability(q.get(), &dur));
    EXPECT_EQ(dur, DDS_DURABILITY_TRANSIENT_LOCAL);
    dds_history_kind_t hist;
    int32_t depth = 0;
    ASSERT_TRUE(dds_qget_history(q.get(), &hist, &depth));
    EXPECT_EQ(hist, DDS_HISTORY_KEEP_LAST);
    EXPECT_EQ(depth, 1);
    void* ud = nullptr;
    size_t size = 0;
    ASSERT_TRUE(dds_qget_userdata(q.get(), &ud, &size));
    EXPECT_EQ(std::string(static_cast<char*>(ud), size),
              layout == GidLayout::kHumble
                  ? ""
                  : TypeHashUserData(kParticipantEntitiesInfoType.type_hash()));
    dds_free(ud);
  }
}

// A sample of each layout through Cyclone's CDR and back; the bytes have the layout's Gid size.
TEST(Ros2DiscoveryInfo, EntriesRoundTripInBothLayouts) {
  ParticipantEntities e;
  e.gid = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16};
  NodeEntities node;
  node.node_namespace = "/stereo";
  node.node_name = "cloudcast_bridge";
  node.reader_gids = {std::vector<std::uint8_t>(16, 0xa1), std::vector<std::uint8_t>(16, 0xa2)};
  node.writer_gids = {std::vector<std::uint8_t>(16, 0xb1)};
  e.nodes.push_back(node);
  std::size_t sizes[2] = {};
  for (GidLayout layout : {GidLayout::kHumble, GidLayout::kIronAndLater}) {
    ParticipantEntitiesInfoSample sample(layout, e);
    const std::vector<std::uint8_t> bytes = SerializeCdr(sample.type(), sample.sample());
    sizes[layout == GidLayout::kHumble] = bytes.size();
    std::vector<std::uint8_t> storage(sample.type().descriptor->m_size + 16, 0);
    ASSERT_TRUE(DeserializeCdr(sample.type(), bytes, storage.data()).ok());
    const ParticipantEntities back = FromSample(layout, storage.data());
    FreeSample(sample.type(), storage.data());
    std::vector<std::uint8_t> gid = e.gid;
    gid.resize(GidSize(layout), 0);
    EXPECT_EQ(back.gid, gid);
    ASSERT_EQ(back.nodes.size(), 1u);
    EXPECT_EQ(back.nodes[0].node_namespace, "/stereo");
    EXPECT_EQ(back.nodes[0].node_name, "cloudcast_bridge");
    ASSERT_EQ(back.nodes[0].reader_gids.size(), 2u);
    ASSERT_EQ(back.nodes[0].writer_gids.size(), 1u);
    EXPECT_EQ(back.nodes[0].writer_gids[0].size(), GidSize(layout));
    EXPECT_EQ(back.nodes[0].writer_gids[0][15], 0xb1);
  }
  // Four Gids of 8 more bytes each in Humble's.
  EXPECT_EQ(sizes[1] - sizes[0], 4u * 8u);
}

}  // namespace
}  // namespace cloudcast::ros2_bridge
