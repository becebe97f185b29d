// The ROS 2 bridge's own parts, without DDS traffic: its command line in ROS 2's style (-p,
// --params-file, -r, __ns, __node), the parameters through the shared core's checks, the
// exact-time synchronizer, and the samples it writes.
#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <vector>

#include "bridge_options.h"
#include "help.h"
#include "ros2_inputs.h"
#include "ros_args.h"
#include "sample_views.h"

namespace cloudcast::ros2_bridge {
namespace {

absl::StatusOr<RosArgs> Parse(std::vector<std::string> args) {
  return ParseRosArgs(args, "cloudcast_bridge");
}

TEST(Ros2Args, ParametersRemapsNamespaceAndNode) {
  auto a = Parse({"--ros-args", "-p", "server:=10.0.0.2:50051", "-p", "voxel.leaf:=0.01", "-p",
                  "queue_size:=7", "-p", "compress:=true", "-p", "input:='depth'", "-r",
                  "__ns:=/camera", "-r", "__node:=cc", "-r", "points2:=/robot/cloud"});
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_EQ(a->node.node_namespace, "/camera");
  EXPECT_EQ(a->node.node_name, "cc");
  EXPECT_EQ(*ResolveTopicName("points2", a->node), "/robot/cloud");
  EXPECT_EQ(*ResolveTopicName("rgb/camera_info", a->node), "/camera/rgb/camera_info");
  EXPECT_EQ(a->params.at("server").type, ParamValue::kString);
  EXPECT_EQ(a->params.at("voxel.leaf").type, ParamValue::kDouble);
  EXPECT_EQ(a->params.at("queue_size").type, ParamValue::kInt);
  EXPECT_EQ(a->params.at("compress").type, ParamValue::kBool);
  EXPECT_EQ(a->params.at("input").s, "depth");

  Ros2ParamReader reader(a->params, {});
  auto o = ros_bridge::ReadBridgeOptions(reader, "cloudcast-ros2-bridge");
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_EQ(o->server, "10.0.0.2:50051");
  EXPECT_EQ(o->input, ros_bridge::InputKind::kDepth);
  EXPECT_EQ(o->sync.queue_size, 7);
  EXPECT_TRUE(o->compress);
  EXPECT_FLOAT_EQ(o->config.voxel_grid().leaf(), 0.01f);
}

TEST(Ros2Args, ErrorsNameTheParameterInRos2Spelling) {
  auto a = Parse({"--ros-args", "-p", "voxel.leaf:=-0.5"});
  ASSERT_TRUE(a.ok());
  auto o = ros_bridge::ReadBridgeOptions(Ros2ParamReader(a->params, {}), "cloudcast-ros2-bridge");
  ASSERT_FALSE(o.ok());
  EXPECT_NE(o.status().message().find("voxel.leaf is -0.5"), std::string::npos) << o.status();

  a = Parse({"--ros-args", "-p", "voxel.leafsize:=1"});
  o = ros_bridge::ReadBridgeOptions(Ros2ParamReader(a->params, {}), "cloudcast-ros2-bridge");
  ASSERT_FALSE(o.ok());
  EXPECT_NE(o.status().message().find("voxel.leafsize is not a parameter of cloudcast-ros2-bridge"),
            std::string::npos)
      << o.status();

  a = Parse({"--ros-args", "-p", "queue_size:=many"});
  o = ros_bridge::ReadBridgeOptions(Ros2ParamReader(a->params, {}), "cloudcast-ros2-bridge");
  ASSERT_FALSE(o.ok());
  EXPECT_NE(o.status().message().find("queue_size is 'many'; must be an integer"),
            std::string::npos)
      << o.status();

  a = Parse({"--ros-args", "-p", "stereo.matcher:=sgm"});  // input is disparity
  o = ros_bridge::ReadBridgeOptions(Ros2ParamReader(a->params, {}), "cloudcast-ros2-bridge");
  ASSERT_FALSE(o.ok());
  EXPECT_NE(o.status().message().find("stereo.matcher is set but input is 'disparity'"),
            std::string::npos)
      << o.status();

  a = Parse({"--ros-args", "-p", "input:=stereo", "-p", "stereo.num_disparities:=17"});
  o = ros_bridge::ReadBridgeOptions(Ros2ParamReader(a->params, {}), "cloudcast-ros2-bridge");
  ASSERT_FALSE(o.ok());
  EXPECT_EQ(o.status().message().rfind("stereo.*: ", 0), 0u) << o.status();

  // ROS 2's extras are not the core's unknown parameters.
  a = Parse({"--ros-args", "-p", "input_qos:=default"});
  EXPECT_TRUE(ros_bridge::ReadBridgeOptions(Ros2ParamReader(a->params, {"input_qos"}), "x").ok());
}

// rate_control (shared with the ROS 1 bridge): the stream follows the link, with delivery latest
// (set when left unset; refused with delivery all, naming both parameters).
TEST(Ros2Args, RateControlTakesDeliveryLatest) {
  auto a = Parse({"--ros-args", "-p", "rate_control:=true"});
  ASSERT_TRUE(a.ok());
  auto o = ros_bridge::ReadBridgeOptions(Ros2ParamReader(a->params, {}), "cloudcast-ros2-bridge");
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_TRUE(o->rate_control);
  EXPECT_EQ(o->config.delivery(), v1::DELIVERY_LATEST);
  a = Parse({"--ros-args", "-p", "rate_control:=true", "-p", "delivery:=all"});
  o = ros_bridge::ReadBridgeOptions(Ros2ParamReader(a->params, {}), "cloudcast-ros2-bridge");
  ASSERT_FALSE(o.ok());
  EXPECT_NE(o.status().message().find("rate_control needs delivery latest; delivery is all"),
            std::string::npos)
      << o.status();
  a = Parse({"--ros-args", "-p", "compress:=true"});
  o = ros_bridge::ReadBridgeOptions(Ros2ParamReader(a->params, {}), "cloudcast-ros2-bridge");
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_FALSE(o->rate_control);
}

TEST(Ros2Args, MalformedArgumentsAreRefused) {
  for (std::vector<std::string> bad :
       {std::vector<std::string>{"server:=x"}, {"--ros-args", "-p"}, {"--ros-args", "-p", "x"},
        {"--ros-args", "-r", "a"}, {"--ros-args", "-r", "__ns:=relative"},
        {"--ros-args", "-r", "__node:=9bad"}, {"--ros-args", "--bogus"},
        {"--ros-args", "--params-file", "/nonexistent/params.yaml"}}) {
    EXPECT_FALSE(Parse(bad).ok()) << bad.back();
  }
  EXPECT_TRUE(Parse({"--help"})->help);
}

TEST(Ros2Args, ParamsFileSectionsForThisNode) {
  NodeNames node;
  node.node_namespace = "/camera";
  node.node_name = "cloudcast_bridge";
  std::map<std::string, ParamValue> params;
  const std::string yaml = R"(
/**:
  ros__parameters:
    server: "robot-pc:50051"
    diagnostics_period: 2
/camera/cloudcast_bridge:
  ros__parameters:
    voxel:
      enabled: true
      leaf: 0.02
other_node:
  ros__parameters:
    server: "wrong:1"
)";
  ASSERT_TRUE(ReadParamsYaml(yaml, "test.yaml", node, &params).ok());
  EXPECT_EQ(params.at("server").s, "robot-pc:50051");
  EXPECT_EQ(params.at("diagnostics_period").type, ParamValue::kInt);
  EXPECT_TRUE(params.at("voxel.enabled").b);
  EXPECT_DOUBLE_EQ(params.at("voxel.leaf").d, 0.02);
  auto bad = ReadParamsYaml("cloudcast_bridge: {foo: 1}", "p.yaml", node, &params);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("p.yaml"), std::string::npos);
  EXPECT_NE(bad.message().find("ros__parameters"), std::string::npos);
  EXPECT_FALSE(ReadParamsYaml("a: [1", "q.yaml", node, &params).ok());
}

// The example parameters file the docs point to is one the bridge takes.
TEST(Ros2Args, TheExampleParamsFileIsValid) {
  auto a = Parse({"--ros-args", "--params-file", CLOUDCAST_ROS2_EXAMPLE_PARAMS, "-r",
                  "__ns:=/stereo"});
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_EQ(a->params.at("input_qos").s, "sensor_data");
  EXPECT_EQ(a->params.at("ros_discovery_info").s, "jazzy");
  auto o = ros_bridge::ReadBridgeOptions(Ros2ParamReader(a->params, Ros2BridgeParameters()), "x");
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_TRUE(o->config.voxel_grid().enabled());
  EXPECT_FLOAT_EQ(o->config.passthrough().max(), 8.0f);
}

std::shared_ptr<TakenSample> ImageAt(std::int32_t sec, std::uint32_t nanosec) {
  auto s = std::make_shared<TakenSample>(kImageType);
  auto* image = static_cast<sensor_msgs_msg_dds__Image_*>(s->get());
  image->header.stamp.sec = sec;
  image->header.stamp.nanosec = nanosec;
  return s;
}

TEST(Ros2ExactTimeSync, PairsEqualStampsAndReportsTheOnesThatNeverMatch) {
  std::vector<std::int32_t> matched;
  std::vector<std::string> errors;
  ExactTimeSync sync(
      {"/cam/disparity", "/cam/left/image_rect_color", "/cam/left/camera_info"}, 3,
      [&](ExactTimeSync::Set& set) { matched.push_back(set[0]->header().stamp.sec); },
      [&](const absl::Status& s) { errors.emplace_back(s.message()); });
  sync.Add(0, ImageAt(1, 0));
  sync.Add(1, ImageAt(1, 0));
  sync.Add(2, ImageAt(1, 0));
  EXPECT_EQ(matched, std::vector<std::int32_t>{1});
  // Stamp 2 lacks the camera_info; stamp 3 completes and drops it, naming what was missing.
  sync.Add(0, ImageAt(2, 5));
  sync.Add(1, ImageAt(2, 5));
  sync.Add(1, ImageAt(3, 0));
  sync.Add(2, ImageAt(3, 0));
  sync.Add(0, ImageAt(3, 0));
  EXPECT_EQ(matched, (std::vector<std::int32_t>{1, 3}));
  ASSERT_EQ(errors.size(), 1u);
  EXPECT_NE(errors[0].find("/cam/disparity, /cam/left/image_rect_color.header.stamp "
                           "2.000000005: no /cam/left/camera_info"),
            std::string::npos)
      << errors[0];
  // Stamps that never match: the queue holds 3, then drops the oldest.
  for (int i = 10; i < 15; ++i) sync.Add(0, ImageAt(i, 0));
  EXPECT_EQ(sync.waiting(), 3u);
  EXPECT_EQ(errors.size(), 3u);
  EXPECT_NE(errors.back().find("the queue was full"), std::string::npos);
}

TEST(Ros2Samples, PointCloud2CarriesTheInputsHeaderAndTheSharedLayout) {
  PointCloud cloud;
  cloud.points.push_back(Point{1.0f, 2.0f, 3.0f, 0xFF102030u});
  ros_bridge::MessageHeader header;
  header.stamp.sec = static_cast<std::uint32_t>(-2);  // a ROS 2 time before 1970
  header.stamp.nsec = 7;
  header.frame_id = "left_camera_optical_frame";
  PointCloud2Sample msg(cloud, header);
  const auto* s = msg.sample();
  EXPECT_EQ(s->header.stamp.sec, -2);
  EXPECT_EQ(s->header.stamp.nanosec, 7u);
  EXPECT_STREQ(s->header.frame_id, "left_camera_optical_frame");
  EXPECT_EQ(s->width, 1u);
  EXPECT_EQ(s->height, 1u);
  ASSERT_EQ(s->fields._length, 4u);
  EXPECT_STREQ(s->fields._buffer[3].name, "rgb");
  EXPECT_EQ(s->fields._buffer[3].offset, 12u);
  EXPECT_EQ(s->point_step, 16u);
  ASSERT_EQ(s->data._length, 16u);
  EXPECT_EQ(s->data._buffer[15], 0x00);  // alpha cleared
  EXPECT_EQ(s->data._buffer[12], 0x30);
  // And it serializes (the round trip through Cyclone's reader).
  const auto bytes = SerializeCdr(kPointCloud2Type, s);
  sensor_msgs_msg_dds__PointCloud2_ back{};
  ASSERT_TRUE(DeserializeCdr(kPointCloud2Type, bytes, &back).ok());
  EXPECT_EQ(back.row_step, 16u);
  FreeSample(kPointCloud2Type, &back);
}

TEST(Ros2Help, ListsEveryParameterInRos2SpellingAndTheTopics) {
  const std::string help = HelpText();
  for (const ros_bridge::ParamDoc& d : ros_bridge::ParamDocs()) {
    if (d.name == "stereo/publish_disparity") continue;  // refused by the ROS 2 bridge
    std::string name = d.name;
    std::replace(name.begin(), name.end(), '/', '.');
    EXPECT_NE(help.find("  " + name + " ("), std::string::npos) << name;
  }
  for (const char* text : {"input_qos (", "use_sim_time (", "--ros-args", "--params-file",
                           "ROS_DOMAIN_ID", "CYCLONEDDS_URI", "points2", "/diagnostics",
                           "depth_registered/image_rect", "right/camera_info"}) {
    EXPECT_NE(help.find(text), std::string::npos) << text;
  }
  EXPECT_EQ(help.find("~"), std::string::npos);  // no ROS 1 private names
}

}  // namespace
}  // namespace cloudcast::ros2_bridge
