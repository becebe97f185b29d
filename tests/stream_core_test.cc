// The client stream core (cloudcast/client/stream_core.h) through the library's Stream, on
// loopback: with DELIVERY_LATEST, Send never waits while the server reads nothing, and every
// frame it replaced comes back as replaced; with DELIVERY_ALL, the same stall holds the sender
// back (lossless back-pressure) and nothing is replaced; against the real server at full speed,
// every frame comes back exactly once, answered, replaced, dropped or errored.
#include "cloudcast/client/stream_core.h"

#include <grpcpp/generic/async_generic_service.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "cloudcast/client/client.h"
#include "cloudcast/client/config.h"
#include "cloudcast/core/pipeline.h"
#include "cloudcast/datasets/synthetic.h"
#include "support/server_fixture.h"
#include "support/waiting.h"

namespace cloudcast::client {
namespace {

// A server whose Stream calls are accepted and then never read: the client's writes stop once
// HTTP/2 flow control's windows are full, as behind a link that carries nothing.
class StalledServer {
 public:
  StalledServer() {
    grpc::ServerBuilder builder;
    builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port_);
    builder.RegisterCallbackGenericService(&service_);
    server_ = builder.BuildAndStart();
  }
  ~StalledServer() { server_->Shutdown(std::chrono::system_clock::now()); }
  std::string address() const { return "127.0.0.1:" + std::to_string(port_); }
  bool started() const { return server_ != nullptr && port_ > 0; }

 private:
  class Reactor : public grpc::ServerGenericBidiReactor {
   public:
    void OnCancel() override { Finish(grpc::Status::CANCELLED); }
    void OnDone() override { delete this; }
  };
  class Service : public grpc::CallbackGenericService {
    grpc::ServerGenericBidiReactor* CreateReactor(
        grpc::GenericCallbackServerContext* /*context*/) override {
      return new Reactor;
    }
  };
  Service service_;
  std::unique_ptr<grpc::Server> server_;
  int port_ = 0;
};

SyntheticFrame Render(std::uint32_t w, std::uint32_t h, std::uint64_t frame) {
  SyntheticOptions options;
  options.width = w;
  options.height = h;
  options.frame = frame;
  return SyntheticScene::Default().Render(options).value();
}

StreamConfig ConfigWith(const CameraModel& camera, v1::DeliveryMode delivery) {
  PipelineOptions options;
  options.camera = camera;
  options.voxel.SetLeaf(0.05f);
  StreamConfig config = MakeStreamConfig(options);
  config.set_delivery(delivery);
  return config;
}

// Every Result of a stream, by sequence, from its on_result callback.
struct Collected {
  std::mutex mu;
  std::map<std::uint64_t, std::vector<Result>> by_sequence;
  std::map<FrameFate, int> fates;

