// The contract cannot silently empty a cloud (issue 29, part 2), against a server with the
// contract's own defaults (no camera, no passthrough): a RealSense-like depth frame keeps its
// table and box with only a focal length; a frame without a camera gets an error naming the
// field, structured; an empty cloud says which stage took its points; a frame's own camera
// overrides the stream's; GetInfo names the contract's revision.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "cloudcast/client/client.h"
#include "cloudcast/client/opencv.h"
#include "cloudcast/core/draco_codec.h"
#include "cloudcast/io/cloud_io.h"
#include "cloudcast/proto/convert.h"
#include "support/program_support.h"
#include "support/server_fixture.h"

namespace cloudcast {
namespace {

namespace fs = std::filesystem;

constexpr int kWidth = 640, kHeight = 480;
// A RealSense-like scene in millimetres (16UC1, REP 118): a table 1.2 m away, a box on it 0.8 m
// away in the middle, and a border of pixels without a measurement (0).
constexpr std::uint16_t kTableMm = 1200, kBoxMm = 800;

cv::Mat DepthMm() {
  cv::Mat d(kHeight, kWidth, CV_16UC1, cv::Scalar(kTableMm));
  d(cv::Rect(240, 160, 160, 160)).setTo(cv::Scalar(kBoxMm));
  d.row(0).setTo(cv::Scalar(0));
  return d;
}

cv::Mat Colour() {
  cv::Mat c(kHeight, kWidth, CV_8UC3, cv::Scalar(40, 120, 200));
  c(cv::Rect(240, 160, 160, 160)).setTo(cv::Scalar(200, 60, 30));
  return c;
}

v1::Frame DepthFrame(std::uint64_t sequence, const cv::Mat& depth) {
  v1::Frame frame;
  frame.set_sequence(sequence);
  std::vector<std::uint8_t> png;
  EXPECT_TRUE(cv::imencode(".png", depth, png));
  frame.mutable_depth()->set_encoded(std::string(png.begin(), png.end()));
  EXPECT_TRUE(cv::imencode(".png", Colour(), png));
  frame.mutable_color()->set_encoded(std::string(png.begin(), png.end()));
  return frame;
}

v1::Frame DisparityFrame(std::uint64_t sequence) {
  v1::Frame frame;
  frame.set_sequence(sequence);
  v1::RawDisparity* d = frame.mutable_disparity()->mutable_raw();
  d->set_encoding(v1::DISPARITY_U8);
  d->set_width(64);
  d->set_height(48);
  d->set_pixels(std::string(64 * 48, '\x40'));
  v1::RawColor* c = frame.mutable_color()->mutable_raw();
  c->set_encoding(v1::COLOR_MONO8);
  c->set_width(64);
  c->set_height(48);
  c->set_pixels(std::string(64 * 48, '\x80'));
  return frame;
}

v1::StreamConfig Focal(double fx) {
  v1::StreamConfig config;
  config.mutable_camera()->set_fx(fx);
  config.set_delivery(v1::DELIVERY_ALL);
  return config;
}

std::vector<v1::StreamReply> Stream(v1::CloudCast::Stub& stub,
                                    const std::vector<v1::StreamRequest>& requests) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  auto stream = stub.Stream(&ctx);
  for (const v1::StreamRequest& r : requests) EXPECT_TRUE(stream->Write(r));
  stream->WritesDone();
  std::vector<v1::StreamReply> replies;
  v1::StreamReply reply;
  while (stream->Read(&reply)) replies.push_back(reply);
  EXPECT_TRUE(stream->Finish().ok());
  return replies;
}

v1::StreamRequest Req(const v1::StreamConfig& config) {
  v1::StreamRequest r;
  *r.mutable_config() = config;
  return r;
}
v1::StreamRequest Req(const v1::Frame& frame) {
  v1::StreamRequest r;
  *r.mutable_frame() = frame;
  return r;
}

::testing::AssertionResult Violation(const v1::FrameError& error, const std::string& field,
                                     const std::string& reason) {
  if (error.bad_request().field_violations_size() != 1) {
    return ::testing::AssertionFailure() << "no field violation: " << error.DebugString();
  }
  const v1::FieldViolation& v = error.bad_request().field_violations(0);
  if (v.field() != field || v.reason() != reason) {
    return ::testing::AssertionFailure()
           << "field " << v.field() << " (" << v.reason() << "), want " << field << " (" << reason
           << "): " << error.message();
  }
  return ::testing::AssertionSuccess();
}

// The z values of a cloud, to 1 cm.
std::vector<int> Depths(const PointCloud& cloud) {
  std::vector<int> cm;
  for (const Point& p : cloud.points) cm.push_back(static_cast<int>(std::lround(p.z * 100)));
  std::sort(cm.begin(), cm.end());
  cm.erase(std::unique(cm.begin(), cm.end()), cm.end());
  return cm;
}

class ContractTest : public testing::ScratchDirTest {
 protected:
  void SetUp() override {
    ScratchDirTest::SetUp();
    server_ = testing::StartTestServer(testing::ContractServerOptions());
    ASSERT_NE(server_, nullptr);
    stub_ = testing::NewStub(*server_);
  }
  std::unique_ptr<server::Server> server_;
  std::unique_ptr<v1::CloudCast::Stub> stub_;
};

// The user: `cloudcast-client --input depth --depth d.png --colour c.png --focal 615`
// against a server left at its defaults gets the table and the box, not 0 points.
TEST_F(ContractTest, RealSenseDepthKeepsTableAndBoxWithTheDefaults) {
  const std::string client = testing::BinDir() + "/cloudcast-client";
  ASSERT_TRUE(fs::exists(client)) << client << " is missing: build cloudcast-client";
  ASSERT_TRUE(cv::imwrite(Path("d.png"), DepthMm()));
  ASSERT_TRUE(cv::imwrite(Path("c.png"), Colour()));
  const testing::RunResult r = testing::RunProgram(
      client, {"--input",     "depth",    "--depth",   Path("d.png"),     "--colour",
               Path("c.png"), "--focal",  "615",       "--server",        server_->address(),
               "--no-window", "--frames", "1",         "--lossless",      "--progress",
               "0",           "--record", Path("out"), "--record-format", "ply"},
      dir_.string());
  ASSERT_TRUE(r.exited && r.code == 0) << r;
  EXPECT_EQ(r.err.find("empty cloud"), std::string::npos) << r;
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(dir_ / "out")) files.push_back(e.path());
  ASSERT_EQ(files.size(), 1u) << r;
  PointCloud cloud;
  ASSERT_TRUE(LoadCloud(files.front().string(), &cloud).ok());
  ASSERT_GT(cloud.size(), 100u);
  // The voxel grid's centroids of a flat table and a flat box: two depths, in metres.
  const std::vector<int> depths = Depths(cloud);
  EXPECT_EQ(depths, (std::vector<int>{80, 120})) << "z in cm of the cloud's points";
  // x right, y down (REP 103's optical frame): the box (at the centre) spans about
  // +-80 px * 0.8 m / 615 px = +-0.10 m.
  float box_min_x = 1e9f, box_max_x = -1e9f;
  for (const Point& p : cloud.points) {
    if (std::lround(p.z * 100) != 80) continue;
    box_min_x = std::min(box_min_x, p.x);
    box_max_x = std::max(box_max_x, p.x);
  }
  EXPECT_NEAR(box_min_x, -0.10f, 0.03f);
  EXPECT_NEAR(box_max_x, 0.10f, 0.03f);
}

