// Scale-out on loopback: three cloudcast-server processes on 127.0.0.1, 127.0.0.2 and 127.0.0.3,
// one client channel on a multi-address target with round_robin, and robot streams that survive
// a replica killed (SIGKILL) or drained (SIGTERM) mid-run.
#include <gtest/gtest.h>
#include <signal.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "cloudcast/client/client.h"
#include "cloudcast/datasets/synthetic.h"
#include "support/replica_support.h"
#include "support/robot.h"
#include "support/small_frames.h"
#include "support/waiting.h"

namespace cloudcast {
namespace {

namespace cc = cloudcast::client;
using std::chrono::milliseconds;
using testing::ServerProcess;

const std::vector<SyntheticFrame>& Frames() { return testing::SmallFrames(4); }

class ReplicasTest : public testing::ScratchDirTest {
 public:
  void StartReplicas(int n, const std::vector<std::string>& args = {}) {
    replicas_ = testing::StartReplicaSet(
        n, args, [this](const std::string& id) { return Path("replica" + id + ".log"); });
    ASSERT_EQ(replicas_.size(), static_cast<std::size_t>(n)) << "replicas did not start";
  }

  std::string Target() const { return testing::ReplicaTarget(replicas_); }

  std::unique_ptr<cc::Client> Connect() {
    cc::ClientOptions options;
    options.load_balancing = "round_robin";
    options.decode_clouds = false;
    auto client = cc::Client::Connect(Target(), options);
    EXPECT_TRUE(client.ok()) << client.status();
    if (!client.ok()) return nullptr;
    // Connect returns once one replica is ready; round_robin spreads over the ready ones, so
    // wait until GetInfo has been answered by every replica. A subchannel's readiness announces
    // nothing the client library exposes, hence Eventually; a loaded machine may take seconds.
    std::set<std::string> seen;
    EXPECT_TRUE(testing::Eventually([&] {
      auto info = (*client)->GetInfo();
      if (info.ok()) seen.insert(info->instance());
      return seen.size() == replicas_.size();
    })) << "only "
        << seen.size() << " of " << replicas_.size() << " replicas answered GetInfo";
    return *std::move(client);
  }

  ServerProcess& Replica(const std::string& instance) {
    for (auto& r : replicas_) {
      if (r->instance() == instance) return *r;
    }
    ADD_FAILURE() << "no replica " << instance;
    return *replicas_.front();
  }

