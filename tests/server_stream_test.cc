// The server's results and delivery modes, end to end: a real cloudcast::server::Server on a
// loopback port, real gRPC through the generated stub, replies compared with the core pipeline
// run in-process.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <iostream>
#include <string>
#include <thread>
#include <vector>

#include "frame_input.h"
#include "support/server_support.h"
#include "support/waiting.h"

namespace cloudcast::server {
namespace {

// ---------------------------------------------------------------------------------------------
// Results.

class StreamInputTest : public ServerTest, public ::testing::WithParamInterface<Input> {};

TEST_P(StreamInputTest, StreamedSequenceMatchesCorePipeline) {
  const Input input = GetParam();
  const Params paper;
  std::vector<v1::StreamRequest> requests = {ConfigRequest(ConfigFor(paper, v1::DELIVERY_ALL))};
  for (std::size_t i = 0; i < Frames().size(); ++i) {
    requests.push_back(FrameRequest(MakeFrame(Frames()[i], 100 + i, input)));
  }
  const StreamResult result = RunStream(*stub_, requests);
  ASSERT_TRUE(result.status.ok()) << result.status.error_message();
  ASSERT_EQ(result.replies.size(), Frames().size());
  for (std::size_t i = 0; i < Frames().size(); ++i) {
    const v1::StreamReply& r = result.replies[i];
    ASSERT_TRUE(r.has_cloud()) << r.error().message();
    const v1::CloudReply& cloud = r.cloud();
    EXPECT_EQ(cloud.sequence(), 100 + i);
    EXPECT_EQ(cloud.frame_id(), Frames()[i].id);
    EXPECT_EQ(cloud.capture_time_unix_ns(), 1'700'000'000'000'000'000 + 100 + (long)i);
    EXPECT_EQ(cloud.frames_dropped(), 0u);
    EXPECT_EQ(cloud.counts().pixels(), 640u * 480u);
    EXPECT_GE(cloud.send_time_unix_ns(), cloud.receive_time_unix_ns());
    EXPECT_GT(cloud.times().pipeline_us() + cloud.times().encode_us(), 0u);
    if (input == Input::kRaw) {
      EXPECT_EQ(cloud.times().decode_us(), 0u);
    }
    EXPECT_LE(cloud.position_error_bound(), 0.03f / 4 + 1e-6f);  // the leaf/4 default
    EXPECT_TRUE(CloudMatches(Reference(Frames()[i], paper), cloud,
                             /*compare_colour=*/input != Input::kJpegColour))
        << Frames()[i].id;
  }
}

INSTANTIATE_TEST_SUITE_P(Inputs, StreamInputTest,
                         ::testing::Values(Input::kRaw, Input::kPng, Input::kJpegColour),
                         [](const auto& info) { return std::string(Name(info.param)); });

TEST_F(ServerTest, RawRowsWithPaddingAndOtherEncodings) {
  // Padded rows (row_stride > width x bytes) and RGBA colour are viewed in place correctly.
  const SourceFrame& f = Frames().front();
  const std::uint32_t w = f.disparity.width, h = f.disparity.height;
  v1::Frame frame = MakeFrame(f, 7);
  std::string disparity(static_cast<std::size_t>(w + 13) * h, '\0');
  std::string colour(static_cast<std::size_t>(w * 4 + 5) * h, '\0');
  for (std::uint32_t v = 0; v < h; ++v) {
    std::memcpy(&disparity[v * (w + 13)], f.disparity.pixels.data() + v * w, w);
    for (std::uint32_t u = 0; u < w; ++u) {
      const std::uint8_t* bgr = f.colour.pixels.data() + (v * w + u) * 3;
      char* rgba = &colour[v * (w * 4 + 5) + u * 4];
      rgba[0] = static_cast<char>(bgr[2]);
      rgba[1] = static_cast<char>(bgr[1]);
      rgba[2] = static_cast<char>(bgr[0]);
      rgba[3] = 0;  // alpha is ignored
    }
  }
  frame.mutable_disparity()->mutable_raw()->set_row_stride(w + 13);
  frame.mutable_disparity()->mutable_raw()->set_pixels(disparity);
  frame.mutable_color()->mutable_raw()->set_encoding(v1::COLOR_RGBA8);
  frame.mutable_color()->mutable_raw()->set_row_stride(w * 4 + 5);
  frame.mutable_color()->mutable_raw()->set_pixels(colour);
  const StreamResult result = RunStream(*stub_, {FrameRequest(frame)});
  ASSERT_TRUE(result.status.ok()) << result.status.error_message();
  ASSERT_EQ(result.replies.size(), 1u);
  ASSERT_TRUE(result.replies[0].has_cloud()) << result.replies[0].error().message();
  EXPECT_TRUE(CloudMatches(Reference(f, Params{}), result.replies[0].cloud()));
}

TEST_F(ServerTest, FloatDisparityAsTiffAndPfm) {
  // 32-bit float disparities arrive as TIFF or PFM files and keep their values.
  const SourceFrame& f = Frames().front();
  const std::uint32_t w = f.disparity.width, h = f.disparity.height;
  OwnedDisparity f32;
  f32.width = w;
  f32.height = h;
  f32.encoding = DisparityEncoding::kF32;
  f32.pixels.resize(std::size_t{w} * h * 4);
  for (std::size_t i = 0; i < std::size_t{w} * h; ++i) {
    const float d = f.disparity.pixels[i] * 0.5f + 0.25f * (f.disparity.pixels[i] > 0);
    std::memcpy(&f32.pixels[i * 4], &d, 4);
  }
  PipelineOptions o;
  o.camera = CameraModel::PclCompatible(w, h, 615.0);
  Pipeline pipeline;
  PointCloud reference;
  ASSERT_TRUE(pipeline.Run(o, f32.view(), f.colour.view(), &reference).ok());
  for (const char* ext : {".tiff", ".pfm"}) {
    SCOPED_TRACE(ext);
    std::vector<std::uint8_t> file;
    ASSERT_TRUE(cv::imencode(ext, cv::Mat(h, w, CV_32FC1, f32.pixels.data()), file));
    std::uint32_t sw = 0, sh = 0;
    const char* format = nullptr;
    ASSERT_TRUE(SniffImageSize(std::string(file.begin(), file.end()), &sw, &sh, &format));
    EXPECT_EQ(sw, w);
    EXPECT_EQ(sh, h);
    v1::Frame frame = MakeFrame(f, 1);
    frame.mutable_disparity()->set_encoded(file.data(), file.size());
    const StreamResult result = RunStream(*stub_, {FrameRequest(frame)});
    ASSERT_TRUE(result.status.ok());
    ASSERT_EQ(result.replies.size(), 1u);
    ASSERT_TRUE(result.replies[0].has_cloud()) << result.replies[0].error().message();
    EXPECT_TRUE(CloudMatches(reference, result.replies[0].cloud()));
  }
}

TEST_F(ServerTest, ConcurrentStreamsEachGetTheirOwnConfig) {
  const std::vector<Params> configs = {
      {0.03f, true, 3.0f, 12.0f},
      {0.05f, true, 2.0f, 8.0f},
      {0.10f, false, 0.0f, 0.0f},
      {0.0f, true, 4.0f, 6.0f},  // voxel grid off
  };
  const std::size_t frames = std::min<std::size_t>(Frames().size(), 5);
  std::vector<StreamResult> results(configs.size());
  std::vector<std::thread> clients;
  for (std::size_t s = 0; s < configs.size(); ++s) {
    clients.emplace_back([&, s] {
      auto stub = testing::NewStub(shared_server());  // a client of its own
      std::vector<v1::StreamRequest> requests = {
          ConfigRequest(ConfigFor(configs[s], v1::DELIVERY_ALL))};
      for (std::size_t i = 0; i < frames; ++i) {
        requests.push_back(FrameRequest(MakeFrame(Frames()[(i + s) % Frames().size()], i)));
      }
      results[s] = RunStream(*stub, requests);
    });
  }
  for (auto& t : clients) t.join();
  for (std::size_t s = 0; s < configs.size(); ++s) {
    SCOPED_TRACE("stream " + std::to_string(s));
    ASSERT_TRUE(results[s].status.ok()) << results[s].status.error_message();
    ASSERT_EQ(results[s].replies.size(), frames);
    for (std::size_t i = 0; i < frames; ++i) {
      ASSERT_TRUE(results[s].replies[i].has_cloud()) << results[s].replies[i].error().message();
      EXPECT_EQ(results[s].replies[i].cloud().sequence(), i);
      EXPECT_TRUE(CloudMatches(Reference(Frames()[(i + s) % Frames().size()], configs[s]),
                               results[s].replies[i].cloud()));
    }
  }
}

TEST_F(ServerTest, NewConfigAppliesToTheFramesAfterIt) {
  const Params a{0.03f, true, 3.0f, 12.0f};
  const Params b{0.2f, true, 1.0f, 20.0f};
  const SourceFrame& f = Frames().front();
  const StreamResult result = RunStream(
      *stub_, {ConfigRequest(ConfigFor(a, v1::DELIVERY_ALL)), FrameRequest(MakeFrame(f, 1)),
               ConfigRequest(ConfigFor(b, v1::DELIVERY_ALL)), FrameRequest(MakeFrame(f, 2))});
  ASSERT_TRUE(result.status.ok());
  ASSERT_EQ(result.replies.size(), 2u);
  EXPECT_TRUE(CloudMatches(Reference(f, a), result.replies[0].cloud()));
  EXPECT_TRUE(CloudMatches(Reference(f, b), result.replies[1].cloud()));
  EXPECT_NE(result.replies[0].cloud().point_count(), result.replies[1].cloud().point_count());
}

TEST_F(ServerTest, ProcessRpcMatchesCorePipeline) {
  const SourceFrame& f = Frames().back();
  v1::ProcessRequest request;
  *request.mutable_config() = ConfigFor(Params{0.05f, true, 2.0f, 10.0f}, v1::DELIVERY_LATEST);
  *request.mutable_frame() = MakeFrame(f, 42, Input::kPng);
  v1::CloudReply reply;
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  const grpc::Status status = stub_->Process(&ctx, request, &reply);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(reply.sequence(), 42u);
  EXPECT_GT(reply.times().decode_us(), 0u);
  EXPECT_TRUE(CloudMatches(Reference(f, Params{0.05f, true, 2.0f, 10.0f}), reply));
}

// ---------------------------------------------------------------------------------------------
// Delivery modes. The slow readers read through FixedWindow() channels and send kUnfiltered
// frames: a reader that stops reading stops the server's writes within a few replies.

TEST_F(ServerTest, LatestModeSlowReaderGetsDropsAndTheyAreReported) {
  // The client sends 30 frames as fast as it can and reads a reply every 50 ms: the server works
  // on one frame at a time and keeps reading while a reply is being written (up to
  // kMaxDropsPerWrite frames, then it waits for the reader), so the waiting frame keeps being
  // replaced. (A client that read nothing until it had written all 30 would block its own
  // writes: the server stops reading a LATEST stream whose replies are not taken, hardening
  // defect 6.)
  constexpr int kFrames = 30;
  auto stub = testing::NewStub(shared_server(), FixedWindow());
  std::vector<v1::StreamRequest> requests = {
      ConfigRequest(ConfigFor(kUnfiltered, v1::DELIVERY_LATEST))};
  for (int i = 0; i < kFrames; ++i) {
    requests.push_back(FrameRequest(MakeFrame(Frames()[i % Frames().size()], i)));
  }
  const StreamResult result = RunStream(*stub, requests, std::chrono::milliseconds(50));
  ASSERT_TRUE(result.status.ok()) << result.status.error_message();
  ASSERT_FALSE(result.replies.empty());
  std::uint64_t last_dropped = 0;
  std::int64_t last_sequence = -1;
  for (const auto& r : result.replies) {
    ASSERT_TRUE(r.has_cloud()) << r.error().message();
    EXPECT_GT(static_cast<std::int64_t>(r.cloud().sequence()), last_sequence);
    EXPECT_GE(r.cloud().frames_dropped(), last_dropped);
    last_sequence = static_cast<std::int64_t>(r.cloud().sequence());
    last_dropped = r.cloud().frames_dropped();
  }
  EXPECT_GT(last_dropped, 0u);
  EXPECT_LT(result.replies.size(), static_cast<std::size_t>(kFrames));
  // Every frame is either answered or counted as dropped, and the newest is always answered.
  EXPECT_EQ(result.replies.size() + last_dropped, static_cast<std::size_t>(kFrames));
  EXPECT_EQ(last_sequence, kFrames - 1);
}

TEST(ServerAllModeTest, SlowReaderGetsEveryFrameInOrderWithBoundedMemory) {
  ServerOptions options = testing::TestServerOptions();
  options.max_queued_frames = 3;
  auto server = testing::StartTestServer(options);
  ASSERT_NE(server, nullptr);
  auto stub = testing::NewStub(*server, FixedWindow());
  constexpr int kFrames = 24;
  std::vector<v1::StreamRequest> requests = {
      ConfigRequest(ConfigFor(kUnfiltered, v1::DELIVERY_ALL))};
  for (int i = 0; i < kFrames; ++i) {
    requests.push_back(FrameRequest(MakeFrame(Frames()[i % Frames().size()], i)));
  }
  // The slowest reader: it reads nothing until the server holds the stream's limit of frames
  // (its replies cannot be written, so it stops reading), then reads everything.
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  auto stream = stub->Stream(&ctx);
  std::thread writer([&] {
    for (const auto& r : requests) {
      if (!stream->Write(r)) break;
    }
    stream->WritesDone();
  });
  // The server announces no queue level: its high-water mark (this is its only stream) is polled.
  EXPECT_TRUE(testing::Eventually([&] { return server->queued_frames_high_water() >= 3; }))
      << "the server never held 3 frames of a stream whose client did not read";
  StreamResult result;
  v1::StreamReply reply;
  while (stream->Read(&reply)) result.replies.push_back(reply);
  writer.join();
  result.status = stream->Finish();

  ASSERT_TRUE(result.status.ok()) << result.status.error_message();
  ASSERT_EQ(result.replies.size(), static_cast<std::size_t>(kFrames));
  for (int i = 0; i < kFrames; ++i) {
    ASSERT_TRUE(result.replies[i].has_cloud());
    EXPECT_EQ(result.replies[i].cloud().sequence(), static_cast<std::uint64_t>(i));
    EXPECT_EQ(result.replies[i].cloud().frames_dropped(), 0u);
  }
  EXPECT_TRUE(CloudMatches(Reference(Frames()[5 % Frames().size()], kUnfiltered),
                           result.replies[5].cloud()));
  // The server held at most max_queued_frames frames of the stream, and did fill its queue.
  const std::uint32_t high_water = server->queued_frames_high_water();
  std::cout << "queued-frame high-water mark: " << high_water << " (limit 3)\n";
  EXPECT_EQ(high_water, 3u);
}

}  // namespace
}  // namespace cloudcast::server