  StreamOptions Options() {
    StreamOptions o;
    o.on_result = [this](Result&& r) {
      std::lock_guard<std::mutex> lock(mu);
      ++fates[r.fate];
      by_sequence[r.sequence].push_back(std::move(r));
    };
    return o;
  }
};

std::unique_ptr<Client> Connect(const std::string& target) {
  absl::StatusOr<std::unique_ptr<Client>> c = Client::Connect(target);
  EXPECT_TRUE(c.ok()) << c.status();
  return c.ok() ? *std::move(c) : nullptr;
}

TEST(StreamCoreTest, LatestNeverHoldsTheSenderWhileTheServerIsStalled) {
  StalledServer stalled;
  ASSERT_TRUE(stalled.started());
  std::unique_ptr<Client> client = Connect(stalled.address());
  ASSERT_NE(client, nullptr);
  const SyntheticFrame f = Render(640, 480, 1);  // 1.5 MB raw: far over the 64 KB window
  Collected got;
  absl::StatusOr<std::unique_ptr<Stream>> stream =
      client->OpenStream(ConfigWith(f.camera, v1::DELIVERY_LATEST), got.Options());
  ASSERT_TRUE(stream.ok()) << stream.status();

  constexpr int kFrames = 40;
  std::atomic<int> sent{0};
  std::thread camera([&] {
    for (int i = 0; i < kFrames; ++i) {
      EXPECT_TRUE((*stream)->Send(f.disparity_view(), f.colour_view()).ok());
      sent.fetch_add(1);
    }
  });
  // A Send that waited for the network would never return: the server reads nothing.
  const bool all_returned = testing::Eventually([&] { return sent.load() == kFrames; });
  if (!all_returned) (*stream)->Cancel();  // free the camera thread, so the test fails, not hangs
  camera.join();
  EXPECT_TRUE(all_returned) << "Send waited for a stalled server (" << sent.load() << " of "
                            << kFrames << " returned)";
  // At most two frames got a write slot (one in HTTP/2's window, one stuck behind it) and one
  // waits; every other was replaced.
  EXPECT_GE((*stream)->frames_replaced(), static_cast<std::uint64_t>(kFrames - 3));
  EXPECT_EQ((*stream)->frames_sent() + (*stream)->frames_replaced(),
            static_cast<std::uint64_t>(kFrames));

  (*stream)->Cancel();
  EXPECT_EQ((*stream)->Finish().code(), absl::StatusCode::kCancelled);
  std::lock_guard<std::mutex> lock(got.mu);
  // None vanishes: each frame came back once, replaced ones as replaced (with their record).
  ASSERT_EQ(got.by_sequence.size(), static_cast<std::size_t>(kFrames));
  for (const auto& [sequence, results] : got.by_sequence) {
    ASSERT_EQ(results.size(), 1u) << "frame " << sequence;
    const Result& r = results[0];
    EXPECT_FALSE(r.ok());
    EXPECT_GT(r.capture_time_unix_ns, 0);
    if (r.fate == FrameFate::kReplaced) {
      EXPECT_EQ(r.status.code(), absl::StatusCode::kAborted) << r.status;
      EXPECT_NE(r.status.message().find("replaced"), std::string::npos) << r.status;
    } else {
      EXPECT_TRUE(r.fate == FrameFate::kLost || r.fate == FrameFate::kUnsent)
          << FateName(r.fate);
      // The code the stream ended with: it was cancelled.
      EXPECT_EQ(r.status.code(), absl::StatusCode::kCancelled) << r.status;
    }
  }
  EXPECT_EQ(got.fates[FrameFate::kReplaced], static_cast<int>((*stream)->frames_replaced()));
  // The newest frame was never replaced.
  EXPECT_NE(got.by_sequence.rbegin()->second[0].fate, FrameFate::kReplaced);
}

TEST(StreamCoreTest, AllHoldsTheSenderBackWhileTheServerIsStalled) {
  StalledServer stalled;
  ASSERT_TRUE(stalled.started());
  std::unique_ptr<Client> client = Connect(stalled.address());
  ASSERT_NE(client, nullptr);
  const SyntheticFrame f = Render(640, 480, 2);
  Collected got;
  StreamOptions options = got.Options();
  options.max_queued_frames = 1;
  absl::StatusOr<std::unique_ptr<Stream>> stream =
      client->OpenStream(ConfigWith(f.camera, v1::DELIVERY_ALL), options);
  ASSERT_TRUE(stream.ok()) << stream.status();

  const pid_t sender_tid_unset = 0;
  std::atomic<pid_t> sender_tid{sender_tid_unset};
  std::atomic<int> accepted{0};
  absl::Status last;
  std::thread camera([&] {
    sender_tid = testing::CurrentThreadId();
    for (int i = 0; i < 20; ++i) {
      absl::Status s = (*stream)->Send(f.disparity_view(), f.colour_view());
      if (!s.ok()) {
        last = s;
        return;
      }
      accepted.fetch_add(1);
    }
  });
  // The sender ends up waiting inside Send, with at most three frames accepted (one in HTTP/2's
  // window, one stuck behind it, one queued): lossless means back-pressure, never replacement.
  EXPECT_TRUE(testing::Eventually([&] {
    return sender_tid.load() != 0 && accepted.load() >= 2 &&
           testing::ThreadIsBlocked(sender_tid.load());
  }));
  EXPECT_LE(accepted.load(), 3);
  EXPECT_EQ((*stream)->frames_replaced(), 0u);
  // Cancel frees it: Send then says the stream has ended.
  (*stream)->Cancel();
  camera.join();
  EXPECT_EQ(last.code(), absl::StatusCode::kUnavailable) << last;
  EXPECT_EQ((*stream)->Finish().code(), absl::StatusCode::kCancelled);
  std::lock_guard<std::mutex> lock(got.mu);
  EXPECT_EQ(got.by_sequence.size(), static_cast<std::size_t>(accepted.load()));
  EXPECT_EQ(got.fates[FrameFate::kReplaced], 0);
  for (const auto& [sequence, results] : got.by_sequence) {
    ASSERT_EQ(results.size(), 1u) << "frame " << sequence;
    EXPECT_TRUE(results[0].fate == FrameFate::kLost || results[0].fate == FrameFate::kUnsent);
  }
}

class StreamCoreServerTest : public testing::SharedServer<> {};

// Faster than one worker can answer, with a bad frame among them: every frame comes back once,
// as a cloud, an error, replaced in the client or dropped by the server; the last is answered.
TEST_F(StreamCoreServerTest, EveryFrameComesBackOnceUnderLatest) {
  std::unique_ptr<Client> client = Connect(shared_target());
  ASSERT_NE(client, nullptr);
  const SyntheticFrame f = Render(640, 480, 3);
  const SyntheticFrame small = Render(80, 60, 3);
  StreamConfig config = ConfigWith(f.camera, v1::DELIVERY_LATEST);
  config.mutable_voxel_grid()->set_enabled(false);  // slow on purpose: frames pile up
  Collected got;
  absl::StatusOr<std::unique_ptr<Stream>> stream = client->OpenStream(config, got.Options());
  ASSERT_TRUE(stream.ok()) << stream.status();
  constexpr int kFrames = 60;
  for (int i = 0; i < kFrames; ++i) {
    // Frame 10's colour does not match its disparity: the server answers it with an error
    // (unless a newer frame replaced or dropped it first).
    const ColorView colour = i == 10 ? small.colour_view() : f.colour_view();
    ASSERT_TRUE((*stream)->Send(f.disparity_view(), colour).ok());
  }
  const absl::Status finish = (*stream)->Finish();
  EXPECT_TRUE(finish.ok()) << finish;
  std::lock_guard<std::mutex> lock(got.mu);
  ASSERT_EQ(got.by_sequence.size(), static_cast<std::size_t>(kFrames));
  int answered = 0;
  for (const auto& [sequence, results] : got.by_sequence) {
    ASSERT_EQ(results.size(), 1u) << "frame " << sequence;
    const Result& r = results[0];
    if (r.fate == FrameFate::kAnswered) {
      ++answered;
      if (sequence == 10) {
        EXPECT_EQ(r.status.code(), absl::StatusCode::kInvalidArgument) << r.status;
      } else {
        EXPECT_TRUE(r.ok()) << r.status;
        EXPECT_GT(r.cloud.size(), 0u);
      }
    } else {
      EXPECT_TRUE(r.fate == FrameFate::kReplaced || r.fate == FrameFate::kDropped)
          << "frame " << sequence << ": " << FateName(r.fate) << " " << r.status;
    }
  }
  EXPECT_GT(answered, 0);
  EXPECT_EQ(got.by_sequence.rbegin()->second[0].fate, FrameFate::kAnswered);
  EXPECT_EQ(got.fates[FrameFate::kReplaced], static_cast<int>((*stream)->frames_replaced()));
}

}  // namespace
}  // namespace cloudcast::client
