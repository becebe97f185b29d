// What the server tests share: the input frames (New Tsukuba, else the synthetic scene), requests
// and configs built independently of the server's own translation, the core pipeline's reference
// cloud, streams run from a client's side, health checking and reflection over the generic stub,
// and the suite-shared server (ServerTest).
//
// Frames: the New Tsukuba sample when it is there, else frames of the synthetic scene (same size,
// same camera), so that every test runs on a fresh machine.
#pragma once

#include <google/protobuf/descriptor.pb.h>
#include <google/protobuf/unknown_field_set.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <fstream>
#include <memory>
#include <mutex>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "cloudcast/core/draco_codec.h"
#include "cloudcast/core/pipeline.h"
#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/io/image_io.h"
#include "cloudcast/server/server.h"
#include "cloudcast/v1/cloudcast.grpc.pb.h"
#include "support/cloud_match.h"
#include "support/server_fixture.h"
#include "support/test_support.h"
#include "support/waiting.h"

namespace cloudcast::server {

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

inline std::string ReadFileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

inline std::string Encode(const char* ext, int w, int h, int type, const void* data,
                          std::vector<int> params = {}) {
  const cv::Mat m(h, w, type, const_cast<void*>(data));
  std::vector<std::uint8_t> out;
  EXPECT_TRUE(cv::imencode(ext, m, out, params));
  return std::string(out.begin(), out.end());
}

inline const std::vector<SourceFrame>& Frames() {
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
inline const char* Name(Input input) {
  switch (input) {
    case Input::kRaw:
      return "Raw";
    case Input::kPng:
      return "Png";
    default:
      return "JpegColour";
  }
}
inline void PrintTo(Input input, std::ostream* os) { *os << Name(input); }

inline v1::Frame MakeFrame(const SourceFrame& f, std::uint64_t sequence,
                           Input input = Input::kRaw) {
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
    v1::RawColor* c = frame.mutable_color()->mutable_raw();
    c->set_encoding(v1::COLOR_BGR8);
    c->set_width(f.colour.width);
    c->set_height(f.colour.height);
    c->set_pixels(f.colour.pixels.data(), f.colour.pixels.size());
  } else {
    frame.mutable_disparity()->set_encoded(f.disparity_png);
    frame.mutable_color()->set_encoded(input == Input::kPng ? f.colour_png : f.colour_jpeg);
  }
  return frame;
}

inline v1::StreamRequest FrameRequest(v1::Frame frame) {
  v1::StreamRequest r;
  *r.mutable_frame() = std::move(frame);
  return r;
}

inline v1::StreamRequest ConfigRequest(const v1::StreamConfig& config) {
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

inline v1::StreamConfig ConfigFor(const Params& p, v1::DeliveryMode delivery) {
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

// Without the passthrough every frame gives many voxels, so every reply is large (tens of KB
// and more): with FixedWindow(), a client that does not read stops the server's writes within
// a few replies, whatever the frames and the machine's speed.
const Params kUnfiltered{0.03f, /*passthrough=*/false};

inline testing::ChannelOptions FixedWindow() {
  testing::ChannelOptions options;
  options.fixed_receive_window = true;
  return options;
}

inline PointCloud Reference(const SourceFrame& f, const Params& p) {
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
inline ::testing::AssertionResult CloudMatches(const PointCloud& reference,
                                               const v1::CloudReply& reply,
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
// Streams from the client's side.

inline void SetDeadline(grpc::ClientContext* ctx,
                        std::chrono::seconds s = std::chrono::seconds(120)) {
  ctx->set_deadline(std::chrono::system_clock::now() + s);
}

struct StreamResult {
  std::vector<v1::StreamReply> replies;
  grpc::Status status;
};

// Sends `requests` from a writer thread while this thread reads (a client that only wrote first
// would deadlock a lossless stream: the server stops reading when its queue is full). With
// `write_all_first`, reading starts only once every request is sent.
// Writes `requests` on one thread while this one reads every reply; a `read_pause` makes the
// reader a slow one (a client's own pace, not a wait for the writer).
inline StreamResult RunStream(v1::CloudCast::Stub& stub,
                              const std::vector<v1::StreamRequest>& requests,
                              std::chrono::milliseconds read_pause = std::chrono::milliseconds(0)) {
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  auto stream = stub.Stream(&ctx);
  std::thread writer([&] {
    for (const auto& r : requests) {
      if (!stream->Write(r)) break;
    }
    stream->WritesDone();
  });
  StreamResult result;
  v1::StreamReply reply;
  while (stream->Read(&reply)) {
    result.replies.push_back(reply);
    if (read_pause.count() > 0) testing::PauseFor(read_pause);
  }
  writer.join();
  result.status = stream->Finish();
  return result;
}

// ---------------------------------------------------------------------------------------------
// Health and reflection.

// Health and reflection are spoken through the generic stub: their protos are not installed with
// Debian's gRPC, and their wire format is small enough to write by hand.
inline std::string ToBytes(const grpc::ByteBuffer& buffer) {
  std::vector<grpc::Slice> slices;
  EXPECT_TRUE(buffer.Dump(&slices).ok());
  std::string out;
  for (const auto& s : slices) out.append(reinterpret_cast<const char*>(s.begin()), s.size());
  return out;
}

inline grpc::ByteBuffer FromBytes(const std::string& bytes) {
  grpc::Slice slice(bytes);
  return grpc::ByteBuffer(&slice, 1);
}

// grpc.health.v1.Health/Check; the ServingStatus number (1 SERVING, 2 NOT_SERVING) or -1.
inline int HealthStatus(const std::shared_ptr<grpc::Channel>& channel, const std::string& service) {
  google::protobuf::UnknownFieldSet request;
  request.AddLengthDelimited(1, service);
  std::string bytes;
  request.SerializeToString(&bytes);
  grpc::GenericStub stub(channel);
  grpc::CompletionQueue cq;
  grpc::ClientContext ctx;
  SetDeadline(&ctx, std::chrono::seconds(10));
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
inline std::unique_ptr<google::protobuf::UnknownFieldSet> Reflect(
    const std::shared_ptr<grpc::Channel>& channel, int request_field, const std::string& value) {
  google::protobuf::UnknownFieldSet request;
  request.AddLengthDelimited(request_field, value);
  std::string bytes;
  request.SerializeToString(&bytes);
  grpc::GenericStub stub(channel);
  grpc::CompletionQueue cq;
  grpc::ClientContext ctx;
  SetDeadline(&ctx, std::chrono::seconds(10));
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

inline const google::protobuf::UnknownField* FieldOf(const google::protobuf::UnknownFieldSet& set,
                                                     int number) {
  for (int i = 0; i < set.field_count(); ++i) {
    if (set.field(i).number() == number) return &set.field(i);
  }
  return nullptr;
}

// ---------------------------------------------------------------------------------------------
// The shared server, for the tests that need nothing special; a stub of its own per test.

class ServerTest : public testing::SharedServerTest {
 protected:
  void SetUp() override {
    testing::SharedServerTest::SetUp();
    stub_ = testing::NewStub(shared_server());
  }

  std::unique_ptr<v1::CloudCast::Stub> stub_;
};

}  // namespace cloudcast::server
