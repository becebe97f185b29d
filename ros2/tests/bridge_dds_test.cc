// cloudcast-ros2-bridge end to end inside a network namespace of its own (unshare -n, loopback
// with multicast: DDS discovery stays in it): a camera publishing New Tsukuba frames on DDS with
// ROS 2's conventions, the bridge (its own process) with a cloudcast server, and a subscriber of
// its PointCloud2 and /diagnostics. The clouds must equal, byte for byte, what the ROS 1 bridge
// publishes for the same frames (its link to the server and its PointCloud2 conversion, run here
// in-process). The camera publishes continuously and the test asserts on later samples: a
// reader still in discovery may miss the first ones (cyclonedds#1110).
//
// Negative cases: an XCDR2 writer and a best-effort camera against input_qos default match no
// reader (the bridge says so on /diagnostics); bad messages give a /diagnostics error naming the
// message and field, and the bridge goes on.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_join.h"
#include "bridge_options.h"
#include "cloud_link.h"
#include "cloudcast/datasets/tsukuba.h"
#include "dds_node.h"
#include "discovery_info.h"
#include "frame_conversions.h"
#include "point_cloud2.h"
#include "ros2_harness.h"
#include "ros2_inputs.h"
#include "ros_args.h"
#include "ros_messages.h"
#include "sample_views.h"
#include "support/program_support.h"
#include "support/server_fixture.h"
#include "tsukuba_samples.h"

namespace cloudcast::ros2_bridge {
namespace {

using Clock = std::chrono::steady_clock;
using testing::TsukubaSamples;

// ---- The network namespace: entered by the process before any test (and any thread) starts.

std::string g_netns_problem = "not set up";

class NetnsEnvironment : public ::testing::Environment {
 public:
  void SetUp() override { g_netns_problem = testing::EnterNetworkNamespace(); }
};
const auto* const g_netns = ::testing::AddGlobalTestEnvironment(new NetnsEnvironment);

// ---- The camera and the subscriber, on a DDS participant of the test's own.

// The camera's writers: the disparity (or the depth image, or the left image of a pair), the
// colour (or the right image), the CameraInfo (the left one) and, for pairs, the right one.
struct CameraWriters {
  dds_entity_t disparity = 0, colour = 0, info = 0, right_info = 0;
};

enum class Input { kDisparity, kDepth, kStereo };

// A writer as rmw makes it, optionally best effort or XCDR2 (the negative cases).
dds_entity_t Writer(DdsNode* node, const MessageType& type, const std::string& topic,
                    bool reliable, bool xcdr2) {
  const dds_entity_t t = dds_create_topic(node->participant(), type.descriptor,
                                          DdsTopicName(topic).c_str(), nullptr, nullptr);
  QosProfile profile = reliable ? DefaultQos() : SensorDataQos();
  DdsQos qos = EndpointQos(profile, type.type_hash());
  if (xcdr2) {
    dds_data_representation_id_t x2 = DDS_DATA_REPRESENTATION_XCDR2;
    dds_qset_data_representation(qos.get(), 1, &x2);
  }
  return dds_create_writer(node->participant(), t, qos.get(), nullptr);
}

struct Received {
  std::vector<std::shared_ptr<TakenSample>> clouds;
  std::vector<std::string> diagnostics;  // each status's message and last_error
  std::vector<std::map<std::string, std::string>> values;  // each status's values, by key
};

class Ros2BridgeTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    const std::string dir = tsukuba::DefaultDir();
    if (!tsukuba::Present(dir)) return;
    for (const char* id : {"00001", "00200", "00400"}) {
      auto f = tsukuba::Load(dir, id);
      if (f.ok()) frames_->push_back(*std::move(f));
      auto pair = tsukuba::LoadStereo(dir, id);
      if (pair.ok()) rights_->push_back(std::move(pair->right));
    }
  }

  void SetUp() override {
    if (!g_netns_problem.empty()) GTEST_SKIP() << g_netns_problem;
    if (frames_->empty()) GTEST_SKIP() << "the New Tsukuba sample is not in " << tsukuba::DefaultDir();
    scratch_ = std::filesystem::path(::testing::TempDir()) /
               ("ros2_bridge_" + std::to_string(getpid()));
    std::filesystem::create_directories(scratch_);
    server_ = cloudcast::testing::StartTestServer();
    ASSERT_NE(server_, nullptr);
    for (std::size_t i = 0; i < frames_->size(); ++i) samples_.push_back(NewSamples(i));
    auto node = DdsNode::Create(0);
    ASSERT_TRUE(node.ok()) << node.status();
    camera_ = *std::move(node);
    auto points = camera_->CreateReader(kPointCloud2Type, "/stereo/points2", DefaultQos());
    ASSERT_TRUE(points.ok()) << points.status();
    points_ = *points;
    auto diag = camera_->CreateReader(kDiagnosticArrayType, "/diagnostics", DefaultQos());
    ASSERT_TRUE(diag.ok()) << diag.status();
    diagnostics_ = *diag;
  }

  void TearDown() override {
    bridge_.reset();
    camera_.reset();
    server_.reset();
    if (!scratch_.empty()) std::filesystem::remove_all(scratch_);
  }

  void StartBridge(std::vector<std::string> params, const std::string& ns = "/stereo") {
    std::vector<std::string> args = {"--ros-args", "-r", "__ns:=" + ns, "-p",
                                     "server:=" + server_->address(), "-p",
                                     "diagnostics_period:=0.3"};
    for (const auto& p : params) {
      args.push_back("-p");
      args.push_back(p);
    }
    // This build's bridge, or another build's (CLOUDCAST_ROS2_BRIDGE: the arm64 cross build)
    // under an emulator (CLOUDCAST_ROS2_BRIDGE_EMULATOR: qemu-aarch64-static), as
    // Arm64Client.Ros2BridgeCarriesDdsTrafficUnderQemu runs these tests.
    const char* program = std::getenv("CLOUDCAST_ROS2_BRIDGE");
    args.insert(args.begin(), program != nullptr
                                  ? program
                                  : cloudcast::testing::BinDir() + "/cloudcast-ros2-bridge");
    if (const char* emulator = std::getenv("CLOUDCAST_ROS2_BRIDGE_EMULATOR")) {
      args.insert(args.begin(), emulator);
    }
    if (program != nullptr) std::cout << "[ bridge   ] " << absl::StrJoin(args, " ") << "\n";
    bridge_ = std::make_unique<testing::ChildProcess>(args, (scratch_ / "bridge.log").string());
    ASSERT_TRUE(bridge_->started());
  }

  CameraWriters Camera(bool reliable = true, bool xcdr2 = false) {
    CameraWriters w;
    w.disparity = Writer(camera_.get(), kDisparityImageType, "/stereo/disparity", reliable, xcdr2);
    w.colour = Writer(camera_.get(), kImageType, "/stereo/left/image_rect_color", reliable, xcdr2);
    w.info = Writer(camera_.get(), kCameraInfoType, "/stereo/left/camera_info", reliable, xcdr2);
    EXPECT_GT(w.disparity, 0);
    EXPECT_GT(w.colour, 0);
    EXPECT_GT(w.info, 0);
    return w;
  }

