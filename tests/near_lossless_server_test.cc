// Near-lossless disparity and depth end to end (issue 27 item 5): frames prepared as
// cloudcast-client prepares them (sources::UplinkFrame, --encoding zstd, --max-point-error) go to
// a real server on 127.0.0.1 with the voxel grid and the passthrough off and Draco at 30 bits; the
// cloud of each near-lossless frame has the lossless frame's points, in the same order, each
// within the bound of its lossless twin, and the near-lossless frames are smaller.
#include <gtest/gtest.h>

#include <opencv2/core.hpp>

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cloudcast/client/client.h"
#include "cloudcast/core/settings.h"
#include "cloudcast/datasets/tsukuba.h"
#include "cloudcast/proto/convert.h"
#include "cloudcast/sources/frame.h"
#include "cloudcast/sources/uplink.h"
#include "support/client_fixture.h"
#include "support/program_support.h"
#include "support/test_support.h"

namespace cloudcast {
namespace {

// The New Tsukuba camera as cloudcast-client sends it (principal point unset: each frame's
// centre), nothing filtered, Draco precise enough (30 bits) to show millimetres, every frame
// answered.
client::StreamConfig Config(const CameraModel& camera) {
  client::StreamConfig config;
  convert::SetCamera(camera, &config);
  config.mutable_camera()->clear_cx();
  config.mutable_camera()->clear_cy();
  config.mutable_passthrough()->set_enabled(false);
  config.mutable_voxel_grid()->set_enabled(false);
  config.mutable_draco()->set_position_bits(30);
  config.mutable_draco()->set_encode_speed(10);
  config.mutable_draco()->set_decode_speed(10);
  config.set_delivery(v1::DELIVERY_ALL);
  return config;
}

CameraModel PresetCamera() {
  FrameSettings settings;
  EXPECT_TRUE(ApplyPreset("new_tsukuba", &settings, "preset", false).ok());
  return settings.pipeline.camera;
}

cv::Mat Bgr(const tsukuba::Frame& f) {
  return cv::Mat(static_cast<int>(f.colour.height), static_cast<int>(f.colour.width), CV_8UC3,
                 const_cast<std::uint8_t*>(f.colour.pixels.data()));
}

// A frame of `kind` with `geometry` (disparity or depth) and the frame's colour.
sources::SourceFrame SourceOf(sources::FrameKind kind, const cv::Mat& geometry,
                              const cv::Mat& colour, const std::string& name) {
  sources::SourceFrame s;
  s.kind = kind;
  s.images = {geometry, colour};  // RolesOf: the geometry, then the colour
  s.name = name;
  return s;
}

constexpr double kBounds[] = {0.005, 0.02};

// Per bound, over the frames: the geometry's compressed bytes and the points that moved.
struct Totals {
  std::uint64_t lossless_bytes = 0;
  std::uint64_t near_bytes[2] = {};
  std::uint64_t moved[2] = {};
};

// The compressed disparity or depth payload of an uplink frame.
std::uint64_t GeometryBytes(const sources::UplinkFrame& uplink) {
  v1::Frame frame;
  EXPECT_TRUE(uplink.ToProto(&frame).ok());
  return frame.has_depth() ? frame.depth().compressed().payload().size()
                           : frame.disparity().compressed().payload().size();
}

class NearLosslessServerTest : public testing::SharedServerClientTest {
 protected:
  // Sends `frame` lossless, then at each bound, through one stream with `camera`; checks each
  // near-lossless cloud against the lossless one.
  void Check(const sources::SourceFrame& frame, const CameraModel& camera,
             const std::string& what, Totals* totals) {
    const client::StreamConfig config = Config(camera);
    auto stream = client_->OpenStream(config);
    ASSERT_TRUE(stream.ok()) << stream.status();
    sources::UplinkOptions options;
    options.encoding = sources::Uplink::kZstd;
    // What cloudcast-client does with --max-point-error: the camera the stream sends.
    ASSERT_TRUE(convert::ApplyCamera(config.camera(), "config.camera", &options.camera).ok());
    sources::UplinkFrame uplink;
    auto send = [&](double bound, client::Result* r, std::uint64_t* bytes) {
      options.max_point_error = bound;
      ASSERT_TRUE(uplink.Encode(frame, options).ok());
      *bytes = GeometryBytes(uplink);
      ASSERT_TRUE((*stream)->Send(uplink.input()).ok());
      ASSERT_TRUE((*stream)->Read(r));
      ASSERT_TRUE(r->ok()) << r->status;
    };
    client::Result lossless;
    std::uint64_t lossless_bytes = 0;
    send(0, &lossless, &lossless_bytes);
    ASSERT_GT(lossless.cloud.size(), 1000u) << what;
    totals->lossless_bytes += lossless_bytes;
    for (int b = 0; b < 2; ++b) {
      const double bound = kBounds[b];
      SCOPED_TRACE(what + " at " + std::to_string(bound) + " m");
      client::Result near;
      std::uint64_t near_bytes = 0;
      send(bound, &near, &near_bytes);
      // Valid pixels stay valid and invalid ones invalid: the same points, in pixel order.
      ASSERT_EQ(near.cloud.size(), lossless.cloud.size());
      std::size_t over = 0, moved = 0;
      double worst = 0;
      for (std::size_t i = 0; i < near.cloud.size(); ++i) {
        const Point& a = lossless.cloud.points[i];
        const Point& b = near.cloud.points[i];
        const double dx = double{a.x} - b.x, dy = double{a.y} - b.y, dz = double{a.z} - b.z;
        const double e = std::sqrt(dx * dx + dy * dy + dz * dz);
        worst = std::max(worst, e);
        // Draco at 30 bits adds a few 1e-8 m to each side.
        over += e > bound + 1e-6;
        moved += e > 1e-6;
      }
      EXPECT_EQ(over, 0u) << "worst " << worst;
      totals->near_bytes[b] += near_bytes;
      totals->moved[b] += moved;
    }
    (*stream)->CloseSend().IgnoreError();
    EXPECT_TRUE((*stream)->Finish().ok());
  }
};

// Depth as cloudcast-client makes it from New Tsukuba (float metres, z = 615 / d) and a sub-pixel
// disparity in 1/16 px (a matcher's fixed point), on every frame.
TEST_F(NearLosslessServerTest, CloudsWithinTheBoundOfTheLosslessOnes) {
  CLOUDCAST_REQUIRE_TSUKUBA();
  auto frames = tsukuba::LoadAll(testing::TsukubaDir());
  ASSERT_TRUE(frames.ok()) << frames.status();
  const CameraModel camera = PresetCamera();
  CameraModel sixteenth = camera;
  sixteenth.disparity_scale = 1.0 / 16;
  sixteenth.invalid_disparities = {0.0};
  Totals depth_totals, disparity_totals;
  for (const tsukuba::Frame& f : *frames) {
    const int w = static_cast<int>(f.disparity.width), h = static_cast<int>(f.disparity.height);
    const cv::Mat truth(h, w, CV_8UC1, const_cast<std::uint8_t*>(f.disparity.pixels.data()));
    cv::Mat depth(h, w, CV_32FC1), d16(h, w, CV_16UC1);
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        const int d = truth.at<std::uint8_t>(v, u);
        const double sub = d == 0 ? 0 : d + 0.5 + 0.5 * std::sin(0.05 * u + 0.03 * v);
        depth.at<float>(v, u) =
            d == 0 ? 0.0f : static_cast<float>(camera.fx * camera.baseline / d);
        d16.at<std::uint16_t>(v, u) = static_cast<std::uint16_t>(std::lround(sub * 16));
      }
    }
    Check(SourceOf(sources::FrameKind::kDepth, depth, Bgr(f), f.id), camera, f.id + " depth",
          &depth_totals);
    Check(SourceOf(sources::FrameKind::kDisparity, d16, Bgr(f), f.id), sixteenth,
          f.id + " u16 disparity", &disparity_totals);
  }
  // Over the frames, each bound moves points and saves bytes (at z = 615 / d a 1/16 px step is
  // 4 mm at 6 m, so the far frames keep their disparities as they are).
  for (int b = 0; b < 2; ++b) {
    SCOPED_TRACE(kBounds[b]);
    EXPECT_GT(depth_totals.moved[b], 0u);
    EXPECT_LT(depth_totals.near_bytes[b], depth_totals.lossless_bytes);
    EXPECT_GT(disparity_totals.moved[b], 0u);
    EXPECT_LT(disparity_totals.near_bytes[b], disparity_totals.lossless_bytes);
  }
}

