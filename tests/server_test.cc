// The gRPC server end to end: a real cloudcast::server::Server on a loopback ephemeral port, real
// gRPC through the generated stub. Results are compared with the core pipeline run in-process.
//
// Frames: the New Tsukuba sample when it is there, else frames of the synthetic scene (same size,
// same camera), so that every test runs on a fresh machine.
#include <arpa/inet.h>
#include <google/protobuf/descriptor.pb.h>
#include <google/protobuf/unknown_field_set.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "cloudcast/core/draco_codec.h"
#include "cloudcast/core/pipeline.h"
#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/io/image_io.h"
#include "cloudcast/server/cli.h"
#include "cloudcast/server/options.h"
#include "cloudcast/server/server.h"
#include "cloudcast/testing/metrics_scrape.h"
#include "cloudcast/v1/cloudcast.grpc.pb.h"
#include "frame_input.h"
#include "service.h"
#include "support/server_fixture.h"
#include "test_support.h"

namespace cloudcast::server {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;
using std::chrono::seconds;

// ---------------------------------------------------------------------------------------------
// Input frames.

struct SourceFrame {
  std::string id;
  OwnedDisparity disparity;  // 8-bit, as decoded
  OwnedColor colour;         // BGR8, as decoded
  std::string disparity_png;
  std::string colour_png;
  std::string colour_jpeg;
};

std::string ReadFileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string Encode(const char* ext, int w, int h, int type, const void* data,
                   std::vector<int> params = {}) {
  const cv::Mat m(h, w, type, const_cast<void*>(data));
  std::vector<std::uint8_t> out;
  EXPECT_TRUE(cv::imencode(ext, m, out, params));
  return std::string(out.begin(), out.end());
}

const std::vector<SourceFrame>& Frames() {
  static const std::vector<SourceFrame> frames = [] {
    std::vector<SourceFrame> out;
    if (testing::HaveTsukuba()) {
      for (const std::string& id : testing::TsukubaFrameIds()) {
        SourceFrame f;
        f.id = "tsukuba_" + id;
        f.disparity_png = ReadFileBytes(testing::TsukubaDisparityPath(id));
        f.colour_png = ReadFileBytes(testing::TsukubaColourPath(id));
        f.disparity = *DecodeDisparity(f.disparity_png);
        f.colour = *DecodeColor(f.colour_png);
        out.push_back(std::move(f));
      }
    } else {
      const SyntheticScene scene = SyntheticScene::Default();
      for (std::uint64_t i = 0; i < 6; ++i) {
        SyntheticOptions o;
        o.frame = i * 10;
        o.disparity_encoding = DisparityEncoding::kU8;
        const SyntheticFrame s = *scene.Render(o);
        SourceFrame f;
        f.id = "synthetic_" + std::to_string(i);
        f.disparity.pixels = s.disparity;
        f.disparity.width = s.width;
        f.disparity.height = s.height;
        f.disparity.encoding = DisparityEncoding::kU8;
        f.colour.pixels = s.colour;
        f.colour.width = s.width;
        f.colour.height = s.height;
        f.colour.encoding = ColorEncoding::kBGR8;
        f.disparity_png = Encode(".png", s.width, s.height, CV_8UC1, s.disparity.data());
        f.colour_png = Encode(".png", s.width, s.height, CV_8UC3, s.colour.data());
        out.push_back(std::move(f));
      }
    }
    for (SourceFrame& f : out) {
      f.colour_jpeg = Encode(".jpg", f.colour.width, f.colour.height, CV_8UC3,
                             f.colour.pixels.data(), {cv::IMWRITE_JPEG_QUALITY, 90});
    }
    return out;
  }();
  return frames;
}

enum class Input { kRaw, kPng, kJpegColour };
const char* Name(Input input) {
  switch (input) {
    case Input::kRaw:
      return "Raw";
    case Input::kPng:
      return "Png";
    default:
      return "JpegColour";
  }
}
void PrintTo(Input input, std::ostream* os) { *os << Name(input); }

v1::Frame MakeFrame(const SourceFrame& f, std::uint64_t sequence, Input input = Input::kRaw) {
  v1::Frame frame;
  frame.set_sequence(sequence);
  frame.set_frame_id(f.id);
  frame.set_capture_time_unix_ns(1'700'000'000'000'000'000 + static_cast<std::int64_t>(sequence));
  if (input == Input::kRaw) {
    v1::RawDisparity* d = frame.mutable_disparity()->mutable_raw();
    d->set_encoding(v1::DISPARITY_U8);
    d->set_width(f.disparity.width);
    d->set_height(f.disparity.height);
    d->set_pixels(f.disparity.pixels.data(), f.disparity.pixels.size());
    v1::RawColor* c = frame.mutable_colour()->mutable_raw();
    c->set_encoding(v1::COLOR_BGR8);
    c->set_width(f.colour.width);
    c->set_height(f.colour.height);
    c->set_pixels(f.colour.pixels.data(), f.colour.pixels.size());
  } else {
    frame.mutable_disparity()->set_encoded(f.disparity_png);
    frame.mutable_colour()->set_encoded(input == Input::kPng ? f.colour_png : f.colour_jpeg);
  }
  return frame;
}

v1::StreamRequest FrameRequest(v1::Frame frame) {
  v1::StreamRequest r;
  *r.mutable_frame() = std::move(frame);
  return r;
}

v1::StreamRequest ConfigRequest(const v1::StreamConfig& config) {
  v1::StreamRequest r;
  *r.mutable_config() = config;
  return r;
}

// ---------------------------------------------------------------------------------------------
// Stage parameters, built independently of the server's own translation.

struct Params {
  float leaf = 0.03f;  // 0: voxel grid off
  bool passthrough = true;
  float min = 3.0f;
  float max = 12.0f;
};

v1::StreamConfig ConfigFor(const Params& p, v1::DeliveryMode delivery) {
  v1::StreamConfig c;
  c.set_delivery(delivery);
  c.mutable_passthrough()->set_enabled(p.passthrough);
  c.mutable_passthrough()->set_min(p.min);
  c.mutable_passthrough()->set_max(p.max);
  if (p.leaf > 0) {
    c.mutable_voxel_grid()->set_leaf(p.leaf);
  } else {
    c.mutable_voxel_grid()->set_enabled(false);
  }
  return c;
}

PointCloud Reference(const SourceFrame& f, const Params& p) {
  PipelineOptions o;
  o.camera = CameraModel::PclCompatible(f.disparity.width, f.disparity.height, 615.0);
  o.passthrough.enabled = p.passthrough;
  o.passthrough.min = p.min;
  o.passthrough.max = p.max;
  o.voxel.enabled = p.leaf > 0;
  if (p.leaf > 0) o.voxel.SetLeaf(p.leaf);
  Pipeline pipeline;
  PointCloud cloud;
  EXPECT_TRUE(pipeline.Run(o, f.disparity.view(), f.colour.view(), &cloud).ok());
  return cloud;
}

// The reply's cloud is the core pipeline's `reference` within the quantization the reply reports.
::testing::AssertionResult CloudMatches(const PointCloud& reference, const v1::CloudReply& reply,
                                        bool compare_colour = true) {
  PointCloud decoded;
  if (absl::Status s = DecodeDraco(reply.draco(), &decoded); !s.ok()) {
    return ::testing::AssertionFailure() << "reply " << reply.sequence() << ": " << s;
  }
  if (reply.point_count() != reference.size()) {
    return ::testing::AssertionFailure() << "reply " << reply.sequence() << ": point_count "
                                         << reply.point_count() << ", core " << reference.size();
  }
  if (reply.counts().after_voxel_grid() != reference.size()) {
    return ::testing::AssertionFailure() << "counts.after_voxel_grid is wrong";
  }
  if (!reference.empty() && !(reply.position_error_bound() > 0)) {
    return ::testing::AssertionFailure() << "position_error_bound " << reply.position_error_bound();
  }
  return testing::CloudsMatch(
      reference, decoded,
      testing::CloudTolerance::DracoBound(reply.position_error_bound(), compare_colour));
}

// ---------------------------------------------------------------------------------------------
// Streams.

void SetDeadline(grpc::ClientContext* ctx, seconds s = seconds(120)) {
  ctx->set_deadline(std::chrono::system_clock::now() + s);
}

struct StreamResult {
  std::vector<v1::StreamReply> replies;
  grpc::Status status;
};

// Sends `requests` from a writer thread while this thread reads (a client that only wrote first
// would deadlock a lossless stream: the server stops reading when its queue is full).
// `read_delay` makes a slow reader. With `write_all_first`, reading starts only once every
// request is sent.
StreamResult RunStream(v1::CloudCast::Stub& stub, const std::vector<v1::StreamRequest>& requests,
                       milliseconds read_delay = milliseconds(0), bool write_all_first = false) {
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  auto stream = stub.Stream(&ctx);
  std::mutex mu;
  std::condition_variable cv;
  bool written = false;
  std::thread writer([&] {
    for (const auto& r : requests) {
      if (!stream->Write(r)) break;
    }
    stream->WritesDone();
    std::lock_guard<std::mutex> lock(mu);
    written = true;
    cv.notify_all();
  });
  if (write_all_first) {
    std::unique_lock<std::mutex> lock(mu);
    cv.wait(lock, [&] { return written; });
  }
  StreamResult result;
  v1::StreamReply reply;
  while (stream->Read(&reply)) {
    result.replies.push_back(reply);
    if (read_delay.count() > 0) std::this_thread::sleep_for(read_delay);  // a slow consumer
  }
  writer.join();
  result.status = stream->Finish();
  return result;
}

// Waits for `condition` with a deadline instead of sleeping a fixed time.
bool Eventually(const std::function<bool()>& condition,
                milliseconds timeout = milliseconds(10000)) {
  const Clock::time_point deadline = Clock::now() + timeout;
  while (Clock::now() < deadline) {
    if (condition()) return true;
    std::this_thread::sleep_for(milliseconds(5));
  }
  return condition();
}

// Health and reflection, spoken through the generic stub: their protos are not installed with
// Debian's gRPC, and their wire format is small enough to write by hand.
std::string ToBytes(const grpc::ByteBuffer& buffer) {
  std::vector<grpc::Slice> slices;
  EXPECT_TRUE(buffer.Dump(&slices).ok());
  std::string out;
  for (const auto& s : slices) out.append(reinterpret_cast<const char*>(s.begin()), s.size());
  return out;
}

grpc::ByteBuffer FromBytes(const std::string& bytes) {
  grpc::Slice slice(bytes);
  return grpc::ByteBuffer(&slice, 1);
}

// grpc.health.v1.Health/Check; the ServingStatus number (1 SERVING, 2 NOT_SERVING) or -1.
int HealthStatus(const std::shared_ptr<grpc::Channel>& channel, const std::string& service) {
  google::protobuf::UnknownFieldSet request;
  request.AddLengthDelimited(1, service);
  std::string bytes;
  request.SerializeToString(&bytes);
  grpc::GenericStub stub(channel);
  grpc::CompletionQueue cq;
  grpc::ClientContext ctx;
  SetDeadline(&ctx, seconds(10));
  auto call = stub.PrepareUnaryCall(&ctx, "/grpc.health.v1.Health/Check", FromBytes(bytes), &cq);
  call->StartCall();
  grpc::ByteBuffer response;
  grpc::Status status;
  call->Finish(&response, &status, reinterpret_cast<void*>(1));
  void* tag;
  bool ok;
  EXPECT_TRUE(cq.Next(&tag, &ok));
  cq.Shutdown();
  while (cq.Next(&tag, &ok)) {
  }
  if (!status.ok()) return -1;
  google::protobuf::UnknownFieldSet fields;
  EXPECT_TRUE(fields.ParseFromString(ToBytes(response)));
  for (int i = 0; i < fields.field_count(); ++i) {
    if (fields.field(i).number() == 1) return static_cast<int>(fields.field(i).varint());
  }
  return 0;  // proto3 default: UNKNOWN
}

// One grpc.reflection.v1alpha request; the raw ServerReflectionResponse.
std::unique_ptr<google::protobuf::UnknownFieldSet> Reflect(
    const std::shared_ptr<grpc::Channel>& channel, int request_field, const std::string& value) {
  google::protobuf::UnknownFieldSet request;
  request.AddLengthDelimited(request_field, value);
  std::string bytes;
  request.SerializeToString(&bytes);
  grpc::GenericStub stub(channel);
  grpc::CompletionQueue cq;
  grpc::ClientContext ctx;
  SetDeadline(&ctx, seconds(10));
  auto call =
      stub.PrepareCall(&ctx, "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo", &cq);
  void* tag;
  bool ok;
  auto step = [&] {
    EXPECT_TRUE(cq.Next(&tag, &ok));
    return ok;
  };
  call->StartCall(reinterpret_cast<void*>(1));
  EXPECT_TRUE(step());
  call->Write(FromBytes(bytes), reinterpret_cast<void*>(2));
  EXPECT_TRUE(step());
  grpc::ByteBuffer response;
  call->Read(&response, reinterpret_cast<void*>(3));
  const bool read = step();
  call->WritesDone(reinterpret_cast<void*>(4));
  step();
  grpc::Status status;
  call->Finish(&status, reinterpret_cast<void*>(5));
  step();
  EXPECT_TRUE(status.ok()) << status.error_message();
  cq.Shutdown();
  while (cq.Next(&tag, &ok)) {
  }
  auto fields = std::make_unique<google::protobuf::UnknownFieldSet>();
  if (read) {
    EXPECT_TRUE(fields->ParseFromString(ToBytes(response)));
  }
  return fields;
}

const google::protobuf::UnknownField* FieldOf(const google::protobuf::UnknownFieldSet& set,
                                              int number) {
  for (int i = 0; i < set.field_count(); ++i) {
    if (set.field(i).number() == number) return &set.field(i);
  }
  return nullptr;
}

using cloudcast::server::MetricValue;

// ---------------------------------------------------------------------------------------------
// The shared server for the tests that need nothing special.

class ServerTest : public testing::SharedServerTest {
 protected:
  void SetUp() override {
    testing::SharedServerTest::SetUp();
    stub_ = testing::NewStub(shared_server());
  }