  // Frame k of the run: frames_[k % n], stamped 1000 + k s.
  void Publish(const CameraWriters& w, int k,
               const std::function<void(TsukubaSamples&)>& spoil = nullptr) {
    TsukubaSamples& s = *samples_[static_cast<std::size_t>(k) % samples_.size()];
    s.Stamp(1000 + k, 0);
    if (spoil) spoil(s);
    switch (input_) {
      case Input::kDisparity:
        dds_write(w.disparity, &s.disparity);
        dds_write(w.colour, &s.colour);
        break;
      case Input::kDepth:
        dds_write(w.disparity, &s.depth);
        dds_write(w.colour, &s.colour);
        break;
      case Input::kStereo:
        dds_write(w.disparity, &s.colour);
        dds_write(w.colour, &s.right);
        dds_write(w.right_info, &s.right_info);
        break;
    }
    dds_write(w.info, &s.info);
    if (spoil) {
      const std::size_t i = static_cast<std::size_t>(k) % samples_.size();
      samples_[i] = NewSamples(i);
    }
  }

  void Take(Received* r) {
    for (;;) {
      auto s = std::make_shared<TakenSample>(kPointCloud2Type);
      void* buf[1] = {s->get()};
      dds_sample_info_t info;
      if (dds_take(points_, buf, &info, 1, 1) <= 0) break;
      if (info.valid_data) r->clouds.push_back(s);
    }
    for (;;) {
      TakenSample s(kDiagnosticArrayType);
      void* buf[1] = {s.get()};
      dds_sample_info_t info;
      if (dds_take(diagnostics_, buf, &info, 1, 1) <= 0) break;
      if (!info.valid_data) continue;
      const auto& a = s.as<diagnostic_msgs_msg_dds__DiagnosticArray_>();
      for (std::uint32_t i = 0; i < a.status._length; ++i) {
        const auto& st = a.status._buffer[i];
        std::string text = std::string(st.name) + " | " + st.message;
        std::map<std::string, std::string>& values = r->values.emplace_back();
        for (std::uint32_t j = 0; j < st.values._length; ++j) {
          values[st.values._buffer[j].key] = st.values._buffer[j].value;
          if (std::string(st.values._buffer[j].key) == "last_error") {
            text += " | last_error: " + std::string(st.values._buffer[j].value);
          }
        }
        r->diagnostics.push_back(text);
      }
    }
  }

  // Frame i's samples (with its right image, when the pair is there).
  std::unique_ptr<TsukubaSamples> NewSamples(std::size_t i) {
    auto s = std::make_unique<TsukubaSamples>((*frames_)[i]);
    if (i < rights_->size()) s->AddRight((*rights_)[i]);
    return s;
  }

  // A stereo camera's four topics under /stereo, as stereo_image_proc takes them.
  CameraWriters StereoCamera() {
    CameraWriters w;
    w.disparity = Writer(camera_.get(), kImageType, "/stereo/left/image_rect_color", true, false);
    w.colour = Writer(camera_.get(), kImageType, "/stereo/right/image_rect", true, false);
    w.info = Writer(camera_.get(), kCameraInfoType, "/stereo/left/camera_info", true, false);
    w.right_info = Writer(camera_.get(), kCameraInfoType, "/stereo/right/camera_info", true, false);
    return w;
  }

  CameraWriters DepthCamera() {
    CameraWriters w;
    w.disparity = Writer(camera_.get(), kImageType, "/camera/depth_registered/image_rect", true,
                         false);
    w.colour = Writer(camera_.get(), kImageType, "/camera/rgb/image_rect_color", true, false);
    w.info = Writer(camera_.get(), kCameraInfoType, "/camera/rgb/camera_info", true, false);
    return w;
  }

  // Publishes a frame every 50 ms (spoiled by `spoil` when given) until `done` holds or
  // `seconds` pass; returns whether `done` held.
  bool PublishUntil(const CameraWriters& w, Received* r, const std::function<bool()>& done,
                    double seconds, const std::function<void(TsukubaSamples&)>& spoil = nullptr) {
    const auto end = Clock::now() + std::chrono::duration<double>(seconds);
    while (Clock::now() < end) {
      Publish(w, next_frame_++, spoil);
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      Take(r);
      if (done()) return true;
      if (!bridge_->running()) {
        ADD_FAILURE() << "the bridge exited:\n" << bridge_->Log();
        return false;
      }
    }
    return false;
  }

  static bool DiagnosticsMention(const Received& r, const std::string& text) {
    for (const auto& d : r.diagnostics) {
      if (d.find(text) != std::string::npos) return true;
    }
    return false;
  }

  // What the ROS 1 bridge publishes for frame i: its link to the server (CloudLink, the same
  // options) and its PointCloud2 conversion.
  // `extra`: the bridge's parameters beyond server, passthrough and voxel grid ("name:=value").
  // `report`: the link's /diagnostics values after the frames (uplink_bytes_per_cloud, ...).
  std::vector<sensor_msgs::PointCloud2> Ros1Clouds(
      Input input = Input::kDisparity, const std::vector<std::string>& extra = {},
      std::map<std::string, std::string>* report_values = nullptr) {
    // The bridge's parameters (kUnfiltered): the whole cloud, not what the server's default
    // passthrough and voxel grid leave.
    std::map<std::string, ParamValue> params;
    params["server"].s = server_->address();
    for (const char* name : {"passthrough.enabled", "voxel.enabled"}) {
      params[name].type = ParamValue::kBool;
      params[name].b = false;
    }
    std::vector<std::string> args = {"--ros-args"};
    for (const std::string& p : extra) args.insert(args.end(), {"-p", p});
    auto parsed = ParseRosArgs(args, "reference");
    EXPECT_TRUE(parsed.ok()) << parsed.status();
    if (parsed.ok()) params.insert(parsed->params.begin(), parsed->params.end());
    auto options = ros_bridge::ReadBridgeOptions(Ros2ParamReader(params, {}), "test");
    EXPECT_TRUE(options.ok()) << options.status();
    options->config.set_delivery(v1::DELIVERY_ALL);
    ros_bridge::BridgeStats stats;
    std::mutex mu;
    std::map<std::uint32_t, sensor_msgs::PointCloud2> clouds;
    {
      ros_bridge::CloudLink link(*options, &stats,
                                 [&](client::Result&& r, const ros_bridge::SentFrame& f) {
                                   sensor_msgs::PointCloud2 msg;
                                   ros_bridge::ToPointCloud2(r.cloud, ros_bridge::ToRos(f.header),
                                                             &msg);
                                   std::lock_guard<std::mutex> lock(mu);
                                   clouds[f.header.stamp.sec] = std::move(msg);
                                 },
                                 [](ros_bridge::LogLevel, const std::string& line) {
                                   std::fprintf(stderr, "reference link: %s\n", line.c_str());
                                 });
      EXPECT_TRUE(link.Probe().ok());
      std::vector<float> masked;
      for (std::size_t i = 0; i < samples_.size(); ++i) {
        samples_[i]->Stamp(static_cast<std::int32_t>(i), 0);
        ros_bridge::OutgoingFrame frame;
        const TsukubaSamples& in = *samples_[i];
        absl::Status s;
        switch (input) {
          case Input::kDisparity:
            s = ros_bridge::ToFrame(View(in.disparity), View(in.colour), View(in.info), &masked,
                                    &frame);
            break;
          case Input::kDepth:
            s = ros_bridge::ToDepthFrame(View(in.depth), View(in.colour), View(in.info),
                                         std::nullopt, &frame);
            break;
          case Input::kStereo:
            s = ros_bridge::ToStereoFrame(View(in.colour), View(in.right), View(in.info),
                                          View(in.right_info), &frame);
            break;
        }
        EXPECT_TRUE(s.ok()) << s;
        link.Send(frame);
      }
    }  // the link's destructor waits for the replies
    const auto report = stats.Report(0, "reference", "");
    for (const auto& [key, value] : report.values) {
      if (key == "last_error") ADD_FAILURE() << "the reference link: " << value;
      if (report_values != nullptr) (*report_values)[key] = value;
    }
    std::vector<sensor_msgs::PointCloud2> out;
    for (std::size_t i = 0; i < samples_.size(); ++i) out.push_back(clouds[i]);
    return out;
  }

