// The ROS 2 bridge's own parts, without DDS traffic: its command line in ROS 2's style (-p,
// --params-file, -r, __ns, __node), the parameters through the shared core's checks, the
// exact-time synchronizer, and the samples it writes.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <set>
#include <string>
#include <variant>
#include <vector>

#include "bridge_options.h"
#include "cloud_link.h"
#include "help.h"
#include "ros2_inputs.h"
#include "ros_args.h"
#include "sample_views.h"
#ifdef CLOUDCAST_BRIDGE_VIDEO
#include "cloudcast/video/frame_encoder.h"
#endif
#ifdef CLOUDCAST_BRIDGE_JPEG
#include "cloudcast/client/adaptive_jpeg_coder.h"
#endif

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
  EXPECT_EQ(o->uplink, ros_bridge::Uplink::kZstd);  // compress: the old name of encoding zstd
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
  EXPECT_EQ(o->uplink, ros_bridge::Uplink::kRaw);
  EXPECT_FALSE(o->config.draco().has_max_cloud_bytes());
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


// ---- The uplink (encoding, h264.*) and the downlink cap (draco.max_reply_kb, min_color_bits),
// shared with the ROS 1 bridge (bridge/bridge_options.cc).

absl::StatusOr<ros_bridge::BridgeOptions> Read(const std::vector<std::string>& params) {
  std::vector<std::string> args = {"--ros-args"};
  for (const std::string& p : params) args.insert(args.end(), {"-p", p});
  auto a = Parse(args);
  if (!a.ok()) return a.status();
  return ros_bridge::ReadBridgeOptions(Ros2ParamReader(a->params, {}), "cloudcast-ros2-bridge");
}

std::string ErrorOf(const std::vector<std::string>& params) {
  auto o = Read(params);
  return o.ok() ? "(accepted)" : std::string(o.status().message());
}

TEST(BridgeUplink, EncodingTakesRawZstdAndH264AndNamesABadOne) {
  EXPECT_EQ(Read({})->uplink, ros_bridge::Uplink::kRaw);
  EXPECT_EQ(Read({"encoding:=zstd"})->uplink, ros_bridge::Uplink::kZstd);
  EXPECT_EQ(Read({"encoding:=raw"})->uplink, ros_bridge::Uplink::kRaw);
  EXPECT_EQ(Read({"encoding:=zstd", "compress:=true"})->uplink, ros_bridge::Uplink::kZstd);
  EXPECT_EQ(ErrorOf({"encoding:=vp9"}), "encoding is 'vp9'; must be raw, zstd, h264 or jpeg");
  EXPECT_EQ(ErrorOf({"encoding:=h264", "compress:=true"}),
            "compress is true (the old name of encoding zstd) but encoding is 'h264'; drop "
            "compress");
  // An h264 setting without encoding h264 would be silently ignored: refused, naming both.
  EXPECT_EQ(ErrorOf({"h264.crf:=20"}),
            "h264.crf is set but encoding is 'raw'; it applies to encoding h264 only");
  EXPECT_EQ(ErrorOf({"compress:=true", "h264.mbps:=2.0"}),
            "h264.mbps is set but encoding is 'zstd'; it applies to encoding h264 only");
}

