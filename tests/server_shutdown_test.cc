// Ending calls and servers, end to end: a client cancelling mid-stream, draining (NOT_SERVING,
// new calls refused), shutdown under load, and a start on an address already taken.
//
// Outcomes and orderings are asserted, never durations: a drained stream answers every frame it
// accepted and then ends UNAVAILABLE; a stream that cannot be drained stays open until the end of
// the grace period cuts it.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <future>
#include <memory>
#include <mutex>
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

// How the service ends a stream it drained (service.cc).
constexpr const char* kDrained = "frames received before were answered";

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
  EXPECT_TRUE(
      shared_server().service().WaitForCalls(std::chrono::steady_clock::now() + seconds(30)));
  EXPECT_EQ(HealthStatus(testing::NewChannel(shared_server()), ""), 1);
  const StreamResult after = RunStream(*stub_, {FrameRequest(MakeFrame(Frames()[1], 9))});
  ASSERT_TRUE(after.status.ok());
  ASSERT_EQ(after.replies.size(), 1u);
  EXPECT_TRUE(CloudMatches(Reference(Frames()[1], Params{}), after.replies[0].cloud()));
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
  // No call is open, so Shutdown has nothing to wait for: given a grace period of two minutes it
  // returns without using it (the 60 s wait only turns a hang into a failure).
  auto shutdown =
      std::async(std::launch::async, [&] { server->Shutdown(std::chrono::minutes(2)); });
  EXPECT_EQ(shutdown.wait_for(seconds(60)), std::future_status::ready)
      << "Shutdown waited for its grace period with no call open";
  shutdown.get();
  EXPECT_EQ(server->service().active_streams(), 0);
}