  static inline std::vector<tsukuba::Frame>* frames_ = new std::vector<tsukuba::Frame>();
  static inline std::vector<OwnedColor>* rights_ = new std::vector<OwnedColor>();
  std::filesystem::path scratch_;
  std::unique_ptr<server::Server> server_;
  std::vector<std::unique_ptr<TsukubaSamples>> samples_;
  std::unique_ptr<DdsNode> camera_;
  dds_entity_t points_ = 0, diagnostics_ = 0;
  std::unique_ptr<testing::ChildProcess> bridge_;
  int next_frame_ = 0;
  Input input_ = Input::kDisparity;  // what Publish writes
};

TEST_F(Ros2BridgeTest, CycloneCameraCloudsEqualTheRos1BridgesPointForPoint) {
  const std::vector<sensor_msgs::PointCloud2> expected = Ros1Clouds();
  ASSERT_EQ(expected.size(), samples_.size());
  for (const auto& e : expected) ASSERT_GT(e.width, 100000u);
  // Reliable at both ends (input_qos default): no sample is lost, so every later set matches.
  StartBridge({"passthrough.enabled:=false", "voxel.enabled:=false", "input_qos:=default"});
  const CameraWriters w = Camera();
  Received r;
  // Later samples: clouds of at least 2 x the frames after the first one that came.
  ASSERT_TRUE(PublishUntil(w, &r, [&] { return r.clouds.size() >= 2 * samples_.size() + 1; }, 40))
      << r.clouds.size() << " clouds\n" << bridge_->Log();
  for (std::size_t c = 1; c < r.clouds.size(); ++c) {
    const auto& got = r.clouds[c]->as<sensor_msgs_msg_dds__PointCloud2_>();
    const int k = got.header.stamp.sec - 1000;
    ASSERT_GE(k, 0);
    const sensor_msgs::PointCloud2& want = expected[static_cast<std::size_t>(k) % expected.size()];
    EXPECT_STREQ(got.header.frame_id, testing::kFrameId);
    EXPECT_EQ(got.header.stamp.nanosec, 0u);
    EXPECT_EQ(got.height, want.height);
    EXPECT_EQ(got.width, want.width);
    EXPECT_EQ(got.point_step, want.point_step);
    EXPECT_EQ(got.row_step, want.row_step);
    EXPECT_EQ(got.is_dense, static_cast<bool>(want.is_dense));
    EXPECT_EQ(got.is_bigendian, static_cast<bool>(want.is_bigendian));
    ASSERT_EQ(got.fields._length, want.fields.size());
    for (std::size_t f = 0; f < want.fields.size(); ++f) {
      EXPECT_EQ(got.fields._buffer[f].name, want.fields[f].name);
      EXPECT_EQ(got.fields._buffer[f].offset, want.fields[f].offset);
      EXPECT_EQ(got.fields._buffer[f].datatype, want.fields[f].datatype);
      EXPECT_EQ(got.fields._buffer[f].count, want.fields[f].count);
    }
    ASSERT_EQ(got.data._length, want.data.size());
    EXPECT_EQ(std::memcmp(got.data._buffer, want.data.data(), want.data.size()), 0)
        << "cloud of stamp " << got.header.stamp.sec;
  }
  EXPECT_TRUE(DiagnosticsMention(r, "/stereo/cloudcast_bridge: cloudcast stream | streaming"))
      << (r.diagnostics.empty() ? "no diagnostics" : r.diagnostics.back()) << "\n"
      << bridge_->Log();
}

// input depth: a depth camera's 16UC1 image, colour and CameraInfo (depth_image_proc's names
// under /camera), the same equality with the ROS 1 bridge's clouds.
TEST_F(Ros2BridgeTest, DepthCameraCloudsEqualTheRos1BridgesPointForPoint) {
  const std::vector<sensor_msgs::PointCloud2> expected = Ros1Clouds(Input::kDepth);
  for (const auto& e : expected) ASSERT_GT(e.width, 100000u);
  // The reader of the clouds, under /camera.
  auto points = camera_->CreateReader(kPointCloud2Type, "/camera/points2", DefaultQos());
  ASSERT_TRUE(points.ok());
  points_ = *points;
  StartBridge({"input:=depth", "passthrough.enabled:=false", "voxel.enabled:=false",
               "input_qos:=default"},
              "/camera");
  input_ = Input::kDepth;
  const CameraWriters w = DepthCamera();
  Received r;
  ASSERT_TRUE(PublishUntil(w, &r, [&] { return r.clouds.size() >= samples_.size() + 1; }, 40))
      << r.clouds.size() << " clouds\n" << bridge_->Log();
  for (std::size_t c = 1; c < r.clouds.size(); ++c) {
    const auto& got = r.clouds[c]->as<sensor_msgs_msg_dds__PointCloud2_>();
    const int k = got.header.stamp.sec - 1000;
    ASSERT_GE(k, 0);
    const sensor_msgs::PointCloud2& want = expected[static_cast<std::size_t>(k) % expected.size()];
    EXPECT_STREQ(got.header.frame_id, testing::kFrameId);
    ASSERT_EQ(got.data._length, want.data.size());
    EXPECT_EQ(std::memcmp(got.data._buffer, want.data.data(), want.data.size()), 0)
        << "cloud of stamp " << got.header.stamp.sec;
  }
}