TEST(BridgeUplink, H264SettingsAreCheckedByTheFlagsRulesNamingTheParameter) {
  if (!ros_bridge::HasVideoEncoder()) {
    EXPECT_NE(ErrorOf({"encoding:=h264"}).find("built without the video encoder"),
              std::string::npos);
    GTEST_SKIP() << "this build has no video encoder (CLOUDCAST_WITH_VIDEO off)";
  }
  const std::vector<std::pair<std::vector<std::string>, std::string>> bad = {
      {{"h264.preset:=placebo"},
       "h264.preset is 'placebo'; must be ultrafast, superfast, veryfast, faster, fast or medium"},
      {{"h264.crf:=52.0"}, "h264.crf is 52; must be 0 or a quality in [1, 51]"},
      {{"h264.crf:=-1"}, "h264.crf is -1; must be 0 or a quality in [1, 51]"},
      {{"h264.mbps:=0.01"}, "h264.mbps is 0.01; must be a bitrate in [0.05, 1000] Mbit/s"},
      {{"h264.fps:=0"}, "h264.fps is 0; must be in [1, 1000] frames a second"},
      {{"h264.keyframe_interval:=-1"}, "h264.keyframe_interval is -1; must be in 0..100000"},
      {{"h264.threads:=17"}, "h264.threads is 17; must be in 1..16"},
      {{"h264.threads:=two"}, "h264.threads is 'two'; must be an integer"},
      {{"h264.grey:=3"}, "h264.grey"},
      {{"h264.separate_stereo:=true"},
       "h264.separate_stereo is set but input is 'disparity'; it applies to input stereo only"},
  };
  for (const auto& [params, message] : bad) {
    std::vector<std::string> with = params;
    with.push_back("encoding:=h264");
    const std::string error = ErrorOf(with);
    EXPECT_EQ(error.rfind(message, 0), 0u) << params[0] << ": " << error;
  }
}

TEST(BridgeUplink, H264SettingsReachTheStreamsEncoder) {
  if (!ros_bridge::HasVideoEncoder()) GTEST_SKIP() << "this build has no video encoder";
  auto o = Read({"input:=stereo", "encoding:=h264", "h264.preset:=ultrafast", "h264.crf:=0",
                 "h264.mbps:=2.5",
                 "h264.fps:=15.0", "h264.keyframe_interval:=30", "h264.threads:=2",
                 "h264.colour_444:=true", "h264.grey:=false", "h264.separate_stereo:=true",
                 "rate_control:=true"});
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_EQ(o->uplink, ros_bridge::Uplink::kH264);
  EXPECT_EQ(o->h264.preset, "ultrafast");
  EXPECT_EQ(o->h264.crf, 0);
  EXPECT_EQ(o->h264.mbps, 2.5);
  EXPECT_EQ(o->h264_fps, 15);
  EXPECT_EQ(o->h264.keyframe_interval, 30);
  EXPECT_EQ(o->h264.threads, 2);
  EXPECT_TRUE(o->h264.colour_444);
  EXPECT_TRUE(o->h264.separate_stereo);
#ifdef CLOUDCAST_BRIDGE_VIDEO
  // The one mapping the programs' --h264-* flags use (video::ToFrameEncoderOptions).
  const video::FrameEncoderOptions e = video::ToFrameEncoderOptions(o->h264, o->h264_fps);
  EXPECT_EQ(e.encoder.preset, "ultrafast");
  EXPECT_EQ(e.encoder.crf, 0);
  EXPECT_EQ(e.encoder.bitrate_bps, 2'500'000);
  EXPECT_EQ(e.encoder.fps, 15);
  EXPECT_EQ(e.encoder.keyframe_interval, 30);
  EXPECT_EQ(e.encoder.threads, 2);
  EXPECT_EQ(e.colour_kind, video::PictureKind::kColour444);
  EXPECT_FALSE(e.interleave_stereo);
  EXPECT_FALSE(e.grey);
  // The stream the link opens: the encoder as its coder, and the rate controller driving it.
  auto so = ros_bridge::StreamOptionsFor(*o, CameraModel{});
  ASSERT_TRUE(so.ok()) << so.status();
  ASSERT_NE(so->coder, nullptr);
  EXPECT_NE(dynamic_cast<video::FrameEncoder*>(so->coder.get()), nullptr);
  EXPECT_TRUE(so->rate_control.has_value());
  EXPECT_EQ(o->config.delivery(), v1::DELIVERY_LATEST);
  // Each stream its own encoder (a new stream starts at an IDR).
  EXPECT_NE(ros_bridge::StreamOptionsFor(*o, CameraModel{})->coder, so->coder);
#endif
  // Without h264 there is no coder.
  auto raw = Read({"encoding:=zstd"});
  ASSERT_TRUE(raw.ok());
  auto plain = ros_bridge::StreamOptionsFor(*raw, CameraModel{});
  ASSERT_TRUE(plain.ok());
  EXPECT_EQ(plain->coder, nullptr);
  EXPECT_FALSE(plain->rate_control.has_value());
}