// Without --focal (or a preset) the client refuses image files before it connects, naming the
// flags; and a server asked without a camera names the field, structured.
TEST_F(ContractTest, DepthWithoutACameraIsAClearErrorNamingTheField) {
  const std::string client = testing::BinDir() + "/cloudcast-client";
  ASSERT_TRUE(cv::imwrite(Path("d.png"), DepthMm()));
  ASSERT_TRUE(cv::imwrite(Path("c.png"), Colour()));
  const testing::RunResult r =
      testing::RunProgram(client,
                          {"--input", "depth", "--depth", Path("d.png"), "--colour", Path("c.png"),
                           "--server", server_->address(), "--no-window", "--frames", "1"},
                          dir_.string());
  EXPECT_TRUE(r.exited && r.code == 1) << r;
  EXPECT_NE(r.err.find("--focal"), std::string::npos) << r;
  EXPECT_NE(r.err.find("--camera-preset new_tsukuba"), std::string::npos) << r;

  // Disparity input with a focal length but no baseline: the flag named too.
  const testing::RunResult d =
      testing::RunProgram(client,
                          {"--disparity", Path("d.png"), "--colour", Path("c.png"), "--focal",
                           "615", "--server", server_->address(), "--no-window", "--frames", "1"},
                          dir_.string());
  EXPECT_TRUE(d.exited && d.code == 1) << d;
  EXPECT_NE(d.err.find("--baseline"), std::string::npos) << d;

  // Over the wire: a stream with no config, a depth frame; then a disparity frame with fx only.
  const std::vector<v1::StreamReply> replies =
      Stream(*stub_, {Req(DepthFrame(1, DepthMm())), Req(Focal(615)), Req(DisparityFrame(2)),
                      Req(DepthFrame(3, DepthMm()))});
  ASSERT_EQ(replies.size(), 3u);
  ASSERT_TRUE(replies[0].has_error());
  EXPECT_EQ(replies[0].error().code(), static_cast<int>(grpc::StatusCode::INVALID_ARGUMENT));
  EXPECT_TRUE(Violation(replies[0].error(), "config.camera.fx", "REQUIRED"));
  EXPECT_NE(replies[0].error().message().find("new_tsukuba"), std::string::npos);
  ASSERT_TRUE(replies[1].has_error());
  EXPECT_TRUE(Violation(replies[1].error(), "config.camera.baseline", "REQUIRED"));
  ASSERT_TRUE(replies[2].has_cloud()) << replies[2].error().message();
  EXPECT_GT(replies[2].cloud().point_count(), 100u);

  // Process: the same in the call status's details (google.rpc.BadRequest).
  v1::ProcessRequest request;
  *request.mutable_frame() = DepthFrame(4, DepthMm());
  v1::CloudReply reply;
  grpc::ClientContext ctx;
  const grpc::Status status = stub_->Process(&ctx, request, &reply);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  v1::BadRequest bad;
  ASSERT_TRUE(convert::ParseStatusDetails(status.error_details(), &bad)) << status.error_message();
  ASSERT_EQ(bad.field_violations_size(), 1);
  EXPECT_EQ(bad.field_violations(0).field(), "config.camera.fx");
  EXPECT_EQ(bad.field_violations(0).reason(), "REQUIRED");
}