// input stereo: a stereo camera's rectified left (bgr8) and right (mono8) images with both
// CameraInfos, exact-time synchronised, matched on the server (sgm, 160 disparities: New
// Tsukuba's reach 146); the clouds equal the ROS 1 bridge's for the same pairs, point for point.
TEST_F(Ros2BridgeTest, StereoCameraCloudsEqualTheRos1BridgesPointForPoint) {
  if (rights_->size() != frames_->size()) {
    GTEST_SKIP() << "the New Tsukuba right images are not in " << tsukuba::DefaultDir();
  }
  const std::vector<std::string> stereo = {"input:=stereo", "stereo.matcher:=sgm",
                                           "stereo.num_disparities:=160"};
  const std::vector<sensor_msgs::PointCloud2> expected = Ros1Clouds(Input::kStereo, stereo);
  ASSERT_EQ(expected.size(), samples_.size());
  for (const auto& e : expected) ASSERT_GT(e.width, 50000u);
  std::vector<std::string> params = {"passthrough.enabled:=false", "voxel.enabled:=false",
                                     "input_qos:=default"};
  params.insert(params.end(), stereo.begin(), stereo.end());
  StartBridge(params);
  input_ = Input::kStereo;
  const CameraWriters w = StereoCamera();
  Received r;
  // Clouds of at least two different pairs (after the first cloud): a loaded machine's server
  // matches slower than the camera publishes, the bridge sends the newest pair each time, and its
  // clouds may then come from every second frame, one pair only (1 of 4 runs beside six busy
  // processes on two cores).
  const auto pairs_seen = [&] {
    std::set<int> seen;
    for (std::size_t c = 1; c < r.clouds.size(); ++c) {
      const auto& got = r.clouds[c]->as<sensor_msgs_msg_dds__PointCloud2_>();
      seen.insert((got.header.stamp.sec - 1000) % static_cast<int>(expected.size()));
    }
    return seen.size();
  };
  ASSERT_TRUE(PublishUntil(
      w, &r, [&] { return r.clouds.size() >= samples_.size() + 1 && pairs_seen() >= 2; }, 50))
      << r.clouds.size() << " clouds\n" << bridge_->Log();
  std::set<int> frames_seen;
  for (std::size_t c = 1; c < r.clouds.size(); ++c) {
    const auto& got = r.clouds[c]->as<sensor_msgs_msg_dds__PointCloud2_>();
    const int k = got.header.stamp.sec - 1000;
    ASSERT_GE(k, 0);
    frames_seen.insert(k % static_cast<int>(expected.size()));
    const sensor_msgs::PointCloud2& want = expected[static_cast<std::size_t>(k) % expected.size()];
    EXPECT_STREQ(got.header.frame_id, testing::kFrameId);
    EXPECT_EQ(got.width, want.width);
    ASSERT_EQ(got.data._length, want.data.size());
    EXPECT_EQ(std::memcmp(got.data._buffer, want.data.data(), want.data.size()), 0)
        << "cloud of stamp " << got.header.stamp.sec;
  }
  EXPECT_GE(frames_seen.size(), 2u) << "the clouds came from one pair only";
}

// Each frame carries its CameraInfo's camera (Frame.camera): frames of the same images whose
// CameraInfo alternates between f = 615 and f = 1230 (a zoom; DisparityImage's f T unchanged, so
// z stays and x, y halve) come back each with its own camera, in order, on one stream.
TEST_F(Ros2BridgeTest, EachFrameIsProjectedWithItsOwnCameraInfo) {
  std::map<std::string, ParamValue> params;
  params["server"].s = server_->address();
  for (const char* name : {"passthrough.enabled", "voxel.enabled"}) {
    params[name].type = ParamValue::kBool;
    params[name].b = false;
  }
  // Sequential Draco coding (point order kept) with fine quantization: the clouds compare
  // point for point.
  params["draco.encode_speed"].type = params["draco.decode_speed"].type = ParamValue::kInt;
  params["draco.encode_speed"].i = params["draco.decode_speed"].i = 10;
  params["draco.position_bits"].type = ParamValue::kInt;
  params["draco.position_bits"].i = 20;
  auto options = ros_bridge::ReadBridgeOptions(Ros2ParamReader(params, {}), "test");
  ASSERT_TRUE(options.ok()) << options.status();
  options->config.set_delivery(v1::DELIVERY_ALL);
  ros_bridge::BridgeStats stats;
  std::mutex mu;
  std::map<std::uint32_t, PointCloud> clouds;  // by stamp
  {
    ros_bridge::CloudLink link(
        *options, &stats,
        [&](client::Result&& r, const ros_bridge::SentFrame& f) {
          std::lock_guard<std::mutex> lock(mu);
          clouds[f.header.stamp.sec] = std::move(r.cloud);
        },
        [](ros_bridge::LogLevel, const std::string&) {});
    ASSERT_TRUE(link.Probe().ok());
    TsukubaSamples& in = *samples_[0];
    std::vector<float> masked;
    for (std::int32_t k = 0; k < 4; ++k) {
      in.Stamp(k, 0);
      const double f = (k % 2 == 0) ? testing::kF : 2 * testing::kF;
      in.info.k[0] = in.info.k[4] = in.info.p[0] = in.info.p[5] = f;
      ros_bridge::OutgoingFrame frame;
      ASSERT_TRUE(ros_bridge::ToFrame(View(in.disparity), View(in.colour), View(in.info), &masked,
                                      &frame)
                      .ok());
      link.Send(frame);
    }
  }
  ASSERT_EQ(clouds.size(), 4u);
  const PointCloud& wide = clouds[0];
  ASSERT_GT(wide.size(), 100000u);
  for (std::uint32_t k = 1; k < 4; ++k) {
    const PointCloud& c = clouds[k];
    ASSERT_EQ(c.size(), wide.size()) << k;
    const float scale = (k % 2 == 0) ? 1.0f : 0.5f;
    std::size_t off = 0;
    for (std::size_t i = 0; i < c.size(); ++i) {
      const Point& a = wide.points[i];
      const Point& b = c.points[i];
      if (std::fabs(b.z - a.z) > 1e-3f || std::fabs(b.x - scale * a.x) > 1e-3f ||
          std::fabs(b.y - scale * a.y) > 1e-3f) {
        ++off;
      }
    }
    EXPECT_EQ(off, 0u) << "frame " << k << " (f = " << (k % 2 ? 1230 : 615) << ")";
  }
}

// ---- The video uplink (encoding h264) and the downlink cap (draco.max_reply_kb), parameters
// both bridges share (bridge/bridge_options.cc).

// The bridge with encoding h264 under rate_control (the rate controller sets the encoder's
// bitrate frame by frame): the server decodes the colour pictures, and the clouds have the raw
// uplink's geometry exactly (the disparity map stays lossless) and its colours nearly (H.264 is
// lossy, so some differ: the pictures did travel as video).
TEST_F(Ros2BridgeTest, H264UplinkGivesTheRawGeometryAndNearlyItsColours) {
  const std::vector<sensor_msgs::PointCloud2> expected = Ros1Clouds();
  ASSERT_EQ(expected.size(), samples_.size());
  StartBridge({"passthrough.enabled:=false", "voxel.enabled:=false", "input_qos:=default",
               "encoding:=h264", "h264.preset:=ultrafast", "h264.crf:=18", "h264.mbps:=8.0",
               "h264.fps:=20.0", "rate_control:=true"});
  const CameraWriters w = Camera();
  Received r;
  // The rate controller ran: /diagnostics carries its target (once a reply has come).
  const auto target_seen = [&] {
    for (const auto& v : r.values) {
      auto it = v.find("target_kbps");
      if (it != v.end() && std::stod(it->second) > 0) return true;
    }
    return false;
  };
  ASSERT_TRUE(PublishUntil(
      w, &r, [&] { return r.clouds.size() >= samples_.size() + 2 && target_seen(); }, 40))
      << r.clouds.size() << " clouds, target_kbps on /diagnostics: " << target_seen() << "\n"
      << bridge_->Log();
  double colour_diff = 0;
  std::size_t channels = 0;
  for (std::size_t c = 1; c < r.clouds.size(); ++c) {
    const auto& got = r.clouds[c]->as<sensor_msgs_msg_dds__PointCloud2_>();
    const int k = got.header.stamp.sec - 1000;
    ASSERT_GE(k, 0);
    const sensor_msgs::PointCloud2& want = expected[static_cast<std::size_t>(k) % expected.size()];
    ASSERT_GT(want.width, 100000u);
    ASSERT_EQ(got.width, want.width) << "cloud of stamp " << got.header.stamp.sec;
    ASSERT_EQ(got.point_step, 16u);
    ASSERT_EQ(got.data._length, want.data.size());
    std::size_t xyz_off = 0;
    for (std::size_t i = 0; i < got.width; ++i) {
      const std::uint8_t* a = got.data._buffer + 16 * i;
      const std::uint8_t* b = want.data.data() + 16 * i;
      if (std::memcmp(a, b, 12) != 0) ++xyz_off;
      for (int ch = 12; ch < 15; ++ch) colour_diff += std::abs(int(a[ch]) - int(b[ch]));
      channels += 3;
    }
    EXPECT_EQ(xyz_off, 0u) << "cloud of stamp " << got.header.stamp.sec;
  }
  ASSERT_GT(channels, 0u);
  const double mean = colour_diff / static_cast<double>(channels);
  EXPECT_GT(mean, 0.0) << "the colours are exact: the pictures did not travel as H.264";
  // Under rate_control the encoder gets the controller's target less the lossless disparity
  // map's bytes (at 20 frames/s those alone exceed the 4 Mbit/s start), so it starts at its
  // floor: the colours are coarse, far nearer than another frame's (tens of levels) all the same.
  EXPECT_LT(mean, 20.0) << "mean colour error per channel, 8-bit levels";
  std::fprintf(stderr, "H.264 uplink: %zu clouds, mean colour error %.2f levels per channel\n",
               r.clouds.size() - 1, mean);
  EXPECT_NE(bridge_->Log().find("encoding h264"), std::string::npos) << bridge_->Log();
}