TEST(BridgeDownlinkCap, MaxReplyKbAndMinColorBitsReachTheStreamConfig) {
  auto o = Read({"draco.max_reply_kb:=12.5", "draco.min_color_bits:=4"});
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_EQ(o->config.draco().max_cloud_bytes(), 12500u);
  EXPECT_EQ(o->config.draco().min_color_bits(), 4);
  o = Read({"draco.max_reply_kb:=20"});  // an integer, as YAML writes it
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_EQ(o->config.draco().max_cloud_bytes(), 20000u);
  EXPECT_FALSE(o->config.draco().has_min_color_bits());
  o = Read({"draco.max_reply_kb:=0"});  // no cap
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_FALSE(o->config.draco().has_max_cloud_bytes());
  o = Read({});
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_FALSE(o->config.draco().has_max_cloud_bytes());
}

TEST(BridgeDownlinkCap, BadValuesAreRefusedNamingTheParameter) {
  EXPECT_EQ(ErrorOf({"draco.max_reply_kb:=0.01"}).rfind("draco.max_reply_kb is 0.01; it must be 0 "
                                                        "(no cap) or a number of kB",
                                                        0),
            0u)
      << ErrorOf({"draco.max_reply_kb:=0.01"});
  EXPECT_EQ(ErrorOf({"draco.max_reply_kb:=-5"}).rfind("draco.max_reply_kb is -5", 0), 0u);
  EXPECT_EQ(ErrorOf({"draco.max_reply_kb:=5000000.0"}).rfind("draco.max_reply_kb is 5", 0), 0u)
      << ErrorOf({"draco.max_reply_kb:=5000000.0"});
  EXPECT_EQ(ErrorOf({"draco.max_reply_kb:=big"}),
            "draco.max_reply_kb is 'big'; must be a number");
  EXPECT_EQ(ErrorOf({"draco.max_reply_kb:=10", "draco.min_color_bits:=9"}),
            "draco.min_color_bits is 9; must be in 1..8");
  EXPECT_EQ(ErrorOf({"draco.max_reply_kb:=10", "draco.min_color_bits:=0"}),
            "draco.min_color_bits is 0; must be in 1..8");
  EXPECT_EQ(ErrorOf({"draco.min_color_bits:=4"}),
            "draco.min_color_bits needs draco.max_reply_kb (the cap it is the floor of)");
  EXPECT_EQ(ErrorOf({"draco.max_reply_kb:=10", "draco.cap_min_points:=65"}),
            "draco.cap_min_points is 65; must be in 0..64");
  EXPECT_EQ(ErrorOf({"draco.max_reply_kb:=10", "draco.cap_min_points:=-1"}),
            "draco.cap_min_points is -1; must be in 0..64");
  EXPECT_EQ(ErrorOf({"draco.cap_min_points:=2"}),
            "draco.cap_min_points needs draco.max_reply_kb or rate_control (a cap to meet)");
}

// Contract revision 5: the cap may drop the sparsest voxels, with a cap set or controlled.
TEST(BridgeDownlinkCap, CapMinPointsReachesTheStreamConfigWithACap) {
  auto o = Read({"draco.max_reply_kb:=12.5", "draco.cap_min_points:=2"});
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_EQ(o->config.draco().cap_min_points_per_voxel(), 2u);
  o = Read({"rate_control:=true", "draco.cap_min_points:=3"});
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_EQ(o->config.draco().cap_min_points_per_voxel(), 3u);
  o = Read({"draco.max_reply_kb:=12.5"});
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_FALSE(o->config.draco().has_cap_min_points_per_voxel());
}