// Each stage that can empty a cloud says so: conversion (no valid pixel), passthrough (with the
// range the points spanned), voxel grid (min_points_per_voxel).
TEST_F(ContractTest, AnEmptyCloudSaysWhichStageTookItsPoints) {
  v1::StreamConfig paper = Focal(615);
  paper.mutable_passthrough()->set_min(3);
  paper.mutable_passthrough()->set_max(12);
  v1::StreamConfig sparse = Focal(615);
  sparse.mutable_voxel_grid()->set_min_points_per_voxel(1000000);
  const std::vector<v1::StreamReply> replies = Stream(
      *stub_, {Req(Focal(615)), Req(DepthFrame(1, DepthMm())),
               Req(DepthFrame(2, cv::Mat(kHeight, kWidth, CV_16UC1, cv::Scalar(0)))), Req(paper),
               Req(DepthFrame(3, DepthMm())), Req(sparse), Req(DepthFrame(4, DepthMm()))});
  ASSERT_EQ(replies.size(), 4u);
  for (const v1::StreamReply& r : replies) ASSERT_TRUE(r.has_cloud()) << r.error().message();

  EXPECT_FALSE(replies[0].cloud().has_empty());
  EXPECT_GT(replies[0].cloud().point_count(), 0u);

  const v1::EmptyCloud& none = replies[1].cloud().empty();
  EXPECT_EQ(none.stage(), v1::STAGE_CONVERSION);
  EXPECT_EQ(none.reason(), "NO_VALID_PIXELS");

  // The case: 307,200 - 640 valid points, all at z 0.8 or 1.2, outside [3, 12].
  const v1::CloudReply& outside = replies[2].cloud();
  EXPECT_EQ(outside.point_count(), 0u);
  EXPECT_EQ(outside.counts().valid_points(), 640u * 479u);
  EXPECT_EQ(outside.empty().stage(), v1::STAGE_PASSTHROUGH);
  EXPECT_EQ(outside.empty().reason(), "OUTSIDE_RANGE");
  ASSERT_TRUE(outside.empty().has_observed_min());
  EXPECT_FLOAT_EQ(outside.empty().observed_min(), 0.8f);
  EXPECT_FLOAT_EQ(outside.empty().observed_max(), 1.2f);
  EXPECT_NE(outside.empty().message().find("z in [3, 12]"), std::string::npos)
      << outside.empty().message();

  EXPECT_EQ(replies[3].cloud().empty().stage(), v1::STAGE_VOXEL_GRID);
  EXPECT_EQ(replies[3].cloud().empty().reason(), "VOXELS_UNDER_MIN_POINTS");
}