// ---- encoding jpeg (client::AdaptiveJpegCoder as the stream's coder, bridge/cloud_link.cc).

// x, y and z of each of `n` points `step` bytes apart (a PointCloud2's data: xyz first).
std::vector<std::array<float, 3>> Points(const std::uint8_t* data, std::size_t n,
                                         std::size_t step) {
  std::vector<std::array<float, 3>> out(n);
  for (std::size_t i = 0; i < n; ++i) std::memcpy(out[i].data(), data + step * i, 12);
  return out;
}

// The smallest and largest x, y and z of `points`.
std::array<std::array<float, 3>, 2> Bounds(const std::vector<std::array<float, 3>>& points) {
  std::array<std::array<float, 3>, 2> b;
  for (int a = 0; a < 3; ++a) {
    b[0][a] = std::numeric_limits<float>::infinity();
    b[1][a] = -std::numeric_limits<float>::infinity();
  }
  for (const auto& p : points) {
    for (int a = 0; a < 3; ++a) {
      if (!std::isfinite(p[a])) continue;
      b[0][a] = std::min(b[0][a], p[a]);
      b[1][a] = std::max(b[1][a], p[a]);
    }
  }
  return b;
}

// The bridge with encoding jpeg under rate_control on loopback: its clouds come back, each
// frame costs the uplink fewer bytes than the zstd encoding's (the server's count, on
// /diagnostics), the disparity stays lossless (a full-resolution cloud's points are the raw
// uplink's exactly) and /diagnostics carries the coder's quality and resolution.
TEST_F(Ros2BridgeTest, JpegUnderRateControlSendsFewerBytesThanZstdWithTheSameGeometry) {
  std::map<std::string, std::string> zstd_report;
  const std::vector<sensor_msgs::PointCloud2> expected =
      Ros1Clouds(Input::kDisparity, {"encoding:=zstd"}, &zstd_report);
  ASSERT_EQ(expected.size(), samples_.size());
  const double zstd_bytes = std::stod(zstd_report.at("uplink_bytes_per_cloud"));
  ASSERT_GT(zstd_bytes, 100000) << "a lossless 640x480 disparity + colour frame";
  StartBridge({"passthrough.enabled:=false", "voxel.enabled:=false", "input_qos:=default",
               "encoding:=jpeg", "rate_control:=true", "jpeg.fps:=20.0"});
  const CameraWriters w = Camera();
  Received r;
  // The reports of periods with clouds: their uplink bytes and the coder's state.
  const auto reports = [&] {
    std::vector<std::map<std::string, std::string>> out;
    for (const auto& v : r.values) {
      auto it = v.find("uplink_bytes_per_cloud");
      if (it != v.end() && std::stod(it->second) > 0 && v.count("jpeg_quality")) out.push_back(v);
    }
    return out;
  };
  // A stream may start at the half-resolution floor (at 20 frames/s the controller's 4 Mbit/s
  // start is under the lossless 32FC1 disparity map) and comes back to full resolution as the
  // target grows on loopback (about a second): the run goes on until full-resolution clouds
  // come after any half-resolution ones.
  const auto full_at_the_end = [&] {
    std::size_t full_run = 0;  // full-resolution clouds since the last half-resolution one
    for (std::size_t c = 1; c < r.clouds.size(); ++c) {
      const auto& got = r.clouds[c]->as<sensor_msgs_msg_dds__PointCloud2_>();
      const int k = got.header.stamp.sec - 1000;
      const bool full =
          k >= 0 && got.width == expected[static_cast<std::size_t>(k) % expected.size()].width;
      full_run = full ? full_run + 1 : 0;
    }
    return full_run >= 3;
  };
  ASSERT_TRUE(PublishUntil(
      w, &r,
      [&] {
        return r.clouds.size() >= samples_.size() + 4 && reports().size() >= 2 &&
               full_at_the_end();
      },
      40))
      << r.clouds.size() << " clouds, the last ones at full resolution: " << full_at_the_end()
      << ", " << reports().size() << " reports with uplink bytes\n"
      << bridge_->Log();
  double most = 0;
  for (const auto& v : reports()) {
    const double bytes = std::stod(v.at("uplink_bytes_per_cloud"));
    most = std::max(most, bytes);
    EXPECT_LT(bytes, zstd_bytes) << "uplink bytes per cloud, jpeg against zstd";
    const int quality = std::stoi(v.at("jpeg_quality"));
    EXPECT_GE(quality, 10);
    EXPECT_LE(quality, 95);
    EXPECT_TRUE(v.at("half_resolution") == "true" || v.at("half_resolution") == "false");
    EXPECT_GT(std::stod(v.at("target_kbps")), 0);
  }
  std::size_t full = 0, half = 0;
  for (std::size_t c = 1; c < r.clouds.size(); ++c) {
    const auto& got = r.clouds[c]->as<sensor_msgs_msg_dds__PointCloud2_>();
    const int k = got.header.stamp.sec - 1000;
    ASSERT_GE(k, 0);
    const sensor_msgs::PointCloud2& want = expected[static_cast<std::size_t>(k) % expected.size()];
    ASSERT_GT(want.width, 100000u);
    ASSERT_EQ(got.point_step, 16u);
    if (got.width != want.width) {
      // A half-resolution frame (the coder's floor): a quarter of the pixels.
      EXPECT_LT(got.width, want.width / 3) << "cloud of stamp " << got.header.stamp.sec;
      ++half;
      continue;
    }
    ++full;
    std::size_t xyz_off = 0;
    for (std::size_t i = 0; i < got.width; ++i) {
      if (std::memcmp(got.data._buffer + 16 * i, want.data.data() + 16 * i, 12) != 0) ++xyz_off;
    }
    EXPECT_EQ(xyz_off, 0u) << "cloud of stamp " << got.header.stamp.sec;
  }
  EXPECT_GT(full, 0u) << "on loopback the target carries full-resolution frames";
  std::fprintf(stderr,
               "JPEG uplink under rate control (loopback): %zu clouds (%zu at full resolution, "
               "%zu at half), at most %.0f bytes a cloud against zstd's %.0f\n",
               full + half, full, half, most, zstd_bytes);
  EXPECT_NE(bridge_->Log().find("encoding jpeg"), std::string::npos) << bridge_->Log();
}

