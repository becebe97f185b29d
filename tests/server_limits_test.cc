// The server's limits, end to end: the message size limit, the stream limit and the idle timeout,
// each on a server of its own with that limit set low.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "service.h"
#include "support/server_support.h"

namespace cloudcast::server {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;
using std::chrono::seconds;

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

}  // namespace
}  // namespace cloudcast::server