TEST(ServerShutdownTest, ShutdownUnderLoadDrainsTheStreamsAndCutsOnlyTheStuckOne) {
  auto server = testing::StartTestServer();
  ASSERT_NE(server, nullptr);
  const std::size_t n = Frames().size();

  // First a lossless stream whose client writes and never reads. Its replies (large, through a
  // 64 KB window) cannot be written, so once the server holds its limit of frames it stops
  // reading the stream for good: the stream can never be drained.
  auto stuck_stub = testing::NewStub(*server, FixedWindow());
  grpc::ClientContext stuck_ctx;
  SetDeadline(&stuck_ctx, seconds(60));
  auto stuck = stuck_stub->Stream(&stuck_ctx);
  std::atomic<bool> stuck_writes_ended{false};
  std::thread stuck_writer([&] {
    stuck->Write(ConfigRequest(ConfigFor(kUnfiltered, v1::DELIVERY_ALL)));
    for (std::uint64_t i = 0; stuck->Write(FrameRequest(MakeFrame(Frames()[i % n], i))); ++i) {
    }
    stuck_writes_ended.store(true);
  });
  // The server announces no queue level: its high-water mark is polled, while the stuck stream is
  // its only stream.
  EXPECT_TRUE(testing::Eventually([&] {
    return server->queued_frames_high_water() == server->options().max_queued_frames;
  })) << "the stuck stream never filled its queue";

  // Then four busy streams (latest and all) that read every reply.
  constexpr int kBusy = 4;
  struct Reply {
    std::uint64_t sequence;
    std::uint64_t frames_dropped;
  };
  struct Busy {
    v1::DeliveryMode delivery;
    std::vector<Reply> replies;
    bool all_clouds = true;
    grpc::Status status;
  };
  std::vector<Busy> busy(kBusy);
  std::mutex mu;
  std::condition_variable cv;
  int answering = 0;
  std::vector<std::thread> clients;
  for (int s = 0; s < kBusy; ++s) {
    busy[s].delivery = s % 2 ? v1::DELIVERY_ALL : v1::DELIVERY_LATEST;
    clients.emplace_back([&, s] {
      auto stub = testing::NewStub(*server);
      grpc::ClientContext ctx;
      SetDeadline(&ctx, seconds(60));
      auto stream = stub->Stream(&ctx);
      stream->Write(ConfigRequest(ConfigFor(Params{}, busy[s].delivery)));
      std::thread writer([&] {
        for (std::uint64_t i = 0; stream->Write(FrameRequest(MakeFrame(Frames()[i % n], i))); ++i) {
        }
      });
      v1::StreamReply reply;
      while (stream->Read(&reply)) {
        busy[s].all_clouds = busy[s].all_clouds && reply.has_cloud();
        busy[s].replies.push_back({reply.cloud().sequence(), reply.cloud().frames_dropped()});
        if (busy[s].replies.size() == 1) {
          std::lock_guard<std::mutex> lock(mu);
          ++answering;
          cv.notify_all();
        }
      }
      writer.join();  // the call is over, so its writes fail
      busy[s].status = stream->Finish();
    });
  }
  {
    std::unique_lock<std::mutex> lock(mu);
    EXPECT_TRUE(cv.wait_for(lock, seconds(60), [&] { return answering == kBusy; }));
  }

  // Shutdown, step 1, under load: every stream stops reading and answers what it holds.
  server->StartDraining();
  for (auto& t : clients) t.join();
  for (int s = 0; s < kBusy; ++s) {
    SCOPED_TRACE("busy stream " + std::to_string(s));
    const Busy& b = busy[s];
    EXPECT_EQ(b.status.error_code(), grpc::StatusCode::UNAVAILABLE) << b.status.error_message();
    EXPECT_NE(b.status.error_message().find(kDrained), std::string::npos)  // drained, not cut
        << b.status.error_message();
    if (b.replies.empty()) {  // no ASSERT: the stuck stream's thread must still be joined
      ADD_FAILURE() << "no reply";
      continue;
    }
    EXPECT_TRUE(b.all_clouds);
    // Every frame the server accepted (a prefix of those sent) was answered before the end, or,
    // in DELIVERY_LATEST, replaced and counted as dropped.
    for (std::size_t i = 1; i < b.replies.size(); ++i) {
      EXPECT_GT(b.replies[i].sequence, b.replies[i - 1].sequence);
      EXPECT_GE(b.replies[i].frames_dropped, b.replies[i - 1].frames_dropped);
    }
    const Reply& last = b.replies.back();
    EXPECT_EQ(b.replies.size() + last.frames_dropped, last.sequence + 1);
    if (b.delivery == v1::DELIVERY_ALL) {
      EXPECT_EQ(last.frames_dropped, 0u);
    }
  }
  // Every busy stream has ended; the stuck one has not. (OnDone of the drained streams may run
  // after their clients' Finish returned, and announces nothing: the count is polled.)
  EXPECT_FALSE(stuck_writes_ended.load()) << "the stuck stream ended while draining";
  EXPECT_TRUE(testing::Eventually([&] { return server->service().active_streams() == 1; }));

  // Step 2: only the end of the grace period can close the stuck stream, and it does.
  server->Shutdown(milliseconds(500));
  EXPECT_EQ(server->service().active_streams(), 0);
  stuck_writer.join();  // the call is over, so its writes fail
  EXPECT_TRUE(stuck_writes_ended.load());
  v1::StreamReply reply;
  while (stuck->Read(&reply)) {
  }
  const grpc::Status stuck_status = stuck->Finish();
  // Cut by gRPC at the deadline (gRPC 1.51 says UNAVAILABLE, "Cancelling all calls"), not
  // drained by the service.
  EXPECT_TRUE(stuck_status.error_code() == grpc::StatusCode::UNAVAILABLE ||
              stuck_status.error_code() == grpc::StatusCode::CANCELLED)
      << stuck_status.error_code() << " " << stuck_status.error_message();
  EXPECT_EQ(stuck_status.error_message().find(kDrained), std::string::npos)
      << stuck_status.error_message();
  server.reset();  // the destructor after Shutdown is a no-op
}

// Stream and Process are admitted by one path (CallAdmitter): a call that arrives while the server
// drains is refused UNAVAILABLE before its frame is weighed (no memory charged, no memory
// refusal), and counted in its RPC's refusal metric.
TEST(ServerShutdownTest, CallsWhileDrainingAreRefusedAndCountedBeforeTheirFrameIsCharged) {
  ServerOptions options = testing::TestServerOptions();
  options.memory_budget_bytes = std::uint64_t{1} << 20;  // a raw 640x480 frame (1.2 MB) never fits
  auto server = testing::StartTestServer(options);
  ASSERT_NE(server, nullptr);
  auto stub = testing::NewStub(*server);
  server->StartDraining();
  const StreamResult stream = RunStream(*stub, {FrameRequest(MakeFrame(Frames()[0], 1))});
  EXPECT_EQ(stream.status.error_code(), grpc::StatusCode::UNAVAILABLE)
      << stream.status.error_message();
  v1::ProcessRequest request;
  *request.mutable_frame() = MakeFrame(Frames()[0], 2);
  v1::CloudReply reply;
  grpc::ClientContext ctx;
  const grpc::Status process = stub->Process(&ctx, request, &reply);
  EXPECT_EQ(process.error_code(), grpc::StatusCode::UNAVAILABLE) << process.error_message();
  const Metrics& m = server->metrics();
  EXPECT_EQ(m.streams_rejected_shutdown.Value(), 1.0);
  EXPECT_EQ(m.process_rejected_shutdown.Value(), 1.0);
  EXPECT_EQ(m.frames_refused_memory_budget.Value(), 0.0);
  EXPECT_EQ(server->metrics().FrameErrors(absl::StatusCode::kResourceExhausted).Value(), 0.0);
}