// The coder's floor: a target too low for even the lossless disparity map at full resolution
// (rate.max_mbps 0.5 at 20 frames/s: about 3 KB a frame) sends frames at half resolution, each
// with its camera halved, so the cloud covers the same scene with a quarter of the points;
// /diagnostics says so.
TEST_F(Ros2BridgeTest, JpegFloorSendsHalfResolutionFramesWithTheirCameraHalved) {
  const std::vector<sensor_msgs::PointCloud2> expected = Ros1Clouds();
  ASSERT_EQ(expected.size(), samples_.size());
  StartBridge({"passthrough.enabled:=false", "voxel.enabled:=false", "input_qos:=default",
               "encoding:=jpeg", "rate_control:=true", "jpeg.fps:=20.0", "rate.start_mbps:=0.3",
               "rate.max_mbps:=0.5"});
  const CameraWriters w = Camera();
  Received r;
  const auto half_reported = [&] {
    for (const auto& v : r.values) {
      auto it = v.find("half_resolution_clouds");
      if (it != v.end() && std::stoul(it->second) > 0 && v.at("half_resolution") == "true") {
        return true;
      }
    }
    return false;
  };
  const auto half_clouds = [&] {
    std::size_t n = 0;
    for (std::size_t c = 1; c < r.clouds.size(); ++c) {
      const auto& got = r.clouds[c]->as<sensor_msgs_msg_dds__PointCloud2_>();
      if (got.width < expected[0].width / 3) ++n;
    }
    return n;
  };
  ASSERT_TRUE(PublishUntil(w, &r, [&] { return half_reported() && half_clouds() >= 3; }, 40))
      << r.clouds.size() << " clouds, " << half_clouds() << " at half resolution; reported: "
      << half_reported() << "\n"
      << bridge_->Log();
  std::size_t checked = 0;
  for (std::size_t c = 1; c < r.clouds.size(); ++c) {
    const auto& got = r.clouds[c]->as<sensor_msgs_msg_dds__PointCloud2_>();
    const int k = got.header.stamp.sec - 1000;
    ASSERT_GE(k, 0);
    const sensor_msgs::PointCloud2& want = expected[static_cast<std::size_t>(k) % expected.size()];
    if (got.width >= want.width / 3) continue;
    ASSERT_GT(got.width, want.width / 5) << "a quarter of the pixels, about";
    // The same scene: with the full camera on the half image, x and y would span half the
    // width and height, and off-centre; with the camera halved the bounds agree.
    const auto a = Bounds(Points(got.data._buffer, std::size_t{got.width} * got.height,
                                 got.point_step));
    const auto b = Bounds(Points(want.data.data(), std::size_t{want.width} * want.height,
                                 want.point_step));
    for (int axis = 0; axis < 3; ++axis) {
      const float extent = b[1][axis] - b[0][axis];
      ASSERT_GT(extent, 0.0f);
      EXPECT_NEAR(a[0][axis], b[0][axis], 0.05f * extent) << "axis " << axis << ", stamp " << k;
      EXPECT_NEAR(a[1][axis], b[1][axis], 0.05f * extent) << "axis " << axis << ", stamp " << k;
    }
    ++checked;
  }
  EXPECT_GE(checked, 3u);
}

// draco.max_reply_kb and draco.min_color_bits reach the server through the bridges' link: each
// reply is within the cap or says it is over (CloudReply.over_cap), the colour bits the server
// chose never go below the floor, and the capped clouds are smaller than the uncapped ones.
TEST_F(Ros2BridgeTest, DownlinkCapParametersReachTheServer) {
  // The bridge's link (CloudLink) with these parameters: the replies, by stamp.
  const auto replies = [&](const std::vector<std::string>& extra) {
    std::map<std::uint32_t, v1::CloudReply> out;
    auto parsed = ParseRosArgs([&] {
      std::vector<std::string> args = {"--ros-args", "-p", "server:=" + server_->address()};
      for (const std::string& p : extra) args.insert(args.end(), {"-p", p});
      return args;
    }(), "reference");
    EXPECT_TRUE(parsed.ok()) << parsed.status();
    if (!parsed.ok()) return out;
    auto options = ros_bridge::ReadBridgeOptions(Ros2ParamReader(parsed->params, {}), "test");
    EXPECT_TRUE(options.ok()) << options.status();
    if (!options.ok()) return out;
    options->config.set_delivery(v1::DELIVERY_ALL);
    ros_bridge::BridgeStats stats;
    std::mutex mu;
    {
      ros_bridge::CloudLink link(
          *options, &stats,
          [&](client::Result&& r, const ros_bridge::SentFrame& f) {
            std::lock_guard<std::mutex> lock(mu);
            out[f.header.stamp.sec] = r.reply;
          },
          [](ros_bridge::LogLevel, const std::string& line) {
            std::fprintf(stderr, "link: %s\n", line.c_str());
          });
      EXPECT_TRUE(link.Probe().ok());
      std::vector<float> masked;
      for (std::size_t i = 0; i < samples_.size(); ++i) {
        samples_[i]->Stamp(static_cast<std::int32_t>(i), 0);
        ros_bridge::OutgoingFrame frame;
        const TsukubaSamples& in = *samples_[i];
        EXPECT_TRUE(ros_bridge::ToFrame(View(in.disparity), View(in.colour), View(in.info),
                                        &masked, &frame)
                        .ok());
        link.Send(frame);
      }
    }
    return out;
  };
  // No passthrough and no voxel grid: frame 00001's 307,200 points, hundreds of kB of Draco.
  const std::vector<std::string> unfiltered = {"passthrough.enabled:=false",
                                               "voxel.enabled:=false"};
  const auto uncapped = replies(unfiltered);
  ASSERT_EQ(uncapped.size(), samples_.size());
  for (const auto& [stamp, reply] : uncapped) {
    std::fprintf(stderr, "uncapped %u: %zu bytes, position bits %d, colour bits %d\n", stamp,
                 reply.draco().size(), reply.position_bits(), reply.color_bits());
  }
  const std::uint64_t cap = 200000;
  std::vector<std::string> with_cap = unfiltered;
  with_cap.insert(with_cap.end(), {"draco.max_reply_kb:=200", "draco.min_color_bits:=3"});
  const auto capped = replies(with_cap);
  for (const auto& [stamp, reply] : capped) {
    std::fprintf(stderr, "capped %u: %zu bytes, position bits %d, colour bits %d, over cap %d\n",
                 stamp, reply.draco().size(), reply.position_bits(), reply.color_bits(),
                 reply.has_over_cap());
  }
  ASSERT_EQ(capped.size(), samples_.size());
  ASSERT_GT(uncapped.at(0).draco().size(), 2 * cap) << "frame 00001 is too small to cap";
  EXPECT_EQ(uncapped.at(0).color_bits(), 8);
  EXPECT_FALSE(uncapped.at(0).has_over_cap());
  for (const auto& [stamp, reply] : capped) {
    if (reply.has_over_cap()) {
      EXPECT_EQ(reply.over_cap().max_cloud_bytes(), cap) << stamp;
      EXPECT_EQ(reply.over_cap().cloud_bytes(), reply.draco().size()) << stamp;
    } else {
      EXPECT_LE(reply.draco().size(), cap) << stamp;
    }
    EXPECT_GE(reply.color_bits(), 3) << stamp;
    EXPECT_LE(reply.draco().size(), uncapped.at(stamp).draco().size()) << stamp;
  }
  // Frame 00001: the server gave up position or colour bits to come down.
  const v1::CloudReply& first = capped.at(0);
  EXPECT_LT(first.draco().size(), uncapped.at(0).draco().size());
  EXPECT_TRUE(first.color_bits() < 8 || first.position_bits() < uncapped.at(0).position_bits())
      << "colour bits " << first.color_bits() << ", position bits " << first.position_bits();
}