  std::unique_ptr<v1::CloudCast::Stub> stub_;
};

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
  frame.mutable_colour()->mutable_raw()->set_encoding(v1::COLOR_RGBA8);
  frame.mutable_colour()->mutable_raw()->set_row_stride(w * 4 + 5);
  frame.mutable_colour()->mutable_raw()->set_pixels(colour);
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
      auto stub = testing::NewStub(shared_server());  // a channel of its own
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
// Delivery modes.

TEST_F(ServerTest, LatestModeSlowReaderGetsDropsAndTheyAreReported) {
  // The client sends 30 frames without reading a reply: the server keeps reading, works on one
  // frame at a time and cannot write past the client's flow-control window, so the waiting frame
  // keeps being replaced.
  constexpr int kFrames = 30;
  std::vector<v1::StreamRequest> requests = {
      ConfigRequest(ConfigFor(Params{}, v1::DELIVERY_LATEST))};
  for (int i = 0; i < kFrames; ++i) {
    requests.push_back(FrameRequest(MakeFrame(Frames()[i % Frames().size()], i)));
  }
  const StreamResult result =
      RunStream(*stub_, requests, milliseconds(20), /*write_all_first=*/true);
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
  auto stub = testing::NewStub(*server);
  constexpr int kFrames = 24;
  std::vector<v1::StreamRequest> requests = {ConfigRequest(ConfigFor(Params{}, v1::DELIVERY_ALL))};
  for (int i = 0; i < kFrames; ++i) {
    requests.push_back(FrameRequest(MakeFrame(Frames()[i % Frames().size()], i)));
  }
  const StreamResult result = RunStream(*stub, requests, milliseconds(30));
  ASSERT_TRUE(result.status.ok()) << result.status.error_message();
  ASSERT_EQ(result.replies.size(), static_cast<std::size_t>(kFrames));
  for (int i = 0; i < kFrames; ++i) {
    ASSERT_TRUE(result.replies[i].has_cloud());
    EXPECT_EQ(result.replies[i].cloud().sequence(), static_cast<std::uint64_t>(i));
    EXPECT_EQ(result.replies[i].cloud().frames_dropped(), 0u);
  }
  EXPECT_TRUE(
      CloudMatches(Reference(Frames()[5 % Frames().size()], Params{}), result.replies[5].cloud()));
  // The server held at most max_queued_frames frames of the stream, and did fill its queue.
  const std::uint32_t high_water = server->queued_frames_high_water();
  std::cout << "queued-frame high-water mark: " << high_water << " (limit 3)\n";
  EXPECT_LE(high_water, 3u);
  EXPECT_GE(high_water, 2u);
}

// ---------------------------------------------------------------------------------------------
// Bad input.

struct BadFrameCase {
  std::string name;
  std::function<void(v1::Frame*)> spoil;
  grpc::StatusCode code;
  std::vector<std::string> message_has;
};

std::string PngWithSize(std::uint32_t w, std::uint32_t h) {
  std::string png = Frames().front().disparity_png;
  for (int i = 0; i < 4; ++i) {
    png[16 + i] = static_cast<char>(w >> (24 - 8 * i));
    png[20 + i] = static_cast<char>(h >> (24 - 8 * i));
  }
  return png;
}

// A little-endian TIFF whose first directory claims w x h (and holds nothing else).
std::string TiffHeader(std::uint32_t w, std::uint32_t h) {
  std::string t = {'I', 'I', 42, 0, 8, 0, 0, 0, 2, 0};
  auto entry = [&](std::uint16_t tag, std::uint32_t value) {
    const std::uint8_t e[12] = {std::uint8_t(tag),
                                std::uint8_t(tag >> 8),
                                4,
                                0,
                                1,
                                0,
                                0,
                                0,
                                std::uint8_t(value),
                                std::uint8_t(value >> 8),
                                std::uint8_t(value >> 16),
                                std::uint8_t(value >> 24)};
    t.append(reinterpret_cast<const char*>(e), 12);
  };
  entry(256, w);
  entry(257, h);
  t.append(4, '\0');
  return t;
}

std::string JpegWithSize(std::uint16_t w, std::uint16_t h) {
  std::string jpeg = Frames().front().colour_jpeg;
  // Walk the marker segments to the start of frame (baseline or progressive) and patch its size.
  auto byte = [&](std::size_t i) { return static_cast<unsigned char>(jpeg[i]); };
  for (std::size_t i = 2; i + 9 < jpeg.size();) {
    const unsigned char marker = byte(i + 1);
    if (marker == 0xC0 || marker == 0xC1 || marker == 0xC2) {
      jpeg[i + 5] = static_cast<char>(h >> 8);
      jpeg[i + 6] = static_cast<char>(h & 0xFF);
      jpeg[i + 7] = static_cast<char>(w >> 8);
      jpeg[i + 8] = static_cast<char>(w & 0xFF);
      return jpeg;
    }
    i += 2 + ((std::size_t{byte(i + 2)} << 8) | byte(i + 3));
  }
  ADD_FAILURE() << "no start-of-frame marker in the JPEG";
  return jpeg;
}

std::vector<BadFrameCase> BadFrameCases() {
  const auto kInvalid = grpc::StatusCode::INVALID_ARGUMENT;
  const auto kExhausted = grpc::StatusCode::RESOURCE_EXHAUSTED;
  const SourceFrame& f = Frames().front();
  return {
      {"missing disparity",
       [](v1::Frame* fr) { fr->clear_disparity(); },
       kInvalid,
       {"frame.disparity is missing"}},
      {"missing colour",
       [](v1::Frame* fr) { fr->clear_colour(); },
       kInvalid,
       {"frame.colour is missing"}},
      {"unspecified disparity encoding",
       [](v1::Frame* fr) {
         fr->mutable_disparity()->mutable_raw()->set_encoding(v1::DISPARITY_ENCODING_UNSPECIFIED);
       },
       kInvalid,
       {"frame.disparity.raw.encoding", "DISPARITY_ENCODING_UNSPECIFIED"}},
      {"unknown colour encoding",
       [](v1::Frame* fr) {
         fr->mutable_colour()->mutable_raw()->set_encoding(static_cast<v1::ColorEncoding>(42));
       },
       kInvalid,
       {"frame.colour.raw.encoding is 42"}},
      {"zero width",
       [](v1::Frame* fr) { fr->mutable_disparity()->mutable_raw()->set_width(0); },
       kInvalid,
       {"frame.disparity.raw.width is 0"}},
      {"zero height",
       [](v1::Frame* fr) { fr->mutable_colour()->mutable_raw()->set_height(0); },
       kInvalid,
       {"frame.colour.raw.height is 0"}},
      {"disparity row_stride too small",
       [](v1::Frame* fr) { fr->mutable_disparity()->mutable_raw()->set_row_stride(100); },
       kInvalid,
       {"frame.disparity.raw.row_stride is 100, less than width x 1 = 640"}},
      {"colour row_stride too small",
       [](v1::Frame* fr) { fr->mutable_colour()->mutable_raw()->set_row_stride(1000); },
       kInvalid,
       {"frame.colour.raw.row_stride is 1000, less than width x 3 = 1920"}},
      {"disparity pixels too short",
       [](v1::Frame* fr) {
         fr->mutable_disparity()->mutable_raw()->mutable_pixels()->resize(1000);
       },
       kInvalid,
       {"frame.disparity.raw.pixels holds 1000 bytes", "needs 307200"}},
      {"colour pixels too short for its stride",
       [](v1::Frame* fr) { fr->mutable_colour()->mutable_raw()->set_row_stride(1921); },
       kInvalid,
       {"frame.colour.raw.pixels holds 921600 bytes", "row_stride 1921"}},
      {"u16 pixels too short",
       [](v1::Frame* fr) {
         fr->mutable_disparity()->mutable_raw()->set_encoding(v1::DISPARITY_U16);
       },
       kInvalid,
       {"frame.disparity.raw.pixels holds 307200 bytes", "DISPARITY_U16"}},
      {"sizes differ",
       [](v1::Frame* fr) {
         v1::RawColor* c = fr->mutable_colour()->mutable_raw();
         c->set_width(320);
         c->set_height(240);
       },
       kInvalid,
       {"frame.colour is 320x240 but frame.disparity is 640x480"}},
      {"unknown image format",
       [](v1::Frame* fr) { fr->mutable_disparity()->set_encoded("this is not a PNG"); },
       kInvalid,
       {"frame.disparity.encoded is not a PNG, JPEG, TIFF, PNM or PFM image"}},
      {"undecodable PNG body",
       [&f](v1::Frame* fr) {
         std::string png = f.disparity_png;
         std::fill(png.begin() + 40, png.end(), 'x');
         fr->mutable_disparity()->set_encoded(png);
       },
       kInvalid,
       {"frame.disparity.encoded: cannot be decoded"}},
      {"truncated colour PNG",
       [&f](v1::Frame* fr) { fr->mutable_colour()->set_encoded(f.colour_png.substr(0, 200)); },
       kInvalid,
       {"frame.colour.encoded"}},
      {"empty encoded disparity",
       [](v1::Frame* fr) { fr->mutable_disparity()->set_encoded(""); },
       kInvalid,
       {"frame.disparity.encoded is empty"}},
      {"multi-channel disparity file",
       [&f](v1::Frame* fr) {
         fr->mutable_disparity()->set_encoded(
             Encode(".png", f.colour.width, f.colour.height, CV_8UC3, f.colour.pixels.data()));
       },
       kInvalid,
       {"frame.disparity.encoded", "3 channels", "one"}},
      {"side over the limit",
       [](v1::Frame* fr) {
         fr->mutable_disparity()->mutable_raw()->set_width(20000);
         fr->mutable_disparity()->mutable_raw()->set_height(1);
       },
       kExhausted,
       {"frame.disparity.raw is 20000x1", "the limit is 16384 pixels per side"}},
      {"pixels over the limit",
       [](v1::Frame* fr) {
         fr->mutable_colour()->mutable_raw()->set_width(5000);
         fr->mutable_colour()->mutable_raw()->set_height(5000);
       },
       kExhausted,
       {"frame.colour.raw is 5000x5000 = 25000000 pixels", "the limit is 16777216"}},
      {"PNG header over the limit",
       [](v1::Frame* fr) { fr->mutable_disparity()->set_encoded(PngWithSize(16000, 16000)); },
       kExhausted,
       {"frame.disparity.encoded (PNG) is 16000x16000", "16777216"}},
      {"TIFF header over the limit",
       [](v1::Frame* fr) { fr->mutable_disparity()->set_encoded(TiffHeader(30000, 30000)); },
       kExhausted,
       {"frame.disparity.encoded (TIFF) is 30000x30000", "16384 pixels per side"}},
      {"PNM header over the limit",
       [](v1::Frame* fr) {
         fr->mutable_colour()->set_encoded("P6\n# a comment\n5000 4000\n255\n");
       },
       kExhausted,
       {"frame.colour.encoded (PNM) is 5000x4000 = 20000000 pixels"}},
      {"JPEG header over the limit",
       [](v1::Frame* fr) { fr->mutable_colour()->set_encoded(JpegWithSize(30000, 2)); },
       kExhausted,
       {"frame.colour.encoded (JPEG) is 30000x2", "16384 pixels per side"}},
  };
}

struct BadConfigCase {
  std::string name;
  std::function<void(v1::StreamConfig*)> spoil;
  std::vector<std::string> message_has;
};

std::vector<BadConfigCase> BadConfigCases() {
  return {
      {"fx zero",
       [](v1::StreamConfig* c) { c->mutable_camera()->set_fx(0); },
       {"config.camera.fx must be finite and in (0, 1e9], got 0"}},
      {"fx NaN",
       [](v1::StreamConfig* c) { c->mutable_camera()->set_fx(std::nan("")); },
       {"config.camera.fx", "nan"}},
      {"baseline negative",
       [](v1::StreamConfig* c) { c->mutable_camera()->set_baseline(-1); },
       {"config.camera.baseline"}},
      {"disparity_scale zero",
       [](v1::StreamConfig* c) { c->mutable_camera()->set_disparity_scale(0); },
       {"config.camera.disparity_scale must not be 0"}},
      {"too many invalid disparities",
       [](v1::StreamConfig* c) {
         for (int i = 0; i < 17; ++i)
           c->mutable_camera()->mutable_invalid_disparities()->add_values(i);
       },
       {"config.camera.invalid_disparities.values holds 17 values; the limit is 16"}},
      {"leaf zero",
       [](v1::StreamConfig* c) { c->mutable_voxel_grid()->set_leaf(0); },
       {"config.voxel_grid.leaf must be finite and > 0", "got 0"}},
      {"leaf negative",
       [](v1::StreamConfig* c) { c->mutable_voxel_grid()->set_leaf_y(-0.5f); },
       {"config.voxel_grid.leaf_y", "got -0.5"}},
      {"min above max",
       [](v1::StreamConfig* c) {
         c->mutable_passthrough()->set_min(20);
         c->mutable_passthrough()->clear_max();
       },
       {"config.passthrough.min (20) must not exceed config.passthrough.max (12, the server "
        "default)"}},
      {"min NaN",
       [](v1::StreamConfig* c) { c->mutable_passthrough()->set_min(std::nanf("")); },
       {"config.passthrough.min must be finite"}},
      {"unknown axis",
       [](v1::StreamConfig* c) { c->mutable_passthrough()->set_axis(static_cast<v1::Axis>(9)); },
       {"config.passthrough.axis is 9"}},
      {"draco bits out of range",
       [](v1::StreamConfig* c) { c->mutable_draco()->set_position_bits(31); },
       {"config.draco.position_bits is 31; it must be in [1, 30]"}},
      {"draco colour bits zero",
       [](v1::StreamConfig* c) { c->mutable_draco()->set_color_bits(0); },
       {"config.draco.color_bits is 0; it must be in [1, 8]"}},
      {"draco speed out of range",
       [](v1::StreamConfig* c) { c->mutable_draco()->set_encode_speed(11); },
       {"config.draco.encode_speed is 11; it must be in [0, 10]"}},
      {"draco negative error",
       [](v1::StreamConfig* c) { c->mutable_draco()->set_max_position_error(-1); },
       {"config.draco.max_position_error must be finite and >= 0"}},
      {"unknown delivery",
       [](v1::StreamConfig* c) { c->set_delivery(static_cast<v1::DeliveryMode>(7)); },
       {"config.delivery is 7"}},
  };
}

::testing::AssertionResult IsError(const v1::StreamReply& reply, grpc::StatusCode code,
                                   std::uint64_t sequence, const std::vector<std::string>& has) {
  if (!reply.has_error()) return ::testing::AssertionFailure() << "not an error reply";
  const v1::FrameError& e = reply.error();
  if (e.code() != static_cast<int>(code)) {
    return ::testing::AssertionFailure()
           << "code " << e.code() << ", want " << code << ": " << e.message();
  }
  if (e.sequence() != sequence) {
    return ::testing::AssertionFailure() << "sequence " << e.sequence() << ", want " << sequence;
  }
  for (const std::string& s : has) {
    if (e.message().find(s) == std::string::npos) {
      return ::testing::AssertionFailure()
             << "message \"" << e.message() << "\" lacks \"" << s << "\"";
    }
  }
  return ::testing::AssertionSuccess() << e.message();
}

TEST_F(ServerTest, BadFramesAndConfigsGetNamedErrorsAndEveryStreamGoesOn) {
  const std::vector<BadFrameCase> frame_cases = BadFrameCases();
  const std::vector<BadConfigCase> config_cases = BadConfigCases();
  const Params before{0.1f, true, 3.0f, 12.0f};  // the config in force throughout
  const SourceFrame& f = Frames().front();

  // A second stream streams good frames meanwhile; it must not notice anything.
  std::atomic<bool> stop{false};
  StreamResult bystander;
  std::thread other([&] {
    auto stub = testing::NewStub(shared_server());
    grpc::ClientContext ctx;
    SetDeadline(&ctx);
    auto stream = stub->Stream(&ctx);
    stream->Write(ConfigRequest(ConfigFor(Params{}, v1::DELIVERY_ALL)));
    v1::StreamReply reply;
    for (std::uint64_t i = 0; !stop.load(); ++i) {
      if (!stream->Write(FrameRequest(MakeFrame(Frames()[i % Frames().size()], i)))) break;
      if (!stream->Read(&reply)) break;
      bystander.replies.push_back(reply);
    }
    stream->WritesDone();
    while (stream->Read(&reply)) bystander.replies.push_back(reply);
    bystander.status = stream->Finish();
  });

  std::vector<v1::StreamRequest> requests = {ConfigRequest(ConfigFor(before, v1::DELIVERY_ALL))};
  std::uint64_t sequence = 1;
  for (const BadFrameCase& c : frame_cases) {
    v1::Frame bad = MakeFrame(f, sequence++);
    c.spoil(&bad);
    requests.push_back(FrameRequest(bad));
    requests.push_back(FrameRequest(MakeFrame(f, sequence++)));
  }
  for (const BadConfigCase& c : config_cases) {
    v1::StreamConfig bad = ConfigFor(before, v1::DELIVERY_ALL);
    c.spoil(&bad);
    requests.push_back(ConfigRequest(bad));
    requests.push_back(FrameRequest(MakeFrame(f, sequence++)));
  }
  requests.push_back(v1::StreamRequest());  // neither config nor frame
  requests.push_back(FrameRequest(MakeFrame(f, sequence++)));
  const StreamResult result = RunStream(*stub_, requests);
  stop.store(true);
  other.join();

  ASSERT_TRUE(result.status.ok()) << result.status.error_message();
  ASSERT_EQ(result.replies.size(), 2 * (frame_cases.size() + config_cases.size() + 1));
  const PointCloud expected = Reference(f, before);
  std::size_t r = 0;
  std::uint64_t s = 1;
  for (const BadFrameCase& c : frame_cases) {
    SCOPED_TRACE(c.name);
    EXPECT_TRUE(IsError(result.replies[r++], c.code, s++, c.message_has));
    ASSERT_TRUE(result.replies[r].has_cloud()) << result.replies[r].error().message();
    EXPECT_EQ(result.replies[r].cloud().sequence(), s++);
    EXPECT_TRUE(CloudMatches(expected, result.replies[r++].cloud()));
  }
  for (const BadConfigCase& c : config_cases) {
    SCOPED_TRACE(c.name);
    EXPECT_TRUE(IsError(result.replies[r++], grpc::StatusCode::INVALID_ARGUMENT, 0, c.message_has));
    // The previous config (leaf 0.1) is still in force.
    ASSERT_TRUE(result.replies[r].has_cloud()) << result.replies[r].error().message();
    EXPECT_EQ(result.replies[r].cloud().sequence(), s++);
    EXPECT_TRUE(CloudMatches(expected, result.replies[r++].cloud()));
  }
  EXPECT_TRUE(IsError(result.replies[r++], grpc::StatusCode::INVALID_ARGUMENT, 0, {"neither"}));
  EXPECT_TRUE(result.replies[r++].has_cloud());

  ASSERT_TRUE(bystander.status.ok()) << bystander.status.error_message();
  ASSERT_FALSE(bystander.replies.empty());
  for (std::size_t i = 0; i < bystander.replies.size(); ++i) {
    ASSERT_TRUE(bystander.replies[i].has_cloud());
    EXPECT_EQ(bystander.replies[i].cloud().sequence(), i);
  }
}

TEST_F(ServerTest, ProcessRpcReturnsFrameErrorsAsStatus) {
  const SourceFrame& f = Frames().front();
  auto process = [&](const v1::ProcessRequest& request) {
    v1::CloudReply reply;
    grpc::ClientContext ctx;
    SetDeadline(&ctx);
    return stub_->Process(&ctx, request, &reply);
  };
  v1::ProcessRequest request;
  *request.mutable_frame() = MakeFrame(f, 1);
  request.mutable_frame()->mutable_disparity()->mutable_raw()->set_row_stride(100);
  grpc::Status status = process(request);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("frame.disparity.raw.row_stride is 100"), std::string::npos)
      << status.error_message();