// The docs the help prints carry the new parameters (docs/ros.md and docs/ros2.md list them too).
TEST(BridgeUplink, ParamDocsListTheUplinkAndCapParameters) {
  std::set<std::string> names;
  for (const ros_bridge::ParamDoc& d : ros_bridge::ParamDocs()) names.insert(d.name);
  for (const char* name :
       {"encoding", "compress", "h264/preset", "h264/crf", "h264/mbps", "h264/fps",
        "h264/keyframe_interval", "h264/threads", "h264/colour_444", "h264/grey",
        "h264/separate_stereo", "draco/max_reply_kb", "draco/min_color_bits",
        "draco/cap_min_points", "jpeg/quality", "jpeg/min_quality", "jpeg/max_quality",
        "jpeg/half_resolution", "jpeg/fps"}) {
    EXPECT_EQ(names.count(name), 1u) << name;
  }
}

// ---- encoding jpeg: client::AdaptiveJpegCoder as the stream's coder (jpeg.*), shared with the
// ROS 1 bridge (bridge/bridge_options.cc, bridge/cloud_link.cc).

TEST(BridgeJpeg, SettingsAreCheckedNamingTheParameter) {
  if (!ros_bridge::HasJpegEncoder()) {
    EXPECT_NE(ErrorOf({"encoding:=jpeg"}).find("built without the JPEG coder"), std::string::npos);
    GTEST_SKIP() << "this build has no JPEG coder (OpenCV)";
  }
  const std::vector<std::pair<std::vector<std::string>, std::string>> bad = {
      // A jpeg setting with another encoding would be silently ignored.
      {{"jpeg.quality:=80"},
       "jpeg.quality is set but encoding is 'raw'; it applies to encoding jpeg only"},
      {{"encoding:=h264", "jpeg.fps:=15.0"},
       "jpeg.fps is set but encoding is 'h264'; it applies to encoding jpeg only"},
      {{"encoding:=jpeg", "h264.crf:=20.0"},
       "h264.crf is set but encoding is 'jpeg'; it applies to encoding h264 only"},
      // The follower's settings without rate_control: every frame goes at jpeg.quality.
      {{"encoding:=jpeg", "jpeg.min_quality:=20"},
       "jpeg.min_quality needs rate_control true (without it every frame goes at jpeg.quality)"},
      {{"encoding:=jpeg", "jpeg.max_quality:=90"},
       "jpeg.max_quality needs rate_control true (without it every frame goes at jpeg.quality)"},
      {{"encoding:=jpeg", "jpeg.half_resolution:=false"},
       "jpeg.half_resolution needs rate_control true"},
      {{"encoding:=jpeg", "jpeg.fps:=15.0"}, "jpeg.fps needs rate_control true"},
      // Ranges and types.
      {{"encoding:=jpeg", "jpeg.quality:=0"}, "jpeg.quality is 0; must be in 1..100"},
      {{"encoding:=jpeg", "jpeg.quality:=101"}, "jpeg.quality is 101; must be in 1..100"},
      {{"encoding:=jpeg", "jpeg.quality:=high"}, "jpeg.quality is 'high'; must be an integer"},
      {{"encoding:=jpeg", "rate_control:=true", "jpeg.min_quality:=-3"},
       "jpeg.min_quality is -3; must be in 1..100"},
      {{"encoding:=jpeg", "rate_control:=true", "jpeg.fps:=0.5"},
       "jpeg.fps is 0.5; must be in [1, 1000] frames a second"},
      {{"encoding:=jpeg", "rate_control:=true", "jpeg.min_quality:=50", "jpeg.quality:=40"},
       "jpeg.min_quality <= jpeg.quality <= jpeg.max_quality must hold with rate_control; they "
       "are 50, 40, 95"},
      {{"encoding:=jpeg", "rate_control:=true", "jpeg.max_quality:=80"},
       "jpeg.min_quality <= jpeg.quality <= jpeg.max_quality must hold with rate_control; they "
       "are 10, 90, 80"},
      // A pair's calibration is the server's: no half-resolution floor for pairs.
      {{"encoding:=jpeg", "rate_control:=true", "input:=stereo", "jpeg.half_resolution:=true"},
       "jpeg.half_resolution is set but input is 'stereo'; the half-resolution floor is for "
       "disparity and depth frames only"},
  };
  for (const auto& [params, message] : bad) {
    EXPECT_EQ(ErrorOf(params), message) << params.back();
  }
}