// ---- ros_discovery_info: the bridge's entry, read by a plain Cyclone reader as rmw's graph
// cache reads it, against what DDS's own discovery (the built-in topics) says of the bridge's
// participant, writers and readers.

// The GUIDs DDS discovery reports on `builtin` (DCPSPublication or DCPSSubscription) for
// endpoints of the participant `participant_guid` whose topic starts with "rt/" (the node's, not
// the ros_discovery_info writer itself).
std::set<std::vector<std::uint8_t>> DiscoveredEndpoints(dds_entity_t reader,
                                                        const std::vector<std::uint8_t>& participant,
                                                        std::size_t gid_size) {
  std::set<std::vector<std::uint8_t>> out;
  void* samples[64] = {nullptr};
  dds_sample_info_t infos[64];
  const dds_return_t n = dds_read(reader, samples, infos, 64, 64);
  for (dds_return_t i = 0; i < n; ++i) {
    if (!infos[i].valid_data) continue;
    const auto* e = static_cast<const dds_builtintopic_endpoint_t*>(samples[i]);
    if (std::memcmp(e->participant_key.v, participant.data(), 16) != 0) continue;
    if (std::string(e->topic_name).rfind("rt/", 0) != 0) continue;
    std::vector<std::uint8_t> gid(gid_size, 0);
    std::memcpy(gid.data(), e->key.v, 16);
    out.insert(gid);
  }
  if (n > 0) dds_return_loan(reader, samples, n);
  return out;
}

void ExpectDiscoveryEntry(GidLayout layout, DdsNode* camera,
                          const std::function<void(std::vector<std::string>)>& start,
                          const std::function<std::string()>& log) {
  const MessageType& type = ParticipantEntitiesInfoType(layout);
  const dds_entity_t topic = dds_create_topic(camera->participant(), type.descriptor,
                                              kDiscoveryInfoTopic, nullptr, nullptr);
  ASSERT_GT(topic, 0);
  DdsQos qos = DiscoveryInfoQos(layout);
  const dds_entity_t reader = dds_create_reader(camera->participant(), topic, qos.get(), nullptr);
  ASSERT_GT(reader, 0);
  const dds_entity_t pubs =
      dds_create_reader(camera->participant(), DDS_BUILTIN_TOPIC_DCPSPUBLICATION, nullptr, nullptr);
  const dds_entity_t subs = dds_create_reader(camera->participant(),
                                              DDS_BUILTIN_TOPIC_DCPSSUBSCRIPTION, nullptr, nullptr);
  ASSERT_GT(pubs, 0);
  ASSERT_GT(subs, 0);
  start({std::string("ros_discovery_info:=") + std::string(Name(layout))});
  // The entry, and DDS discovery's view of the same participant (3 readers, 2 writers).
  std::optional<ParticipantEntities> entry;
  std::set<std::vector<std::uint8_t>> writers, readers;
  const auto end = Clock::now() + std::chrono::seconds(20);
  while (Clock::now() < end) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    for (;;) {
      TakenSample sample(type);
      void* buf[1] = {sample.get()};
      dds_sample_info_t info;
      if (dds_take(reader, buf, &info, 1, 1) <= 0) break;
      if (!info.valid_data) continue;
      ParticipantEntities e = FromSample(layout, sample.get());
      if (e.nodes.size() == 1 && e.nodes[0].node_name == "cloudcast_bridge") entry = e;
    }
    if (!entry) continue;
    writers = DiscoveredEndpoints(pubs, entry->gid, GidSize(layout));
    readers = DiscoveredEndpoints(subs, entry->gid, GidSize(layout));
    if (writers.size() >= 2 && readers.size() >= 3) break;
  }
  ASSERT_TRUE(entry.has_value()) << "no ros_discovery_info entry of the bridge\n" << log();
  // The participant's GID: its GUID (known to DDS discovery), zero-padded.
  ASSERT_EQ(entry->gid.size(), GidSize(layout));
  for (std::size_t i = 16; i < entry->gid.size(); ++i) EXPECT_EQ(entry->gid[i], 0) << i;
  const NodeEntities& node = entry->nodes[0];
  EXPECT_EQ(node.node_namespace, "/stereo");
  EXPECT_EQ(node.node_name, "cloudcast_bridge");
  // Its writers (rt/stereo/points2, rt/diagnostics) and readers (the disparity input's three),
  // GID for GID as DDS discovery reports them.
  const std::set<std::vector<std::uint8_t>> listed_writers(node.writer_gids.begin(),
                                                           node.writer_gids.end());
  const std::set<std::vector<std::uint8_t>> listed_readers(node.reader_gids.begin(),
                                                           node.reader_gids.end());
  EXPECT_EQ(node.writer_gids.size(), 2u);
  EXPECT_EQ(node.reader_gids.size(), 3u);
  EXPECT_EQ(listed_writers, writers);
  EXPECT_EQ(listed_readers, readers);
}

TEST_F(Ros2BridgeTest, RosDiscoveryInfoListsTheNodeAndItsEndpointsJazzy) {
  ExpectDiscoveryEntry(
      GidLayout::kIronAndLater, camera_.get(),
      [&](std::vector<std::string> p) { StartBridge(std::move(p)); }, [&] { return bridge_->Log(); });
}

TEST_F(Ros2BridgeTest, RosDiscoveryInfoListsTheNodeAndItsEndpointsHumble) {
  ExpectDiscoveryEntry(
      GidLayout::kHumble, camera_.get(),
      [&](std::vector<std::string> p) { StartBridge(std::move(p)); }, [&] { return bridge_->Log(); });
}

