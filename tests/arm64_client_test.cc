// The client library on arm64, under qemu-user: tests/arm64/cross_build.sh cross-builds it
// (scripts/build-arm64, warm through ccache), runs its unit tests under qemu-user, installs it and
// builds a robot project against the install tree with find_package(cloudcast); this test then
// streams a frame from that arm64 robot to this machine's amd64 cloudcast-server on loopback, raw
// and through the lossless uplink codec, and decodes the reply's Draco bytes here too: the arm64
// client's cloud must equal amd64's bit for bit. Skips, saying what is missing, without the cross
// toolchain, qemu-user or the arm64 packages (scripts/setup --arm64 installs them).
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "cloudcast/core/draco_codec.h"
#include "cloudcast/core/point.h"
#include "support/program_support.h"
#include "support/replica_support.h"

namespace cloudcast {
namespace {

using testing::ReadText;
using testing::RunProgram;
using testing::ServerProcess;

// Where the cross build and the robot project live between runs (so that a second run rebuilds
// only what changed), and the script that makes them.
const std::string kScratch = CLOUDCAST_ARM64_SCRATCH_DIR;
const std::string kSourceDir = CLOUDCAST_SOURCE_DIR;
// qemu-user as the cross build runs its own tests: with the arm64 libraries scripts/setup
// unpacked rather than installed (OpenCV's) on the guest's library path (cmake/qemu-wrapper.cmake).
const std::string kQemu = kScratch + "/cloudcast/qemu-aarch64";

class Arm64Client : public ::testing::Test {
 protected:
  // Runs the cross build (idempotent); skips when the tools are missing (exit 77).
  void SetUp() override {
    std::filesystem::create_directories(kScratch);
    build_ =
        RunProgram(kSourceDir + "/tests/arm64/cross_build.sh", {kSourceDir, kScratch}, kScratch);
    if (build_.exited && build_.code == 77) {
      GTEST_SKIP() << "arm64 cross build not possible here: " << build_.err;
    }
    ASSERT_EQ(build_.code, 0) << build_;
  }