TEST(BridgeJpeg, SettingsAndTheCameraReachTheStreamsCoder) {
  if (!ros_bridge::HasJpegEncoder()) GTEST_SKIP() << "this build has no JPEG coder (OpenCV)";
  auto o = Read({"encoding:=jpeg", "rate_control:=true", "jpeg.quality:=70",
                 "jpeg.min_quality:=25", "jpeg.max_quality:=85", "jpeg.half_resolution:=false",
                 "jpeg.fps:=15"});  // an integer, as YAML writes it
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_EQ(o->uplink, ros_bridge::Uplink::kJpeg);
  EXPECT_EQ(o->jpeg.quality, 70);
  EXPECT_EQ(o->jpeg.min_quality, 25);
  EXPECT_EQ(o->jpeg.max_quality, 85);
  EXPECT_FALSE(o->jpeg.half_resolution);
  EXPECT_EQ(o->jpeg.fps, 15.0);
  EXPECT_EQ(o->config.delivery(), v1::DELIVERY_LATEST);
  // Unset: AdaptiveJpegOptions' defaults (cloudcast-client's).
  auto d = Read({"encoding:=jpeg", "rate_control:=true"});
  ASSERT_TRUE(d.ok()) << d.status();
#ifdef CLOUDCAST_BRIDGE_JPEG
  const client::AdaptiveJpegOptions lib;
  EXPECT_EQ(d->jpeg.quality, lib.start_quality);
  EXPECT_EQ(d->jpeg.min_quality, lib.min_quality);
  EXPECT_EQ(d->jpeg.max_quality, lib.max_quality);
  EXPECT_EQ(d->jpeg.half_resolution, lib.half_resolution_floor);
  EXPECT_EQ(d->jpeg.fps, lib.fps);

  CameraModel camera;
  camera.fx = 600;
  camera.fy = 590;
  camera.cx = 300;
  camera.cy = 200;
  camera.baseline = 0.1;
  auto so = ros_bridge::StreamOptionsFor(*o, camera);
  ASSERT_TRUE(so.ok()) << so.status();
  ASSERT_TRUE(so->rate_control.has_value());
  auto* coder = dynamic_cast<client::AdaptiveJpegCoder*>(so->coder.get());
  ASSERT_NE(coder, nullptr);
  // Each stream its own coder.
  EXPECT_NE(ros_bridge::StreamOptionsFor(*o, camera)->coder, so->coder);

  // The coder at work on a 4x2 disparity + colour frame: without a target it keeps the start
  // quality (jpeg.quality), the colour as a JPEG, the disparity lossless.
  std::vector<float> disparity(8, 20.0f);
  std::vector<std::uint8_t> colour(4 * 2 * 3, 128);
  DisparityView dv;
  dv.data = disparity.data();
  dv.width = 4;
  dv.height = 2;
  dv.stride_bytes = 4 * sizeof(float);
  dv.size_bytes = disparity.size() * sizeof(float);
  dv.encoding = DisparityEncoding::kF32;
  ColorView cv;
  cv.data = colour.data();
  cv.width = 4;
  cv.height = 2;
  cv.stride_bytes = 4 * 3;
  cv.size_bytes = colour.size();
  cv.encoding = ColorEncoding::kBGR8;
  auto coded = coder->Encode(client::DisparityFrame{dv, cv}, 0);
  ASSERT_TRUE(coded.ok()) << coded.status();
  EXPECT_EQ(coder->last_quality(), 70);
  EXPECT_FALSE(coder->last_half());
  const auto* frame = std::get_if<client::DisparityFrame>(&*coded);
  ASSERT_NE(frame, nullptr);
  EXPECT_TRUE(std::holds_alternative<client::EncodedImage>(frame->colour));
  EXPECT_EQ(coder->last_resolution().divisor, 1);
#endif

  // Without rate_control: jpeg.quality alone, a coder without a controller (fixed quality).
  auto fixed = Read({"encoding:=jpeg", "jpeg.quality:=60"});
  ASSERT_TRUE(fixed.ok()) << fixed.status();
  EXPECT_EQ(fixed->jpeg.quality, 60);
  auto fso = ros_bridge::StreamOptionsFor(*fixed, CameraModel{});
  ASSERT_TRUE(fso.ok()) << fso.status();
  EXPECT_NE(fso->coder, nullptr);
  EXPECT_FALSE(fso->rate_control.has_value());
}