// The range an emptied cloud's points spanned costs a second conversion, so a worker measures it
// on one such frame in 32 (the first always); every empty frame still names its stage and reason.
// A camera set up for the wrong range sends such frames 30 times a second.
TEST_F(ContractTest, TheRangeOfFramesThePassthroughEmptiesIsMeasuredOnOneIn32) {
  server::ServerOptions one_worker = testing::ContractServerOptions();
  one_worker.threads = 1;  // one worker: which frames it measures is then fixed
  auto server = testing::StartTestServer(one_worker);
  ASSERT_NE(server, nullptr);
  auto stub = testing::NewStub(*server);
  v1::StreamConfig paper = Focal(615);
  paper.mutable_passthrough()->set_min(3);
  paper.mutable_passthrough()->set_max(12);
  paper.set_delivery(v1::DELIVERY_ALL);
  std::vector<v1::StreamRequest> requests = {Req(paper)};
  for (int i = 1; i <= 40; ++i) requests.push_back(Req(DepthFrame(i, DepthMm())));
  const std::vector<v1::StreamReply> replies = Stream(*stub, requests);
  ASSERT_EQ(replies.size(), 40u);
  std::vector<int> measured;
  for (int i = 0; i < 40; ++i) {
    const v1::CloudReply& cloud = replies[static_cast<std::size_t>(i)].cloud();
    EXPECT_EQ(cloud.empty().stage(), v1::STAGE_PASSTHROUGH) << i;
    EXPECT_EQ(cloud.empty().reason(), "OUTSIDE_RANGE") << i;
    if (cloud.empty().has_observed_min()) {
      measured.push_back(i);
      EXPECT_FLOAT_EQ(cloud.empty().observed_min(), 0.8f);
    } else {
      EXPECT_NE(cloud.empty().message().find("one such frame in 32"), std::string::npos)
          << cloud.empty().message();
    }
  }
  EXPECT_EQ(measured, (std::vector<int>{0, 32}));
}

// A frame's camera overrides the stream's for that frame only: twice the focal length halves the
// cloud's width; its errors name frame.camera.
TEST_F(ContractTest, AFramesCameraOverridesTheStreamsForThatFrame) {
  v1::StreamConfig config = Focal(615);
  config.mutable_voxel_grid()->set_enabled(false);
  v1::Frame zoomed = DepthFrame(2, DepthMm());
  zoomed.mutable_camera()->set_fx(1230);
  v1::Frame bad = DepthFrame(4, DepthMm());
  bad.mutable_camera()->set_fy(-1);
  const std::vector<v1::StreamReply> replies =
      Stream(*stub_, {Req(config), Req(DepthFrame(1, DepthMm())), Req(zoomed),
                      Req(DepthFrame(3, DepthMm())), Req(bad)});
  ASSERT_EQ(replies.size(), 4u);
  auto width = [](const v1::StreamReply& r) {
    PointCloud cloud;
    EXPECT_TRUE(DecodeDraco(r.cloud().draco(), &cloud).ok());
    float lo = std::numeric_limits<float>::max(), hi = std::numeric_limits<float>::lowest();
    for (const Point& p : cloud.points) {
      lo = std::min(lo, p.x);
      hi = std::max(hi, p.x);
    }
    return hi - lo;
  };
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(replies[i].has_cloud()) << replies[i].error().message();
  const float wide = width(replies[0]);
  EXPECT_NEAR(width(replies[1]), wide / 2, wide * 0.01f);
  EXPECT_NEAR(width(replies[2]), wide, wide * 0.001f) << "the stream's camera is back";
  ASSERT_TRUE(replies[3].has_error());
  EXPECT_EQ(replies[3].error().sequence(), 4u);
  EXPECT_TRUE(Violation(replies[3].error(), "frame.camera.fy", "INVALID"));
}

// The client library sends a frame's camera (FrameMeta::camera), and reports a refusal's field.
TEST_F(ContractTest, TheClientLibrarySendsAFramesCamera) {
  auto client = client::Client::Connect(server_->address());
  ASSERT_TRUE(client.ok()) << client.status();
  const cv::Mat depth = DepthMm(), colour = Colour();  // the input views their pixels
  auto input = client::DepthFrameFromMats(depth, colour);
  ASSERT_TRUE(input.ok()) << input.status();
  // No camera anywhere: refused, naming the field.
  auto refused = (*client)->Process(*input);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(refused.status().message().find("config.camera.fx"), std::string::npos);
  // The frame's own camera is enough.
  client::FrameMeta meta;
  meta.camera.emplace();
  meta.camera->set_fx(615);
  auto result = (*client)->Process(*input, {}, meta);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(Depths(result->cloud), (std::vector<int>{80, 120}));
}

TEST_F(ContractTest, GetInfoNamesTheRevisionAndAssumesNoCamera) {
  v1::ServerInfo info;
  grpc::ClientContext ctx;
  ASSERT_TRUE(stub_->GetInfo(&ctx, v1::GetInfoRequest(), &info).ok());
  EXPECT_EQ(info.contract_revision(), convert::kContractRevision);
  EXPECT_EQ(info.contract_revision(), "5");
  EXPECT_FALSE(info.defaults().camera().has_fx());
  EXPECT_FALSE(info.defaults().camera().has_fy());
  EXPECT_FALSE(info.defaults().camera().has_baseline());
  EXPECT_FALSE(info.defaults().passthrough().enabled());
}

}  // namespace
}  // namespace cloudcast