 public:
  std::vector<std::unique_ptr<ServerProcess>> replicas_;
};

using testing::Robot;

std::unique_ptr<Robot> OpenRobot(cc::Client& client) {
  return testing::OpenRobot(client, /*resilient=*/true, milliseconds(20000));
}

// Sends `frames` frames as fast as the stream takes them (flow control keeps a few in flight, so
// a replica lost mid-run leaves frames unanswered), then finishes the stream.
void Drive(Robot* robot, int frames) {
  for (int i = 0; i < frames; ++i) {
    const SyntheticFrame& f = Frames()[static_cast<std::size_t>(i) % Frames().size()];
    cc::FrameMeta meta;
    meta.sequence = static_cast<std::uint64_t>(i);
    if (!robot->stream->Send(f.disparity_view(), f.colour_view(), meta).ok()) break;
    ++robot->sent;
  }
  robot->final_status = robot->stream->Finish();
}

// Waits (bounded) until every robot has at least `n` answers.
bool AllAnswered(std::vector<std::unique_ptr<Robot>>& robots, std::size_t n) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  for (auto& r : robots) {
    std::unique_lock<std::mutex> lock(r->mu);
    if (!r->cv.wait_until(lock, deadline, [&] { return r->answers.size() >= n; })) return false;
  }
  return true;
}

// Sends a robot fleet through a replica that is stopped with `signal_number` mid-run, and checks
// that every frame of every stream was answered exactly once, the stopped replica's streams
// having moved to the others. Prints the per-stream table.
void RunFleetThroughALostReplica(ReplicasTest* test, int signal_number, const char* what) {
  constexpr int kRobots = 6, kFrames = 150;
  auto client = test->Connect();
  ASSERT_NE(client, nullptr);
  std::vector<std::unique_ptr<Robot>> robots;
  for (int i = 0; i < kRobots; ++i) robots.push_back(OpenRobot(*client));
  for (auto& r : robots) ASSERT_NE(r->stream, nullptr);
  std::vector<std::thread> drivers;
  for (auto& r : robots) drivers.emplace_back(Drive, r.get(), kFrames);

  // Once every stream runs, stop the replica that serves the first one.
  ASSERT_TRUE(AllAnswered(robots, 5));
  std::string victim;
  {
    std::lock_guard<std::mutex> lock(robots.front()->mu);
    victim = robots.front()->first_instance;
  }
  ServerProcess& stopped = test->Replica(victim);
  stopped.Signal(signal_number);
  const std::optional<int> exit_status = stopped.Wait();
  for (std::thread& t : drivers) t.join();

  std::printf("%s %s mid-run (%d DELIVERY_ALL streams x %d frames, unpaced):\n", what,
              victim.c_str(), kRobots, kFrames);
  std::printf("stream  first replica  sent  answered  resent  lost  reconnects  reconnect ms\n");
  std::map<std::string, std::uint64_t> frames_per_replica;
  std::set<std::string> first_instances;
  std::uint64_t resent_by_victims = 0;
  for (std::size_t i = 0; i < robots.size(); ++i) {
    Robot& r = *robots[i];
    std::lock_guard<std::mutex> lock(r.mu);
    first_instances.insert(r.first_instance);
    std::string took;
    for (const cc::Reconnect& e : r.reconnects) took += std::to_string(e.took.count()) + " ";
    std::printf("%6zu  %13s  %4lu  %8zu  %6lu  %4zu  %10zu  %s\n", i, r.first_instance.c_str(),
                static_cast<unsigned long>(r.sent), r.answers.size(),
                static_cast<unsigned long>(r.stream->frames_resent()), r.errors.size(),
                r.reconnects.size(), took.c_str());
    for (const auto& [sequence, instance] : r.by) ++frames_per_replica[instance];

    EXPECT_TRUE(r.final_status.ok()) << "stream " << i << ": " << r.final_status;
    EXPECT_EQ(r.sent, static_cast<std::uint64_t>(kFrames)) << "stream " << i;
    EXPECT_TRUE(r.errors.empty()) << "stream " << i << ": " << r.errors.front();
    // Every frame sent answered exactly once.
    ASSERT_EQ(r.answers.size(), static_cast<std::size_t>(kFrames)) << "stream " << i;
    for (const auto& [sequence, times] : r.answers) {
      EXPECT_EQ(times, 1) << "stream " << i << " frame " << sequence;
    }
    if (r.first_instance == victim) {
      // Its stream moved: a reconnect, and its last frames answered by another replica.
      EXPECT_GE(r.reconnects.size(), 1u) << "stream " << i;
      resent_by_victims += r.stream->frames_resent();
      EXPECT_NE(r.by.rbegin()->second, victim) << "stream " << i;
      for (const cc::Reconnect& e : r.reconnects) {
        EXPECT_EQ(e.cause.code(), absl::StatusCode::kUnavailable) << e.cause;
      }
    } else {
      EXPECT_TRUE(r.reconnects.empty()) << "stream " << i << " was not on " << victim;
    }
  }
  std::printf("frames per replica:");
  for (const auto& [instance, n] : frames_per_replica) {
    std::printf(" %s %lu", instance.c_str(), static_cast<unsigned long>(n));
  }
  std::printf("\n");
  // round_robin put the streams on every replica.
  EXPECT_EQ(first_instances.size(), 3u);
  // Frames were in flight when the replica went: they were sent again, and answered once.
  EXPECT_GE(resent_by_victims, 1u);
  if (signal_number == SIGTERM) {
    // A drain is a clean exit.
    EXPECT_EQ(exit_status, std::optional<int>(0)) << stopped.log();
  }
}

TEST_F(ReplicasTest, RoundRobinSpreadsStreamsOverEveryReplica) {
  StartReplicas(3);
  auto client = Connect();
  ASSERT_NE(client, nullptr);
  std::map<std::string, int> streams_per_replica;
  for (int s = 0; s < 9; ++s) {
    auto stream = client->OpenStream();
    ASSERT_TRUE(stream.ok()) << stream.status();
    const SyntheticFrame& f = Frames()[0];
    ASSERT_TRUE((*stream)->Send(f.disparity_view(), f.colour_view()).ok());
    ASSERT_TRUE((*stream)->CloseSend().ok());
    cc::Result r;
    ASSERT_TRUE((*stream)->Read(&r));
    ASSERT_TRUE(r.ok()) << r.status;
    ++streams_per_replica[r.server_instance];
    EXPECT_TRUE((*stream)->Finish().ok());
  }
  for (const auto& [instance, n] : streams_per_replica) {
    std::printf("%s: %d streams\n", instance.c_str(), n);
  }
  ASSERT_EQ(streams_per_replica.size(), 3u);
  for (const auto& [instance, n] : streams_per_replica) EXPECT_EQ(n, 3) << instance;
}

TEST_F(ReplicasTest, KilledReplicaStreamsResumeOnTheOthersLosingNothing) {
  StartReplicas(3);
  RunFleetThroughALostReplica(this, SIGKILL, "SIGKILL");
}

TEST_F(ReplicasTest, DrainingReplicaHandsItsStreamsOver) {
  StartReplicas(3);
  RunFleetThroughALostReplica(this, SIGTERM, "SIGTERM");
}

// --max-connection-age: the server sends GOAWAY to old connections and, after the grace,
// cancels what still runs on them; a resilient stream carries on over a new connection.
TEST_F(ReplicasTest, ConnectionAgeMovesLongStreamsToNewConnectionsLosingNothing) {
  StartReplicas(2, {"--max-connection-age", "0.5", "--max-connection-age-grace", "0.3"});
  auto client = Connect();
  ASSERT_NE(client, nullptr);
  auto robot = OpenRobot(*client);
  ASSERT_NE(robot->stream, nullptr);
  // A camera with two frames in flight (each sent once the one before the last is answered)
  // until its stream has moved to a new connection twice: several connection lifetimes. The
  // count and the deadline only turn a stream that never moves into a failure.
  constexpr std::size_t kMoves = 2, kMaxFrames = 200000;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  std::size_t frames = 0;
  for (; frames < kMaxFrames && std::chrono::steady_clock::now() < deadline; ++frames) {
    if (frames >= 2) {
      ASSERT_TRUE(robot->WaitForAnswers(frames - 1)) << "frame " << frames - 2;
    }
    {
      std::lock_guard<std::mutex> lock(robot->mu);
      if (robot->reconnects.size() >= kMoves) break;
    }
    const SyntheticFrame& f = Frames()[frames % Frames().size()];
    cc::FrameMeta meta;
    meta.sequence = frames;
    ASSERT_TRUE(robot->stream->Send(f.disparity_view(), f.colour_view(), meta).ok());
  }
  EXPECT_TRUE(robot->stream->Finish().ok());
  std::lock_guard<std::mutex> lock(robot->mu);
  std::printf("%d reconnects over %zu frames\n", robot->stream->reconnects(), frames);
  EXPECT_GE(robot->reconnects.size(), kMoves);
  EXPECT_TRUE(robot->errors.empty());
  ASSERT_EQ(robot->answers.size(), frames);
  for (const auto& [sequence, times] : robot->answers) EXPECT_EQ(times, 1) << sequence;
}

TEST_F(ReplicasTest, AResilientStreamGivesUpWhenNoReplicaIsLeftAndReportsEveryFrame) {
  StartReplicas(1);
  auto client = Connect();
  ASSERT_NE(client, nullptr);
  cc::StreamConfig config;
  config.set_delivery(v1::DELIVERY_ALL);
  cc::StreamOptions options;
  options.resilient = true;
  options.reconnect_timeout = milliseconds(1500);
  auto stream = client->OpenStream(config, options);
  ASSERT_TRUE(stream.ok());
  const SyntheticFrame& f = Frames()[0];
  cc::FrameMeta meta;
  meta.sequence = 0;
  ASSERT_TRUE((*stream)->Send(f.disparity_view(), f.colour_view(), meta).ok());
  cc::Result first;
  ASSERT_TRUE((*stream)->Read(&first));
  ASSERT_TRUE(first.ok());
  replicas_.front()->Signal(SIGKILL);
  replicas_.front()->Wait();
  // Sent after the loss: never answered, so reported.
  for (std::uint64_t s = 1; s <= 3; ++s) {
    meta.sequence = s;
    EXPECT_TRUE((*stream)->Send(f.disparity_view(), f.colour_view(), meta).ok());
  }
  std::set<std::uint64_t> reported;
  cc::Result r;
  while ((*stream)->Read(&r)) {
    EXPECT_EQ(r.status.code(), absl::StatusCode::kUnavailable) << r.status;
    EXPECT_NE(std::string(r.status.message()).find("never answered"), std::string::npos);
    reported.insert(r.sequence);
  }
  EXPECT_EQ(reported, (std::set<std::uint64_t>{1, 2, 3}));
  const absl::Status done = (*stream)->Finish();
  EXPECT_EQ(done.code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(std::string(done.message()).find("reconnect_timeout"), std::string::npos) << done;
}

}  // namespace
}  // namespace cloudcast