  *request.mutable_frame() = MakeFrame(f, 1);
  request.mutable_config()->mutable_camera()->set_fx(0);
  status = process(request);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("config.camera.fx"), std::string::npos)
      << status.error_message();

  request.clear_config();
  request.mutable_frame()->mutable_colour()->mutable_raw()->set_width(100000);
  status = process(request);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(status.error_message().find("frame.colour.raw is 100000x480"), std::string::npos)
      << status.error_message();

  *request.mutable_frame() = MakeFrame(f, 1);
  EXPECT_TRUE(process(request).ok());
}

TEST(ServerLimitsTest, MessageOverTheSizeLimitEndsOnlyItsCall) {
  ServerOptions options = testing::TestServerOptions();
  options.max_message_bytes = 1 << 20;  // a raw 640x480 frame is 1.2 MB
  auto server = testing::StartTestServer(options);
  ASSERT_NE(server, nullptr);
  auto stub = testing::NewStub(*server);
  const SourceFrame& f = Frames().front();
  const StreamResult big = RunStream(*stub, {FrameRequest(MakeFrame(f, 1))});
  EXPECT_EQ(big.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED)
      << big.status.error_message();
  EXPECT_NE(big.status.error_message().find(std::to_string(1 << 20)), std::string::npos)
      << big.status.error_message();
  // PNG-encoded frames fit, on a new stream of the same channel.
  const StreamResult small = RunStream(*stub, {FrameRequest(MakeFrame(f, 2, Input::kPng))});
  ASSERT_TRUE(small.status.ok()) << small.status.error_message();
  ASSERT_EQ(small.replies.size(), 1u);
  EXPECT_TRUE(small.replies[0].has_cloud());
}

