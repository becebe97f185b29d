// Ending calls and servers, end to end: a client cancelling mid-stream, draining (NOT_SERVING,
// new calls refused), shutdown under load, and a start on an address already taken.
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

}  // namespace
}  // namespace cloudcast::server