#ifdef CLOUDCAST_ROS2_FASTDDS_PEER
// The other vendor, both ways: a Fast DDS camera (ros2-fastdds-peer, Fast DDS's own CDR of
// fastddsgen's types) into the bridge, the bridge's clouds into a Fast DDS reader; the clouds as
// the Fast DDS reader decoded them equal the ROS 1 bridge's.
TEST_F(Ros2BridgeTest, FastDdsCameraAndSubscriberGetTheRos1BridgesClouds) {
  const std::vector<sensor_msgs::PointCloud2> expected = Ros1Clouds();
  StartBridge({"passthrough.enabled:=false", "voxel.enabled:=false", "input_qos:=default"});
  const std::string out = (scratch_ / "fastdds").string();
  std::filesystem::create_directories(out);
  const auto r = cloudcast::testing::RunProgram(
      cloudcast::testing::BinDir() + "/ros2-fastdds-peer",
      {"--data", tsukuba::DefaultDir(), "--namespace", "/stereo", "--clouds", "6", "--out", out,
       "--seconds", "90"},
      scratch_.string());
  ASSERT_TRUE(r.exited && r.code == 0) << r << "\n" << bridge_->Log();
  int compared = 0;
  for (const auto& entry : std::filesystem::directory_iterator(out)) {
    if (entry.path().extension() != ".bin") continue;
    const int k = std::stoi(entry.path().stem().string()) - 1000;
    ASSERT_GE(k, 0);
    const sensor_msgs::PointCloud2& want = expected[static_cast<std::size_t>(k) % expected.size()];
    const std::string data = cloudcast::testing::ReadText(entry.path().string());
    ASSERT_EQ(data.size(), want.data.size()) << entry.path();
    EXPECT_EQ(std::memcmp(data.data(), want.data.data(), data.size()), 0) << entry.path();
    std::string txt = cloudcast::testing::ReadText(
        (entry.path().parent_path() / (entry.path().stem().string() + ".txt")).string());
    const std::string fields = " x:0:7:1 y:4:7:1 z:8:7:1 rgb:12:7:1\n";
    EXPECT_EQ(txt, std::string(testing::kFrameId) + " 0 1 " + std::to_string(want.width) +
                       " 16 " + std::to_string(want.row_step) + " 1 0" + fields);
    ++compared;
  }
  EXPECT_EQ(compared, 6);
}

// Samples that are no valid CDR (a Fast DDS writer of random bytes under the DisparityImage type
// name) never reach the bridge: Cyclone's reader checks every sample against the type and drops
// them. The bridge keeps running and turns the good camera's frames into clouds meanwhile.
TEST_F(Ros2BridgeTest, NonCdrBytesAreDroppedAndTheBridgeGoesOn) {
  StartBridge({});
  const CameraWriters w = Camera();
  Received r;
  ASSERT_TRUE(PublishUntil(w, &r, [&] { return !r.clouds.empty(); }, 40)) << bridge_->Log();
  std::thread garbage([&] {
    const auto g = cloudcast::testing::RunProgram(
        cloudcast::testing::BinDir() + "/ros2-fastdds-peer",
        {"--namespace", "/stereo", "--garbage", "4"}, scratch_.string());
    EXPECT_TRUE(g.exited && g.code == 0) << g;
  });
  // A reader of the same topic here: it must match the garbage writer (else the test proves
  // nothing) and receive only the camera's valid samples.
  auto witness = camera_->CreateReader(kDisparityImageType, "/stereo/disparity", SensorDataQos());
  ASSERT_TRUE(witness.ok());
  const std::size_t before = r.clouds.size();
  std::uint32_t most_writers = 0;
  int valid = 0;
  const auto end = Clock::now() + std::chrono::seconds(4);
  while (Clock::now() < end) {
    Publish(w, next_frame_++);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    Take(&r);
    dds_subscription_matched_status_t matched;
    if (dds_get_subscription_matched_status(*witness, &matched) == DDS_RETCODE_OK) {
      most_writers = std::max(most_writers, matched.current_count);
    }
    for (;;) {
      TakenSample sample(kDisparityImageType);
      void* buf[1] = {sample.get()};
      dds_sample_info_t info;
      if (dds_take(*witness, buf, &info, 1, 1) <= 0) break;
      if (!info.valid_data) continue;
      EXPECT_GE(sample.header().stamp.sec, 1000);
      EXPECT_STREQ(sample.header().frame_id, testing::kFrameId);
      ++valid;
    }
  }
  garbage.join();
  EXPECT_EQ(most_writers, 2u) << "the garbage writer never matched";
  EXPECT_GT(valid, 0);
  EXPECT_TRUE(bridge_->running()) << bridge_->Log();
  EXPECT_GT(r.clouds.size(), before + 10) << bridge_->Log();
}
#endif

TEST_F(Ros2BridgeTest, AnXcdr2CameraMatchesNoReaderAndTheBridgeSaysSo) {
  StartBridge({});
  const CameraWriters w = Camera(/*reliable=*/true, /*xcdr2=*/true);
  Received r;
  const bool said = PublishUntil(
      w, &r, [&] { return DiagnosticsMention(r, "data representation is not XCDR1"); }, 20);
  EXPECT_TRUE(said) << bridge_->Log();
  EXPECT_TRUE(r.clouds.empty());
}

TEST_F(Ros2BridgeTest, ABestEffortCameraAgainstReliableInputsIsReported) {
  StartBridge({"input_qos:=default"});
  const CameraWriters w = Camera(/*reliable=*/false);
  Received r;
  EXPECT_TRUE(PublishUntil(w, &r, [&] { return DiagnosticsMention(r, "it is best effort"); }, 20))
      << bridge_->Log();
  EXPECT_TRUE(r.clouds.empty());
}

TEST_F(Ros2BridgeTest, ABestEffortCameraIsTakenWithTheSensorDataDefault) {
  StartBridge({});
  const CameraWriters w = Camera(/*reliable=*/false);
  Received r;
  EXPECT_TRUE(PublishUntil(w, &r, [&] { return r.clouds.size() >= 3; }, 40)) << bridge_->Log();
}

// Each bad input gets its error on /diagnostics, naming the message and field; good frames
// afterwards still become clouds.
TEST_F(Ros2BridgeTest, BadInputIsReportedAndTheBridgeGoesOn) {
  StartBridge({"queue_size:=3"});
  const CameraWriters w = Camera();
  Received r;
  ASSERT_TRUE(PublishUntil(w, &r, [&] { return !r.clouds.empty(); }, 40)) << bridge_->Log();
  struct Case {
    const char* name;
    std::function<void(TsukubaSamples&)> spoil;
    std::string expected;
  };
  const std::vector<Case> cases = {
      {"step", [](TsukubaSamples& s) { s.colour.step = s.colour.width * 3 + 8; },
       "left/image_rect_color.data holds"},
      {"step too small", [](TsukubaSamples& s) { s.colour.step = 100; },
       "left/image_rect_color.step is 100"},
      {"encoding", [](TsukubaSamples& s) { s.colour.encoding = const_cast<char*>("yuv422"); },
       "left/image_rect_color.encoding is 'yuv422'"},
      {"disparity encoding",
       [](TsukubaSamples& s) { s.disparity.image.encoding = const_cast<char*>("16UC1"); },
       "disparity.image.encoding is '16UC1'"},
      {"camera_info size", [](TsukubaSamples& s) { s.info.width = 320; },
       "left/camera_info is 320x480 but disparity.image is 640x480"},
      {"stamps", [](TsukubaSamples& s) { s.info.header.stamp.nanosec = 1; },
       "/stereo/left/camera_info with the same stamp"},
  };
  for (const Case& c : cases) {
    r.diagnostics.clear();
    EXPECT_TRUE(PublishUntil(w, &r, [&] { return DiagnosticsMention(r, c.expected); }, 15,
                             c.spoil))
        << c.name << ": " << (r.diagnostics.empty() ? "no diagnostics" : r.diagnostics.back())
        << "\n"
        << bridge_->Log();
  }
  const std::size_t before = r.clouds.size();
  EXPECT_TRUE(PublishUntil(w, &r, [&] { return r.clouds.size() >= before + 3; }, 30))
      << bridge_->Log();
  EXPECT_TRUE(bridge_->running());
}

}  // namespace
}  // namespace cloudcast::ros2_bridge