TEST(ServerLimitsTest, TooManyStreamsGetResourceExhausted) {
  ServerOptions options = testing::TestServerOptions();
  options.max_streams = 2;
  auto server = testing::StartTestServer(options);
  ASSERT_NE(server, nullptr);
  auto stub = testing::NewStub(*server);
  const SourceFrame& f = Frames().front();
  // Two streams, each proven open by a round trip.
  std::vector<std::unique_ptr<grpc::ClientContext>> contexts;
  std::vector<std::unique_ptr<grpc::ClientReaderWriter<v1::StreamRequest, v1::StreamReply>>>
      streams;
  for (int i = 0; i < 2; ++i) {
    contexts.push_back(std::make_unique<grpc::ClientContext>());
    SetDeadline(contexts.back().get());
    streams.push_back(stub->Stream(contexts.back().get()));
    ASSERT_TRUE(streams.back()->Write(FrameRequest(MakeFrame(f, i))));
    v1::StreamReply reply;
    ASSERT_TRUE(streams.back()->Read(&reply));
    ASSERT_TRUE(reply.has_cloud());
  }
  EXPECT_EQ(server->service().active_streams(), 2);
  const StreamResult third = RunStream(*stub, {FrameRequest(MakeFrame(f, 3))});
  EXPECT_EQ(third.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(third.status.error_message().find("limit is 2"), std::string::npos)
      << third.status.error_message();
  EXPECT_NE(third.status.error_message().find("--max-streams"), std::string::npos);
  EXPECT_TRUE(third.replies.empty());

  // Once one ends, a new stream is accepted.
  streams[0]->WritesDone();
  EXPECT_TRUE(streams[0]->Finish().ok());
  ASSERT_TRUE(Eventually([&] { return server->service().active_streams() == 1; }));
  const StreamResult fourth = RunStream(*stub, {FrameRequest(MakeFrame(f, 4))});
  EXPECT_TRUE(fourth.status.ok()) << fourth.status.error_message();
  EXPECT_EQ(fourth.replies.size(), 1u);
  streams[1]->WritesDone();
  EXPECT_TRUE(streams[1]->Finish().ok());
}

TEST(ServerLimitsTest, IdleStreamIsEndedWithDeadlineExceeded) {
  ServerOptions options = testing::TestServerOptions();
  options.idle_timeout = milliseconds(1000);
  auto server = testing::StartTestServer(options);
  ASSERT_NE(server, nullptr);
  auto stub = testing::NewStub(*server);
  const SourceFrame& f = Frames().front();

  // A stream that keeps sending (every 400 ms, under the timeout) stays open.
  {
    grpc::ClientContext ctx;
    SetDeadline(&ctx, seconds(30));
    auto stream = stub->Stream(&ctx);
    v1::StreamReply reply;
    for (int i = 0; i < 4; ++i) {
      ASSERT_TRUE(stream->Write(FrameRequest(MakeFrame(f, i))));
      ASSERT_TRUE(stream->Read(&reply)) << "ended after " << i << " frames";
      std::this_thread::sleep_for(milliseconds(400));  // the client's pace, not a wait
    }
    stream->WritesDone();
    EXPECT_TRUE(stream->Finish().ok());
  }
  // A silent one is ended, after about the timeout, by the server (not by our 30 s deadline).
  grpc::ClientContext ctx;
  SetDeadline(&ctx, seconds(30));
  const Clock::time_point start = Clock::now();
  auto stream = stub->Stream(&ctx);
  v1::StreamReply reply;
  EXPECT_FALSE(stream->Read(&reply));
  const grpc::Status status = stream->Finish();
  const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
  EXPECT_EQ(status.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED) << status.error_message();
  EXPECT_NE(status.error_message().find("idle"), std::string::npos) << status.error_message();
  EXPECT_GE(elapsed, 0.9);
  EXPECT_LT(elapsed, 10.0);
  EXPECT_TRUE(Eventually([&] { return server->service().active_streams() == 0; }));

  // A lossless stream whose client sends until the server stops reading and never reads a reply
  // holds its slot only for the timeout: nothing moves, so the server cancels it.
  grpc::ClientContext stuck_ctx;
  SetDeadline(&stuck_ctx, seconds(30));
  auto stuck = stub->Stream(&stuck_ctx);
  std::atomic<bool> writer_done{false};
  std::thread writer([&] {
    stuck->Write(ConfigRequest(ConfigFor(Params{}, v1::DELIVERY_ALL)));
    for (std::uint64_t i = 0; stuck->Write(FrameRequest(MakeFrame(f, i))); ++i) {
    }
    writer_done.store(true);
  });
  ASSERT_TRUE(Eventually([&] { return server->service().active_streams() == 1; }));
  EXPECT_TRUE(
      Eventually([&] { return server->service().active_streams() == 0; }, milliseconds(15000)));
  EXPECT_TRUE(Eventually([&] { return writer_done.load(); }));
  writer.join();
  while (stuck->Read(&reply)) {
  }
  const grpc::Status stuck_status = stuck->Finish();
  EXPECT_EQ(stuck_status.error_code(), grpc::StatusCode::CANCELLED) << stuck_status.error_message();
}

// ---------------------------------------------------------------------------------------------
// Cancellation, shutdown, health, reflection, info, metrics.

TEST_F(ServerTest, ClientCancelsMidStreamAndTheServerCarriesOn) {
  {
    grpc::ClientContext ctx;
    SetDeadline(&ctx);
    auto stream = stub_->Stream(&ctx);
    ASSERT_TRUE(stream->Write(ConfigRequest(ConfigFor(Params{}, v1::DELIVERY_ALL))));
    std::atomic<bool> stop{false};
    std::thread writer([&] {
      for (std::uint64_t i = 0; !stop.load(); ++i) {
        if (!stream->Write(FrameRequest(MakeFrame(Frames()[i % Frames().size()], i)))) break;
      }
    });
    v1::StreamReply reply;
    int replies = 0;
    while (replies < 3 && stream->Read(&reply)) ++replies;
    EXPECT_EQ(replies, 3);
    ctx.TryCancel();
    stop.store(true);
    writer.join();
    while (stream->Read(&reply)) {
    }
    EXPECT_EQ(stream->Finish().error_code(), grpc::StatusCode::CANCELLED);
  }
  EXPECT_TRUE(Eventually([&] { return shared_server().service().active_streams() == 0; }));
  EXPECT_EQ(HealthStatus(testing::NewChannel(shared_server()), ""), 1);
  const StreamResult after = RunStream(*stub_, {FrameRequest(MakeFrame(Frames()[1], 9))});
  ASSERT_TRUE(after.status.ok());
  ASSERT_EQ(after.replies.size(), 1u);
  EXPECT_TRUE(CloudMatches(Reference(Frames()[1], Params{}), after.replies[0].cloud()));
}

TEST_F(ServerTest, HealthCheckingAndReflectionAnswer) {
  const auto channel = testing::NewChannel(shared_server());
  EXPECT_EQ(HealthStatus(channel, ""), 1);  // SERVING
  EXPECT_EQ(HealthStatus(channel, "cloudcast.v1.CloudCast"), 1);

  // list_services (field 7) -> list_services_response (6) -> service (1) -> name (1).
  const auto listed = Reflect(channel, 7, "");
  const auto* list = FieldOf(*listed, 6);
  ASSERT_NE(list, nullptr);
  google::protobuf::UnknownFieldSet services;
  ASSERT_TRUE(services.ParseFromString(list->length_delimited()));
  std::vector<std::string> names;
  for (int i = 0; i < services.field_count(); ++i) {
    google::protobuf::UnknownFieldSet service;
    ASSERT_TRUE(service.ParseFromString(services.field(i).length_delimited()));
    if (const auto* name = FieldOf(service, 1)) names.push_back(name->length_delimited());
  }
  EXPECT_NE(std::find(names.begin(), names.end(), "cloudcast.v1.CloudCast"), names.end());
  EXPECT_NE(std::find(names.begin(), names.end(), "grpc.health.v1.Health"), names.end());

  // file_containing_symbol (4) -> file_descriptor_response (4) -> file_descriptor_proto (1).
  const auto file = Reflect(channel, 4, "cloudcast.v1.CloudCast");
  const auto* response = FieldOf(*file, 4);
  ASSERT_NE(response, nullptr);
  google::protobuf::UnknownFieldSet files;
  ASSERT_TRUE(files.ParseFromString(response->length_delimited()));
  bool found = false;
  for (int i = 0; i < files.field_count(); ++i) {
    google::protobuf::FileDescriptorProto proto;
    ASSERT_TRUE(proto.ParseFromString(files.field(i).length_delimited()));
    for (const auto& service : proto.service()) {
      if (service.name() != "CloudCast") continue;
      found = true;
      std::vector<std::string> methods;
      for (const auto& m : service.method()) methods.push_back(m.name());
      EXPECT_EQ(methods, (std::vector<std::string>{"Stream", "Process", "GetInfo"}));
    }
  }
  EXPECT_TRUE(found);
}

TEST_F(ServerTest, GetInfoReportsLimitsAndDefaults) {
  v1::ServerInfo info;
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  ASSERT_TRUE(stub_->GetInfo(&ctx, v1::GetInfoRequest(), &info).ok());
  const ServerOptions defaults;
  EXPECT_FALSE(info.version().empty());
  EXPECT_EQ(info.limits().max_message_bytes(), 64u << 20);
  EXPECT_EQ(info.limits().max_side(), 16384u);
  EXPECT_EQ(info.limits().max_pixels(), 1u << 24);
  EXPECT_EQ(info.limits().max_streams(), 64u);
  EXPECT_EQ(info.limits().idle_timeout_seconds(), 60u);
  EXPECT_EQ(info.limits().max_queued_frames(), 4u);
  const v1::StreamConfig& d = info.defaults();
  EXPECT_EQ(d.camera().fx(), 615.0);
  EXPECT_EQ(d.camera().fy(), 615.0);
  EXPECT_FALSE(d.camera().has_cx());
  EXPECT_EQ(d.camera().baseline(), 1.0);
  EXPECT_EQ(d.camera().invalid_disparities().values_size(), 2);
  EXPECT_TRUE(d.passthrough().enabled());
  EXPECT_EQ(d.passthrough().axis(), v1::AXIS_Z);
  EXPECT_EQ(d.passthrough().min(), 3.0f);
  EXPECT_EQ(d.passthrough().max(), 12.0f);
  EXPECT_TRUE(d.voxel_grid().enabled());
  EXPECT_FLOAT_EQ(d.voxel_grid().leaf(), 0.03f);
  EXPECT_EQ(d.draco().position_bits(), DracoOptions{}.position_bits);
  EXPECT_EQ(d.draco().color_bits(), 8);
  EXPECT_EQ(d.draco().encode_speed(), 10);
  EXPECT_FLOAT_EQ(d.draco().max_position_error(), 0.0075f);
  EXPECT_EQ(d.delivery(), v1::DELIVERY_LATEST);
  EXPECT_EQ(info.disparity_encodings_size(), 3);
  EXPECT_EQ(info.color_encodings_size(), 4);
  EXPECT_NE(std::find(info.image_formats().begin(), info.image_formats().end(), "jpeg"),
            info.image_formats().end());
  EXPECT_EQ(info.worker_threads(), 2u);
  EXPECT_EQ(info.draco_version(), "1.5.5");
}

TEST(ServerShutdownTest, DrainingGoesNotServingAndRefusesNewStreams) {
  auto server = testing::StartTestServer();
  ASSERT_NE(server, nullptr);
  const auto channel = testing::NewChannel(*server);
  auto stub = v1::CloudCast::NewStub(channel);
  EXPECT_EQ(HealthStatus(channel, ""), 1);
  server->StartDraining();
  EXPECT_EQ(HealthStatus(channel, ""), 2);  // NOT_SERVING
  EXPECT_EQ(HealthStatus(channel, "cloudcast.v1.CloudCast"), 2);
  const StreamResult refused = RunStream(*stub, {FrameRequest(MakeFrame(Frames()[0], 1))});
  EXPECT_EQ(refused.status.error_code(), grpc::StatusCode::UNAVAILABLE);
  v1::ProcessRequest request;
  *request.mutable_frame() = MakeFrame(Frames()[0], 1);
  v1::CloudReply reply;
  grpc::ClientContext ctx;
  EXPECT_EQ(stub->Process(&ctx, request, &reply).error_code(), grpc::StatusCode::UNAVAILABLE);
  const Clock::time_point start = Clock::now();
  server->Shutdown(milliseconds(2000));
  EXPECT_LT(Clock::now() - start, seconds(4));
}

TEST(ServerShutdownTest, ShutdownUnderLoadReturnsWithinTheGracePeriod) {
  auto server = testing::StartTestServer();
  ASSERT_NE(server, nullptr);
  // Four busy streams (latest and all) that read their replies, and one lossless stream whose
  // client stops reading: its frames can never all be answered, so only the grace period's end
  // (gRPC cancelling the call) can close it.
  constexpr int kBusy = 4;
  constexpr int kStreams = kBusy + 1;
  constexpr int kStuck = kBusy;
  std::atomic<int> streams_with_replies{0};
  std::atomic<int> stuck_writes{0};
  std::atomic<bool> shut_down{false};
  std::vector<grpc::Status> statuses(kStreams);
  std::vector<int> replies(kStreams, 0);
  std::vector<std::thread> clients;
  for (int s = 0; s < kStreams; ++s) {
    clients.emplace_back([&, s] {
      auto stub = testing::NewStub(*server);
      grpc::ClientContext ctx;
      SetDeadline(&ctx, seconds(60));
      auto stream = stub->Stream(&ctx);
      stream->Write(ConfigRequest(
          ConfigFor(Params{}, s % 2 || s == kStuck ? v1::DELIVERY_ALL : v1::DELIVERY_LATEST)));
      std::thread writer([&] {
        for (std::uint64_t i = 0;; ++i) {
          if (!stream->Write(FrameRequest(MakeFrame(Frames()[i % Frames().size()], i)))) break;
          if (s == kStuck) stuck_writes.fetch_add(1);
        }
      });
      if (s == kStuck) Eventually([&] { return shut_down.load(); }, milliseconds(60000));
      v1::StreamReply reply;
      while (stream->Read(&reply)) {
        if (++replies[s] == 1 && s != kStuck) streams_with_replies.fetch_add(1);
      }
      writer.join();  // the call is over, so its writes fail
      statuses[s] = stream->Finish();
    });
  }
  ASSERT_TRUE(
      Eventually([&] { return streams_with_replies.load() == kBusy; }, milliseconds(30000)));
  // The stuck stream is stuck once its client cannot write any more: the server stopped reading
  // it (its queue is full) and cannot write to it.
  int last = -1;
  ASSERT_TRUE(Eventually(
      [&] {
        const int now = stuck_writes.load();
        if (now == last) return true;
        last = now;
        std::this_thread::sleep_for(milliseconds(300));
        return false;
      },
      milliseconds(30000)));
  EXPECT_GT(stuck_writes.load(), 0);

  const auto grace = milliseconds(1500);
  const Clock::time_point start = Clock::now();
  server->Shutdown(grace);
  const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
  shut_down.store(true);
  for (auto& t : clients) t.join();
  std::cout << "shutdown under load took " << elapsed << " s (grace 1.5 s)\n";
  EXPECT_GE(elapsed, 1.5 * 0.9);  // the stuck stream held it up until the deadline...
  EXPECT_LT(elapsed, 1.5 + 1.5);  // ...and no longer than a frame and the joins after it
  for (int s = 0; s < kStreams; ++s) {
    SCOPED_TRACE("stream " + std::to_string(s));
    if (s != kStuck) {
      EXPECT_GT(replies[s], 0);
    }
    EXPECT_TRUE(statuses[s].error_code() == grpc::StatusCode::UNAVAILABLE ||
                statuses[s].error_code() == grpc::StatusCode::CANCELLED)
        << statuses[s].error_code() << " " << statuses[s].error_message();
  }
  EXPECT_EQ(statuses[0].error_code(), grpc::StatusCode::UNAVAILABLE);  // drained, not cut
  EXPECT_EQ(server->service().active_streams(), 0);
  server.reset();  // the destructor after Shutdown is a no-op
}

TEST(ServerShutdownTest, StartFailsCleanlyOnABusyAddress) {
  auto first = testing::StartTestServer();
  ASSERT_NE(first, nullptr);
  ServerOptions options = testing::TestServerOptions();
  options.listen = first->address();
  auto second = Server::Start(options);
  EXPECT_EQ(second.status().code(), absl::StatusCode::kUnavailable) << second.status();
  EXPECT_NE(second.status().message().find("--listen"), std::string::npos);
  options = testing::TestServerOptions();
  options.metrics_listen = "256.1.1.1:0";
  auto third = Server::Start(options);
  EXPECT_EQ(third.status().code(), absl::StatusCode::kUnavailable) << third.status();
  EXPECT_NE(third.status().message().find("--metrics-listen"), std::string::npos);
  options = testing::TestServerOptions();
  options.max_queued_frames = 0;
  EXPECT_EQ(Server::Start(options).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(ServerMetricsTest, PrometheusEndpointServesTheCounters) {
  ServerOptions options = testing::TestServerOptions();
  options.metrics_listen = "127.0.0.1:0";
  auto server = testing::StartTestServer(options);
  ASSERT_NE(server, nullptr);
  ASSERT_GT(server->metrics_port(), 0);
  auto stub = testing::NewStub(*server);
  v1::Frame bad = MakeFrame(Frames()[0], 2);
  bad.clear_colour();
  const StreamResult result =
      RunStream(*stub, {ConfigRequest(ConfigFor(Params{}, v1::DELIVERY_ALL)),
                        FrameRequest(MakeFrame(Frames()[0], 1)), FrameRequest(bad),
                        FrameRequest(MakeFrame(Frames()[1 % Frames().size()], 3, Input::kPng))});
  ASSERT_TRUE(result.status.ok());
  const std::string text = cloudcast::server::ScrapeMetrics(server->metrics_port());
  ASSERT_NE(text.find("200 OK"), std::string::npos) << text.substr(0, 200);
  EXPECT_EQ(MetricValue(text, "cloudcast_frames_processed_total"), 2.0);
  EXPECT_EQ(MetricValue(text, "cloudcast_streams_accepted_total"), 1.0);
  EXPECT_GT(MetricValue(text, "cloudcast_bytes_received_total"), 640.0 * 480 * 4);
  EXPECT_GT(MetricValue(text, "cloudcast_bytes_sent_total"), 0.0);
  EXPECT_GT(MetricValue(text, "cloudcast_core_cpu_seconds_total"), 0.0);
  EXPECT_GE(MetricValue(text, "cloudcast_worker_cpu_seconds_total"),
            MetricValue(text, "cloudcast_core_cpu_seconds_total"));
  EXPECT_GT(MetricValue(text, "cloudcast_process_cpu_seconds_total"), 0.0);
  EXPECT_NE(text.find("cloudcast_frame_errors_total{code=\"INVALID_ARGUMENT\"} 1"),
            std::string::npos);
  EXPECT_NE(text.find("cloudcast_active_streams"), std::string::npos);
  for (const char* stage : {"decode", "pipeline", "encode", "queue", "total"}) {
    EXPECT_NE(text.find(std::string("cloudcast_stage_seconds_count{stage=\"") + stage + "\"}"),
              std::string::npos)
        << stage;
  }
  EXPECT_NE(text.find("cloudcast_stage_seconds_count{stage=\"decode\"} 1"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Pieces of the server library.

TEST(ServerOptionsTest, FlagsAndConfigFile) {
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("cloudcast_server_test_" + std::to_string(getpid()) + ".toml"))
                               .string();
  {
    std::ofstream out(path);
    out << "max-streams = 8\nidle-timeout = 2.5\ndelivery = \"all\"\nleaf = 0.05\n"
           "listen = \"127.0.0.1:6000\"\n";
  }
  CLI::App app;
  ServerFlags flags(app);
  std::vector<std::string> args = {"--config", path, "--leaf", "0.07"};
  std::reverse(args.begin(), args.end());  // CLI11 takes them last-first
  ASSERT_NO_THROW(app.parse(args));
  auto options = flags.Options();
  ASSERT_TRUE(options.ok()) << options.status();
  EXPECT_EQ(options->max_streams, 8u);
  EXPECT_EQ(options->idle_timeout, milliseconds(2500));
  EXPECT_EQ(options->defaults.delivery, Delivery::kAll);
  EXPECT_FLOAT_EQ(options->defaults.frame.pipeline.voxel.leaf_x, 0.07f);  // the command line wins
  EXPECT_EQ(options->listen, "127.0.0.1:6000");
  EXPECT_EQ(options->max_queued_frames, 4u);  // untouched default
  std::filesystem::remove(path);

  // Every flag shows its default in --help.
  const std::string help = app.help();
  for (const char* flag : {"--listen",
                           "--threads",
                           "--max-message-bytes",
                           "--max-side",
                           "--max-pixels",
                           "--max-streams",
                           "--idle-timeout",
                           "--max-queued-frames",
                           "--shutdown-grace",
                           "--metrics-listen",
                           "--focal",
                           "--axis",
                           "--min",
                           "--max",
                           "--leaf",
                           "--draco-bits",
                           "--draco-speed",
                           "--delivery",
                           "--log-level",
                           "--config"}) {
    EXPECT_NE(help.find(flag), std::string::npos) << flag;
  }
  EXPECT_NE(help.find("=0.0.0.0:50051"), std::string::npos) << help;

  CLI::App bad_app;
  ServerFlags bad(bad_app);
  std::vector<std::string> bad_args = {"--max-queued-frames", "0"};
  std::reverse(bad_args.begin(), bad_args.end());
  bad_app.parse(bad_args);
  EXPECT_FALSE(bad.Options().ok());
}

TEST(FrameInputTest, SniffsImageSizesFromHeaders) {
  const SourceFrame& f = Frames().front();
  std::uint32_t w = 0, h = 0;
  const char* format = nullptr;
  ASSERT_TRUE(SniffImageSize(f.disparity_png, &w, &h, &format));
  EXPECT_EQ(std::string(format), "PNG");
  EXPECT_EQ(w, 640u);
  EXPECT_EQ(h, 480u);
  ASSERT_TRUE(SniffImageSize(f.colour_jpeg, &w, &h, &format));
  EXPECT_EQ(std::string(format), "JPEG");
  EXPECT_EQ(w, 640u);
  EXPECT_EQ(h, 480u);
  EXPECT_FALSE(SniffImageSize("not an image", &w, &h, &format));
  EXPECT_FALSE(SniffImageSize(f.colour_jpeg.substr(0, 20), &w, &h, &format));
  ASSERT_TRUE(SniffImageSize(TiffHeader(7, 9), &w, &h, &format));
  EXPECT_EQ(std::string(format), "TIFF");
  EXPECT_EQ(w, 7u);
  EXPECT_EQ(h, 9u);
  EXPECT_FALSE(SniffImageSize(TiffHeader(7, 9).substr(0, 20), &w, &h, &format));
  const std::string pgm =
      Encode(".pgm", f.disparity.width, f.disparity.height, CV_8UC1, f.disparity.pixels.data());
  ASSERT_TRUE(SniffImageSize(pgm, &w, &h, &format));
  EXPECT_EQ(std::string(format), "PNM");
  EXPECT_EQ(w, 640u);
  EXPECT_EQ(h, 480u);
  ASSERT_TRUE(SniffImageSize("P5 #c\n 12\n#d\n34 255\n", &w, &h, &format));
  EXPECT_EQ(w, 12u);
  EXPECT_EQ(h, 34u);
  EXPECT_FALSE(SniffImageSize("P5\n12", &w, &h, &format));
  EXPECT_FALSE(SniffImageSize("P9\n12 13\n", &w, &h, &format));
}

}  // namespace
}  // namespace cloudcast::server