  testing::RunResult build_;
};

// The client's unit tests (tests/client_only/) ran under qemu-user in cross_build.sh, through
// ctest with the toolchain's CMAKE_CROSSCOMPILING_EMULATOR: every one listed and passed.
TEST_F(Arm64Client, UnitTestsPassUnderQemu) {
  EXPECT_NE(build_.out.find("tests passed, 0 tests failed"), std::string::npos) << build_;
  EXPECT_NE(build_.out.find("qemu-aarch64"), std::string::npos)
      << "the tests did not run under qemu-user\n"
      << build_;
  // The robot links the installed library, and the binary is arm64 code.
  EXPECT_NE(build_.out.find("robot: AArch64"), std::string::npos) << build_;
}

// The ROS 2 bridge is a robot program too: cross-built beside the client (its DDS library from
// cyclonedds-dev:arm64), its unit tests (names, QoS, type hashes, CDR, parameters, sync) among
// those that passed under qemu-user above, and the program starts there.
TEST_F(Arm64Client, Ros2BridgeBuildsAndItsUnitTestsPassUnderQemu) {
  if (build_.out.find("ros2 bridge: not built") != std::string::npos) {
    GTEST_SKIP() << "cyclonedds-dev:arm64 is not installed (scripts/setup --arm64)";
  }
  EXPECT_NE(build_.out.find("ros2 bridge: AArch64"), std::string::npos) << build_;
  const std::size_t at = build_.out.find("ros2 unit tests under qemu-user: ");
  ASSERT_NE(at, std::string::npos) << build_;
  EXPECT_GE(std::stoi(build_.out.substr(at + 33)), 20) << build_;
  EXPECT_NE(
      build_.out.find("ros2 bridge --help under qemu-user: cloudcast-ros2-bridge: a ROS 2 node"),
      std::string::npos)
      << build_;
}

// The ROS 1 bridge as well: cross-built against Debian's arm64 roscpp libraries (their -dev
// packages do not install beside the host's; the headers are the host's), its unit tests among
// those that passed under qemu-user above, and the program starts there.
TEST_F(Arm64Client, RosBridgeBuildsAndItsUnitTestsPassUnderQemu) {
  if (build_.out.find("ros1 bridge: not built") != std::string::npos) {
    GTEST_SKIP() << "the arm64 roscpp libraries are not installed (scripts/setup --arm64)";
  }
  EXPECT_NE(build_.out.find("ros1 bridge: AArch64"), std::string::npos) << build_;
  const std::size_t at = build_.out.find("ros1 unit tests under qemu-user: ");
  ASSERT_NE(at, std::string::npos) << build_;
  EXPECT_GE(std::stoi(build_.out.substr(at + 33)), 30) << build_;
  EXPECT_NE(build_.out.find("ros1 bridge --help under qemu-user: cloudcast-ros-bridge: turns a "
                            "ROS camera's disparity"),
            std::string::npos)
      << build_;
}

// The ROS 1 bridge's traffic under qemu-user: the ROS tests (ros/tests/*.py: a real master,
// Debian's stereo_image_proc and depth_image_proc, an amd64 server) with the arm64 bridge in
// place of this build's (CLOUDCAST_ROS_BRIDGE, CLOUDCAST_ROS_BRIDGE_EMULATOR). A selection, for
// CI's time: the clouds of a disparity camera against stereo_image_proc's and of a depth camera
// against depth_image_proc's (point for point), and TLS with a token. Left out: h264 and jpeg
// (their encoders' unit tests pass under qemu-user above, and cloudcast-client's h264 below), the
// launch files (roslaunch
// starts the package's program: this build's), and the rest of the scripts' tests, which passed
// so by hand on 2026-12-06 (rosbag playback, a bad parameter, stereo pairs; docs/client.md).
TEST_F(Arm64Client, RosBridgeCarriesRosTrafficUnderQemu) {
  const std::string bridge = kScratch + "/cloudcast/bin/cloudcast-ros-bridge";
  if (!std::filesystem::exists(bridge)) {
    GTEST_SKIP() << "the arm64 roscpp libraries are not installed (scripts/setup --arm64)";
  }
  const std::string bin = testing::BinDir();
  if (!std::filesystem::exists(bin + "/cloudcast-ros-bridge")) {
    GTEST_SKIP() << "this build has no ROS 1 bridge, so no ROS 1 tests to run it by";
  }
  const std::string env = "CLOUDCAST_ROS_BRIDGE=" + bridge +
                          " CLOUDCAST_ROS_BRIDGE_EMULATOR=" + kQemu;
  const struct {
    const char* script;
    std::vector<std::string> tests;
  } runs[] = {
      {"ros_bridge_test.py",
       {"RosBridgeTest.test_1_clouds_equal_stereo_image_procs_point_for_point",
        "RosBridgeTest.test_5_tls_and_a_bearer_token"}},
      {"ros_depth_test.py", {"RosDepthTest.test_1_16uc1_millimetres_equal_depth_image_proc"}},
  };
  for (const auto& run : runs) {
    std::vector<std::string> args = {kSourceDir + "/ros/tests/" + run.script, "--bin-dir", bin,
                                     "--data", CLOUDCAST_DEFAULT_DATA_DIR};
    args.insert(args.end(), run.tests.begin(), run.tests.end());
    const testing::RunResult r = RunProgram(CLOUDCAST_ROS_PYTHON, args, kScratch, env);
    if (r.exited && r.code == 77) GTEST_SKIP() << run.script << " skipped\n" << r;
    EXPECT_EQ(r.code, 0) << run.script << "\n" << r;
    // The bridge it started was the arm64 one, under qemu-user, and every test it ran passed.
    EXPECT_NE(r.out.find("[ bridge ] " + kQemu + " " + bridge),
              std::string::npos)
        << r;
    EXPECT_NE(r.err.find("Ran " + std::to_string(run.tests.size()) + " test"), std::string::npos)
        << r;
  }
}

// The bridge's DDS traffic under qemu-user: ros2_bridge_dds_test (its camera and subscriber in
// this process, its network namespace, an amd64 server) with the arm64 bridge in place of this
// build's. qemu-user 7.2 has no IP_MULTICAST_IF, so Cyclone discovers by unicast on loopback
// (CYCLONEDDS_URI: no multicast, the peer 127.0.0.1), at both ends. Left out: h264 and jpeg (as
// in the ROS 1 test above) and the Fast DDS garbage writer, whose discovery needs multicast.
TEST_F(Arm64Client, Ros2BridgeCarriesDdsTrafficUnderQemu) {
  const std::string bridge = kScratch + "/cloudcast/bin/cloudcast-ros2-bridge";
  if (!std::filesystem::exists(bridge)) {
    GTEST_SKIP() << "cyclonedds-dev:arm64 is not installed (scripts/setup --arm64)";
  }
  const std::string dds_test = testing::BinDir() + "/ros2_bridge_dds_test";
  if (!std::filesystem::exists(dds_test)) {
    GTEST_SKIP() << "ros2_bridge_dds_test is not built here (it needs the ROS 1 bridge)";
  }
  const std::string uri =
      "<CycloneDDS><Domain><General><AllowMulticast>false</AllowMulticast></General>"
      "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
      "<MaxAutoParticipantIndex>20</MaxAutoParticipantIndex>"
      "<Peers><Peer address=\"127.0.0.1\"/></Peers></Discovery>"
      "<Internal><SocketReceiveBufferSize min=\"default\" max=\"10MB\"/></Internal>"
      "</Domain></CycloneDDS>";
  const std::string env = "CYCLONEDDS_URI='" + uri + "' CLOUDCAST_ROS2_BRIDGE=" + bridge +
                          " CLOUDCAST_ROS2_BRIDGE_EMULATOR=" + kQemu;
  const testing::RunResult r = RunProgram(
      dds_test, {"--gtest_filter=Ros2BridgeTest.*-*H264*:*Jpeg*:*NonCdr*"}, kScratch, env);
  if (r.out.find("[  PASSED  ] 0 tests") != std::string::npos &&
      r.out.find("SKIPPED") != std::string::npos) {
    GTEST_SKIP() << "ros2_bridge_dds_test skipped (its network namespace needs root)\n" << r;
  }
  ASSERT_EQ(r.code, 0) << r;
  EXPECT_EQ(r.out.find("FAILED"), std::string::npos) << r;
  // Every bridge it started was the arm64 one, under qemu-user.
  EXPECT_NE(r.out.find("[ bridge   ] " + kQemu + " " + bridge),
            std::string::npos)
      << r;
  const std::size_t at = r.out.find("[  PASSED  ] ");
  ASSERT_NE(at, std::string::npos) << r;
  // The clouds (disparity, depth, stereo cameras) equal the ROS 1 bridge's point for point, the
  // discovery info, QoS mismatches, bad input: at least the 12 tests of 2026-12-05.
  EXPECT_GE(std::stoi(r.out.substr(at + 13)), 12) << r;
}

TEST_F(Arm64Client, StreamsToAnAmd64ServerAndDecodesAsAmd64Does) {
  ServerProcess server("127.0.0.1:0", "amd64-server", {}, kScratch + "/server.log");
  ASSERT_TRUE(server.WaitUntilServing()) << server.log();

  const std::string out = kScratch + "/robot-out";
  std::filesystem::remove_all(out);
  std::filesystem::create_directories(out);
  const testing::RunResult robot =
      RunProgram(kQemu, {kScratch + "/robot/robot", server.address(), out}, out);
  ASSERT_EQ(robot.code, 0) << robot << "\nserver log:\n" << server.log();
  // Frame 0 raw, frame 1 through the uplink codec (compressed on arm64, decompressed on amd64):
  // the robot checked that both gave the same Draco bytes.
  EXPECT_NE(robot.out.find("frame 0 from amd64-server"), std::string::npos) << robot;
  EXPECT_NE(robot.out.find("frame 1 from amd64-server"), std::string::npos) << robot;

  // The same Draco bytes, decoded by the amd64 engine: the same points, in the same order.
  const std::string draco = ReadText(out + "/cloud.drc");
  const std::string arm64_points = ReadText(out + "/cloud.points");
  ASSERT_FALSE(draco.empty());
  PointCloud here;
  ASSERT_TRUE(DecodeDraco(draco, &here).ok());
  ASSERT_GT(here.size(), 0u);
  ASSERT_EQ(arm64_points.size(), here.size() * sizeof(Point));
  EXPECT_EQ(std::memcmp(arm64_points.data(), here.points.data(), arm64_points.size()), 0)
      << "the arm64 client decoded a different cloud from the same " << draco.size()
      << " Draco bytes";
}

// The README's robot example on arm64 (built when scripts/setup unpacked OpenCV's arm64
// libraries): New Tsukuba's PNG folders read by OpenCV's imgcodecs into cv::Mats, and the synthetic
// scene as a depth camera, each streamed to an amd64 server: every frame's cloud has the points and
// the Draco bytes that the amd64 example's same frames get.
TEST_F(Arm64Client, RobotExampleSendsWhatTheAmd64OneSends) {
  const std::string example = kScratch + "/cloudcast/bin/cloudcast-robot-example";
  if (!std::filesystem::exists(example)) {
    GTEST_SKIP() << "OpenCV's arm64 libraries are not unpacked (scripts/setup --arm64)";
  }
  const std::string here = testing::BinDir() + "/cloudcast-robot-example";
  if (!std::filesystem::exists(here)) GTEST_SKIP() << "this build has no robot example";
  ServerProcess server("127.0.0.1:0", "amd64-server", {}, kScratch + "/server.log");
  ASSERT_TRUE(server.WaitUntilServing()) << server.log();

  const std::string data = CLOUDCAST_DEFAULT_DATA_DIR;
  const struct {
    std::vector<std::string> args;
    std::size_t frames;
  } runs[] = {
      {{server.address(), "3", data + "/groundtruth/disparity_maps/left",
        data + "/illumination/daylight/left"},
       3},
      {{"--input", "depth", server.address(), "2"}, 2},
  };
  // "frame 1: 1873 points, 4124 Draco bytes, latency 3.6 ms": all but the latency.
  const auto clouds = [](const std::string& out) {
    std::vector<std::string> lines;
    for (std::size_t at = out.find("frame "); at != std::string::npos;
         at = out.find("frame ", at + 1)) {
      const std::size_t end = out.find(", latency", at);
      if (end != std::string::npos) lines.push_back(out.substr(at, end - at));
    }
    return lines;
  };
  for (const auto& run : runs) {
    SCOPED_TRACE(run.args.front() + " ...");
    std::vector<std::string> qemu_args = {example};
    qemu_args.insert(qemu_args.end(), run.args.begin(), run.args.end());
    const testing::RunResult arm64 = RunProgram(kQemu, qemu_args, kScratch);
    ASSERT_EQ(arm64.code, 0) << arm64 << "\nserver log:\n" << server.log();
    const testing::RunResult amd64 = RunProgram(here, run.args, kScratch);
    ASSERT_EQ(amd64.code, 0) << amd64;
    EXPECT_NE(arm64.out.find("stream finished: OK"), std::string::npos) << arm64;
    const std::vector<std::string> got = clouds(arm64.out), want = clouds(amd64.out);
    ASSERT_EQ(want.size(), run.frames) << amd64;
    EXPECT_EQ(got, want) << arm64 << amd64;
    EXPECT_EQ(arm64.out.find(" 0 points"), std::string::npos) << arm64;
  }
}

// cloudcast-client on arm64, as a robot runs it (no display: --no-window), built when scripts/setup
// --arm64 unpacked PCL's and OpenCV's arm64 libraries and installed GLFW's, libepoxy's, FFmpeg's
// and spdlog's: New Tsukuba's frames recorded as .pcd files equal, byte for byte, what the amd64
// client records from the same server; and the colour as H.264 (libx264 on arm64, decoded on the
// amd64 server) answered frame for frame.
TEST_F(Arm64Client, ClientRecordsWithoutADisplayAsTheAmd64OneDoes) {
  const std::string client = kScratch + "/cloudcast/bin/cloudcast-client";
  if (!std::filesystem::exists(client)) {
    GTEST_SKIP() << "cloudcast-client is not in the arm64 build (scripts/setup --arm64)";
  }
  const std::string here = testing::BinDir() + "/cloudcast-client";
  ServerProcess server("127.0.0.1:0", "amd64-server", {}, kScratch + "/server.log");
  ASSERT_TRUE(server.WaitUntilServing()) << server.log();

  const std::vector<std::string> common = {
      "--tsukuba", CLOUDCAST_DEFAULT_DATA_DIR, "--camera-preset", "new_tsukuba",
      "--server",  server.address(),          "--no-window",     "--frames", "3"};
  // Records 3 frames as .pcd files into kScratch/client-NAME, with the arm64 client under qemu-user
  // or with this build's.
  const auto record = [&](bool on_arm64, const std::string& name, std::vector<std::string> extra) {
    const std::string dir = kScratch + "/client-" + name;
    std::filesystem::remove_all(dir);
    std::vector<std::string> args = common;
    args.insert(args.end(), extra.begin(), extra.end());
    args.insert(args.end(), {"--record", dir, "--record-format", "pcd", "--json", dir + ".json"});
    if (!on_arm64) return RunProgram(here, args, kScratch, "env -u DISPLAY");
    args.insert(args.begin(), client);
    return RunProgram(kQemu, args, kScratch, "env -u DISPLAY");
  };
  const testing::RunResult arm64 = record(true, "arm64", {});
  ASSERT_EQ(arm64.code, 0) << arm64 << "\nserver log:\n" << server.log();
  EXPECT_NE(arm64.out.find("frames: sent 3, received 3, dropped 0, errors 0"), std::string::npos)
      << arm64;
  const testing::RunResult amd64 = record(false, "amd64", {});
  ASSERT_EQ(amd64.code, 0) << amd64;
  std::vector<std::string> files;
  for (const auto& entry : std::filesystem::directory_iterator(kScratch + "/client-amd64")) {
    files.push_back(entry.path().filename());
  }
  ASSERT_EQ(files.size(), 3u);
  for (const std::string& file : files) {
    SCOPED_TRACE(file);
    const std::string want = ReadText(kScratch + "/client-amd64/" + file);
    ASSERT_FALSE(want.empty());
    EXPECT_TRUE(ReadText(kScratch + "/client-arm64/" + file) == want)
        << "the arm64 client recorded a different " << file;
  }

  const testing::RunResult h264 = record(true, "h264", {"--encoding", "h264"});
  ASSERT_EQ(h264.code, 0) << h264 << "\nserver log:\n" << server.log();
  EXPECT_NE(h264.out.find("frames: sent 3, received 3, dropped 0, errors 0"), std::string::npos)
      << h264;
}

}  // namespace
}  // namespace cloudcast