// Issue 30, defect 6: a stream's client may send a frame just as the drain begins; the server was
// reading it (the read is always started while there is room), and dropped it when it came. Now
// it is answered, and the stream ends after it. (The drain waits up to a second for such a read:
// the frame is written at once here.)
TEST(ServerShutdownTest, AFrameArrivingAsTheDrainBeginsIsAnsweredBeforeTheStreamEnds) {
  auto server = testing::StartTestServer();
  ASSERT_NE(server, nullptr);
  auto stub = testing::NewStub(*server);
  grpc::ClientContext ctx;
  SetDeadline(&ctx, seconds(60));
  auto stream = stub->Stream(&ctx);
  ASSERT_TRUE(stream->Write(ConfigRequest(ConfigFor(Params{}, v1::DELIVERY_ALL))));
  ASSERT_TRUE(stream->Write(FrameRequest(MakeFrame(Frames()[0], 1))));
  v1::StreamReply reply;
  ASSERT_TRUE(stream->Read(&reply));  // answered: the server is reading the next message now
  EXPECT_EQ(reply.cloud().sequence(), 1u);
  server->StartDraining();
  const bool written = stream->Write(FrameRequest(MakeFrame(Frames()[1], 2)));
  std::vector<v1::StreamReply> after;
  while (stream->Read(&reply)) after.push_back(reply);
  const grpc::Status status = stream->Finish();
  EXPECT_TRUE(written);
  ASSERT_EQ(after.size(), 1u) << "the frame that arrived as the drain began was not answered";
  ASSERT_TRUE(after[0].has_cloud()) << after[0].error().message();
  EXPECT_EQ(after[0].cloud().sequence(), 2u);
  EXPECT_TRUE(CloudMatches(Reference(Frames()[1], Params{}), after[0].cloud()));
  EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAVAILABLE) << status.error_message();
  EXPECT_NE(status.error_message().find(kDrained), std::string::npos) << status.error_message();
  // One message only: nothing is read after it.
  EXPECT_TRUE(server->Shutdown(seconds(10)));
}

// A stream that sends nothing more holds the drain for its read no longer than a second (not
// its grace period); a stream its client cancelled is not waited for at all.
TEST(ServerShutdownTest, AnIdleStreamHoldsTheDrainOnlyBrieflyAndACancelledOneNotAtAll) {
  auto server = testing::StartTestServer();
  ASSERT_NE(server, nullptr);
  auto stub = testing::NewStub(*server);
  grpc::ClientContext idle_ctx;
  SetDeadline(&idle_ctx, seconds(60));
  auto idle = stub->Stream(&idle_ctx);
  ASSERT_TRUE(idle->Write(FrameRequest(MakeFrame(Frames()[0], 1))));
  v1::StreamReply reply;
  ASSERT_TRUE(idle->Read(&reply));
  grpc::ClientContext cancelled_ctx;
  SetDeadline(&cancelled_ctx, seconds(60));
  auto cancelled = stub->Stream(&cancelled_ctx);
  ASSERT_TRUE(cancelled->Write(FrameRequest(MakeFrame(Frames()[0], 1))));
  ASSERT_TRUE(cancelled->Read(&reply));
  cancelled_ctx.TryCancel();
  while (cancelled->Read(&reply)) {
  }
  EXPECT_EQ(cancelled->Finish().error_code(), grpc::StatusCode::CANCELLED);
  // A grace far longer than the wait: a shutdown that waits for the idle stream's read until
  // its grace is over fails.
  auto shutdown = std::async(std::launch::async, [&] { return server->Shutdown(seconds(120)); });
  EXPECT_FALSE(idle->Read(&reply));
  const grpc::Status status = idle->Finish();
  EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAVAILABLE) << status.error_message();
  EXPECT_NE(status.error_message().find(kDrained), std::string::npos) << status.error_message();
  ASSERT_EQ(shutdown.wait_for(seconds(60)), std::future_status::ready)
      << "Shutdown waited for an idle stream's read, or for a cancelled stream";
  EXPECT_TRUE(shutdown.get());
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

}  // namespace
}  // namespace cloudcast::server