#ifdef CLOUDCAST_BRIDGE_JPEG
// A camera that changes mid-stream (a new CameraInfo): the link hands it to the coder from that
// frame on (AdaptiveJpegCoder::SetCamera), and a half-resolution frame carries it halved.
TEST(BridgeJpeg, AHalfResolutionFrameCarriesItsOwnCameraHalved) {
  auto o = Read({"encoding:=jpeg", "rate_control:=true", "jpeg.quality:=10"});
  ASSERT_TRUE(o.ok()) << o.status();
  CameraModel first;
  first.fx = first.fy = 600;
  auto so = ros_bridge::StreamOptionsFor(*o, first);
  ASSERT_TRUE(so.ok()) << so.status();
  auto* coder = dynamic_cast<client::AdaptiveJpegCoder*>(so->coder.get());
  ASSERT_NE(coder, nullptr);
  CameraModel second = first;
  second.fx = second.fy = 1200;
  coder->SetCamera(3, ros_bridge::CameraProto(second));

  std::vector<float> disparity(8, 20.0f);
  std::vector<std::uint8_t> colour(4 * 2 * 3, 128);
  DisparityView dv;
  dv.data = disparity.data();
  dv.size_bytes = disparity.size() * sizeof(float);
  dv.width = 4;
  dv.height = 2;
  dv.stride_bytes = 4 * sizeof(float);
  dv.encoding = DisparityEncoding::kF32;
  ColorView cv;
  cv.data = colour.data();
  cv.size_bytes = colour.size();
  cv.width = 4;
  cv.height = 2;
  cv.stride_bytes = 4 * 3;
  cv.encoding = ColorEncoding::kBGR8;
  std::vector<double> fx;  // each frame's camera fx (0: the caller's, full resolution)
  for (std::uint64_t seq = 0; seq < 5; ++seq) {
    // A target far under any frame: at the lowest quality, the floor.
    coder->SetStreamBitrate(1000, 0);
    ASSERT_TRUE(coder->Encode(client::DisparityFrame{dv, cv}, seq).ok());
    const client::FrameCoder::Resolution r = coder->last_resolution();
    fx.push_back(r.camera ? r.camera->fx() : 0.0);
    if (r.camera) {
      EXPECT_EQ(r.divisor, 2);
    }
  }
  // Frame 0 has no target yet; then half resolution, the first camera's fx halved until frame 3.
  EXPECT_EQ(fx, (std::vector<double>{0, 300, 300, 600, 600}));
}
#endif

}  // namespace
}  // namespace cloudcast::ros2_bridge
