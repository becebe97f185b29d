// The server's limits, end to end: the message size limit, the stream limit and the idle timeout,
// each on a server of its own with that limit set low.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <future>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "metrics.h"
#include "service.h"
#include "support/server_support.h"
#include "support/waiting.h"

namespace cloudcast::server {
namespace {

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
  options.max_streams_per_client = 2;  // one client here: test the server-wide limit
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

  // Once one ends, a new stream is accepted. The server's OnDone may run after our Finish has
  // returned, and the service announces no single stream's end: its count is polled.
  streams[0]->WritesDone();
  EXPECT_TRUE(streams[0]->Finish().ok());
  ASSERT_TRUE(testing::Eventually([&] { return server->service().active_streams() == 1; }));
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
  const SourceFrame& f = Frames().front();

  // A stream that keeps moving (frame, reply, frame, ... back to back) and a silent one, open
  // at the same time: the server ends the silent one, and the moving one is still open after.
  auto moving_stub = testing::NewStub(*server);
  grpc::ClientContext moving_ctx;
  SetDeadline(&moving_ctx, seconds(60));
  auto moving = moving_stub->Stream(&moving_ctx);
  v1::StreamReply moving_reply;
  auto round_trip = [&](std::uint64_t sequence) {
    return moving->Write(FrameRequest(MakeFrame(f, sequence))) && moving->Read(&moving_reply) &&
           moving_reply.has_cloud() && moving_reply.cloud().sequence() == sequence;
  };
  ASSERT_TRUE(round_trip(0)) << "the moving stream does not answer";
  std::atomic<bool> silent_ended{false};
  bool moving_broke = false;
  bool moving_answered_after = false;
  grpc::Status moving_status;
  std::thread moving_client([&] {
    std::uint64_t sequence = 1;
    while (!silent_ended.load()) {
      if (!round_trip(sequence++)) {
        moving_broke = true;
        break;
      }
    }
    if (!moving_broke) moving_answered_after = round_trip(sequence++);
    moving->WritesDone();
    while (moving->Read(&moving_reply)) {
    }
    moving_status = moving->Finish();
  });
  {
    auto silent_stub = testing::NewStub(*server);
    grpc::ClientContext ctx;
    SetDeadline(&ctx, seconds(60));
    auto silent = silent_stub->Stream(&ctx);
    v1::StreamReply reply;
    EXPECT_FALSE(silent->Read(&reply));  // returns when the call ends
    const grpc::Status status = silent->Finish();
    silent_ended.store(true);
    // Ended by the server for being idle (the message says so), not by our 60 s deadline.
    EXPECT_EQ(status.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED) << status.error_message();
    EXPECT_NE(status.error_message().find("idle"), std::string::npos) << status.error_message();
    EXPECT_NE(status.error_message().find("--idle-timeout"), std::string::npos)
        << status.error_message();
  }
  moving_client.join();
  EXPECT_FALSE(moving_broke) << "the moving stream ended while the silent one was open";
  EXPECT_TRUE(moving_answered_after) << "the moving stream did not outlive the silent one";
  EXPECT_TRUE(moving_status.ok()) << moving_status.error_message();
  EXPECT_EQ(server->metrics().streams_idle_timeout.Value(), 1.0);
  EXPECT_TRUE(server->service().WaitForCalls(std::chrono::steady_clock::now() + seconds(30)));

  // A lossless stream whose client sends until the server stops reading and never reads a reply
  // holds its slot only for the timeout: nothing moves, so the server cancels it (a Finish would
  // wait for its write, which this client never lets complete).
  auto stuck_stub = testing::NewStub(*server, FixedWindow());
  grpc::ClientContext stuck_ctx;
  SetDeadline(&stuck_ctx, seconds(60));
  auto stuck = stuck_stub->Stream(&stuck_ctx);
  std::promise<void> writes_failed;
  std::thread writer([&] {
    stuck->Write(ConfigRequest(ConfigFor(kUnfiltered, v1::DELIVERY_ALL)));
    for (std::uint64_t i = 0; stuck->Write(FrameRequest(MakeFrame(f, i))); ++i) {
    }
    writes_failed.set_value();
  });
  // The client's writes fail once the call is cancelled (60 s only turns a hang into a failure).
  EXPECT_EQ(writes_failed.get_future().wait_for(seconds(60)), std::future_status::ready);
  writer.join();
  EXPECT_TRUE(server->service().WaitForCalls(std::chrono::steady_clock::now() + seconds(30)));
  v1::StreamReply reply;
  while (stuck->Read(&reply)) {
  }
  const grpc::Status stuck_status = stuck->Finish();
  EXPECT_EQ(stuck_status.error_code(), grpc::StatusCode::CANCELLED) << stuck_status.error_message();
  EXPECT_EQ(server->metrics().streams_idle_timeout.Value(), 2.0);
}

// A Process call over its client's share is refused and counted as a Stream is (one admission
// path): the first call holds the client's only place while its memory refusal waits out
// --refusal-delay, so the second finds the share taken.
TEST(ServerLimitsTest, ProcessOverItsClientShareIsRefusedAndCounted) {
  ServerOptions options = testing::TestServerOptions();
  options.memory_budget_bytes = std::uint64_t{1} << 20;  // a raw 640x480 frame (1.2 MB) never fits
  options.max_process_per_client = 1;
  options.refusal_delay = std::chrono::minutes(1);  // held until the drain below answers it
  auto server = testing::StartTestServer(options);
  ASSERT_NE(server, nullptr);
  auto stub = testing::NewStub(*server);
  v1::ProcessRequest request;
  *request.mutable_frame() = MakeFrame(Frames().front(), 1);
  auto held = std::async(std::launch::async, [&] {
    v1::CloudReply reply;
    grpc::ClientContext ctx;
    return stub->Process(&ctx, request, &reply);
  });
  // Nothing announces that the first call was refused and now waits: its counter says so.
  ASSERT_TRUE(testing::Eventually(
      [&] { return server->metrics().frames_refused_memory_budget.Value() == 1.0; }));
  v1::ProcessRequest small;
  *small.mutable_frame() = MakeFrame(Frames().front(), 2, Input::kPng);
  v1::CloudReply reply;
  grpc::ClientContext ctx;
  const grpc::Status refused = stub->Process(&ctx, small, &reply);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << refused.error_message();
  EXPECT_NE(refused.error_message().find("--max-process-per-client"), std::string::npos)
      << refused.error_message();
  EXPECT_EQ(server->metrics().process_rejected_limit.Value(), 1.0);
  server->StartDraining();  // answers the held call now
  const grpc::Status first = held.get();
  EXPECT_EQ(first.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << first.error_message();
  EXPECT_NE(first.error_message().find("--memory-budget-mb"), std::string::npos)
      << first.error_message();
}

}  // namespace
}  // namespace cloudcast::server