// cloudcast-client --max-point-error: New Tsukuba depth frames (float metres) with zstd, every
// frame answered, fewer uplink bytes than without it; a negative bound refused naming the flag.
TEST_F(NearLosslessServerTest, ClientProgramFlagShrinksTheUplink) {
  CLOUDCAST_REQUIRE_TSUKUBA();
  const std::string binary = testing::BinDir() + "/cloudcast-client";
  ASSERT_TRUE(std::filesystem::exists(binary)) << binary << " is missing: build cloudcast-client";
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("near_lossless_server_test_" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  auto run = [&](const std::string& bound) {
    const std::string json = (dir / ("run_" + bound + ".json")).string();
    const testing::RunResult r = testing::RunProgram(
        binary,
        {"--server", shared_target(), "--tsukuba", testing::TsukubaDir(), "--input", "depth",
         "--encoding", "zstd", "--frames", "10", "--lossless", "--no-window", "--quiet",
         "--max-point-error", bound, "--json", json},
        dir.string(), "env -u DISPLAY");
    EXPECT_TRUE(r.exited && r.code == 0) << r;
    return nlohmann::json::parse(testing::ReadText(json), nullptr, false);
  };
  const nlohmann::json lossless = run("0");
  const nlohmann::json near = run("0.05");
  ASSERT_FALSE(lossless.is_discarded());
  ASSERT_FALSE(near.is_discarded());
  EXPECT_EQ(lossless["frames"]["received"], 10);
  EXPECT_EQ(near["frames"]["received"], 10);
  EXPECT_LT(near["mean_uplink_bytes_per_frame"].get<double>(),
            lossless["mean_uplink_bytes_per_frame"].get<double>());
  const testing::RunResult bad = testing::RunProgram(
      binary, {"--server", shared_target(), "--no-window", "--max-point-error", "-1"},
      dir.string(), "env -u DISPLAY");
  EXPECT_EQ(bad.code, 2) << bad;
  EXPECT_NE((bad.out + bad.err).find("--max-point-error"), std::string::npos) << bad;
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace cloudcast
