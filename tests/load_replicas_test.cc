// cloudcast-load against three real cloudcast-server processes on 127.0.0.1, 127.0.0.2 and
// 127.0.0.3 (one port, three loopback addresses), one round_robin channel over the three: one
// replica is killed (SIGKILL) or drained (SIGTERM) mid-run, in DELIVERY_ALL with resilient
// streams. Everything is asserted from the report's JSON, as a user of the report would read it:
// every frame sent is answered exactly once or reported lost, frames were sent again, the lost
// replica's streams reconnected, and every replica had frames before the loss.
//
// The fleet runs in this process (the cloudcast_load library, what cloudcast-load's main wraps)
// so that the test can wait for the run's own counters before stopping a replica: no sleeps.
#include <gtest/gtest.h>
#include <signal.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "cloudcast/load/fleet.h"
#include "cloudcast/load/frame_store.h"
#include "cloudcast/load/report.h"
#include "support/replica_support.h"
#include "support/waiting.h"

namespace cloudcast {
namespace {

using nlohmann::json;
using std::chrono::seconds;
using testing::ServerProcess;

// Small synthetic frames (160x120), so three servers, the generator and the other tests share two
// cores without the run crawling.
const load::FrameStore& Store() {
  static const load::FrameStore store = [] {
    load::FrameSourceOptions o;
    o.source.synthetic_width = 160;
    o.source.synthetic_height = 120;
    o.synthetic_frames = 4;
    return load::FrameStore::Prepare(o).value();
  }();
  return store;
}

class LoadReplicasTest : public testing::ScratchDirTest {
 public:
  void StartReplicas(int n) {
    replicas_ = testing::StartReplicaSet(n, {"--threads", "1"}, [this](const std::string& id) {
      return Path("replica" + id + ".log");
    });
    ASSERT_EQ(replicas_.size(), static_cast<std::size_t>(n)) << "replicas did not start";
  }

  std::string Target() const { return testing::ReplicaTarget(replicas_); }

  // Closed loop with more frames in flight per stream (8) than a server holds per stream (4):
  // whenever a replica goes, frames it has not read or not answered are outstanding, so the
  // resends are certain, not a matter of timing.
  load::FleetOptions Options(int streams, std::uint64_t frames) const {
    load::FleetOptions o;
    o.server = Target();
    o.streams = streams;
    o.connections = 1;  // round_robin on one channel: stream after stream on the next replica
    o.closed_loop = true;
    o.in_flight = 8;
    o.duration = std::chrono::nanoseconds(0);
    o.frames = frames;
    o.drain_timeout = seconds(60);
    o.connect_timeout = seconds(20);
    o.config.set_delivery(v1::DELIVERY_ALL);
    o.resilient = true;
    o.reconnect_timeout = seconds(30);
    return o;
  }

  struct Outcome {
    json report;
    std::uint64_t sent_at_loss = 0;
    std::map<std::string, std::uint64_t> frames_at_loss;  // per replica, when it was stopped
  };

  // Runs the fleet, stops `victim` with `signal_number` once every replica has answered
  // `min_frames` (polled on the run's own counters, bounded), and returns the JSON report.
  Outcome RunStopping(const load::FleetOptions& o, ServerProcess* victim, int signal_number,
                      std::uint64_t min_frames) {
    Outcome out;
    auto fleet = load::Fleet::Connect(o, &Store());
    EXPECT_TRUE(fleet.ok()) << fleet.status();
    if (!fleet.ok()) return out;
    load::FleetResult result;
    std::thread run([&] { result = (*fleet)->Run(); });
    if (victim != nullptr) {
      // Until every replica has answered min_frames: the recorder announces nothing to wait on.
      testing::Eventually(
          [&] {
            auto per = (*fleet)->recorder().per_instance();
            bool all = per.size() >= replicas_.size();
            for (const auto& [name, n] : per) all = all && n >= min_frames;
            return all;
          },
          std::chrono::seconds(60));
      out.frames_at_loss = (*fleet)->recorder().per_instance();
      out.sent_at_loss = (*fleet)->recorder().totals().sent;
      victim->Signal(signal_number);
    }
    run.join();
    const load::Report report =
        load::MakeReport(**fleet, result, Store().description(), "test", json::object());
    out.report = load::GhzJson(report);
    std::printf("%s", load::FormatTable(report).c_str());
    return out;
  }

  std::vector<std::unique_ptr<ServerProcess>> replicas_;
};

// What both losses must show in the report.
void ExpectHandedOver(const LoadReplicasTest& test, const json& j, const std::string& victim,
                      std::uint64_t frames) {
  const json& f = j["frames"];
  EXPECT_EQ(f["sent"], frames) << f;
  // Exactly once or reported: with two replicas alive nothing is lost.
  EXPECT_EQ(f["answered"], frames) << f;
  EXPECT_EQ(f["lost"], 0) << f;
  EXPECT_EQ(f["frameErrors"], 0) << f;
  EXPECT_EQ(f["duplicates"], 0) << f;
  EXPECT_EQ(f["unsent"], 0) << f;
  EXPECT_GT(f["resent"].get<std::uint64_t>(), 0u) << f;
  EXPECT_EQ(j["resilience"]["streamsGivenUp"], 0);
  std::uint64_t answered = 0;
  int moved = 0;
  for (const json& s : j["streams"]) {
    EXPECT_EQ(s["sent"].get<std::uint64_t>(),
              s["answered"].get<std::uint64_t>() + s["lost"].get<std::uint64_t>())
        << s;
    EXPECT_EQ(s["duplicates"], 0) << s;
    answered += s["answered"].get<std::uint64_t>();
    ASSERT_FALSE(s["replicas"].empty()) << s;
    if (s["replicas"][0] == victim) {
      // The lost replica's streams reconnected and finished elsewhere.
      ++moved;
      EXPECT_GE(s["reconnects"].get<int>(), 1) << s;
      EXPECT_NE(s["replicas"].back(), victim) << s;
      EXPECT_EQ(s["reconnectNs"].size(), s["reconnects"].get<std::size_t>()) << s;
    } else {
      EXPECT_EQ(s["reconnects"], 0) << "stream not on " << victim << ": " << s;
    }
  }
  EXPECT_EQ(answered, frames);
  EXPECT_GE(moved, 1) << "no stream was on " << victim;
  // The replicas' figures add up: frames per replica sum to the answers.
  std::uint64_t per_replica = 0;
  for (const auto& [name, r] : j["replicas"].items())
    per_replica += r["frames"].get<std::uint64_t>();
  EXPECT_EQ(per_replica, frames);
  EXPECT_EQ(j["replicas"].size(), test.replicas_.size());
}

void ExpectAllBusyBeforeTheLoss(const LoadReplicasTest::Outcome& out, std::uint64_t frames) {
  EXPECT_EQ(out.frames_at_loss.size(), 3u);
  for (const auto& [name, n] : out.frames_at_loss) EXPECT_GT(n, 0u) << name;
  // The loss came mid-run, not after it.
  EXPECT_LT(out.sent_at_loss, frames);
  EXPECT_EQ(out.report["loadBalancing"]["policy"], "round_robin");
  EXPECT_EQ(out.report["loadBalancing"]["replicasAtStart"].size(), 3u);
  EXPECT_EQ(out.report["loadBalancing"]["addressesAnsweringAtStart"], 3);
  for (const auto& [name, r] : out.report["replicas"].items()) {
    EXPECT_GE(r["streamsAtStart"].get<int>(), 1) << name;
  }
}

constexpr int kStreams = 6;
constexpr std::uint64_t kFrames = 6 * 150;

TEST_F(LoadReplicasTest, KilledReplicaStreamsResumeOnTheOthersEveryFrameAnsweredOnce) {
  StartReplicas(3);
  ServerProcess* victim = replicas_[1].get();
  const Outcome out = RunStopping(Options(kStreams, kFrames), victim, SIGKILL, 10);
  EXPECT_FALSE(victim->Wait().has_value());  // killed by the signal
  ExpectAllBusyBeforeTheLoss(out, kFrames);
  ExpectHandedOver(*this, out.report, victim->instance(), kFrames);
}

TEST_F(LoadReplicasTest, DrainedReplicaHandsItsStreamsOverEveryFrameAnsweredOnce) {
  StartReplicas(3);
  ServerProcess* victim = replicas_[1].get();
  const Outcome out = RunStopping(Options(kStreams, kFrames), victim, SIGTERM, 10);
  EXPECT_EQ(victim->Wait(), std::optional<int>(0)) << victim->log();  // a drain is a clean exit
  ExpectAllBusyBeforeTheLoss(out, kFrames);
  ExpectHandedOver(*this, out.report, victim->instance(), kFrames);
}

// Without --resilient the same loss ends the victim's streams: their unanswered frames are
// reported lost, which is what the resilient runs above avoid.
TEST_F(LoadReplicasTest, WithoutResilienceAKilledReplicaLosesItsStreamsFrames) {
  StartReplicas(3);
  load::FleetOptions o = Options(kStreams, kFrames);
  o.resilient = false;
  ServerProcess* victim = replicas_[1].get();
  const Outcome out = RunStopping(o, victim, SIGKILL, 10);
  const json& f = out.report["frames"];
  EXPECT_GT(f["lost"].get<std::uint64_t>(), 0u) << f;
  EXPECT_EQ(f["resent"], 0) << f;
  EXPECT_EQ(out.report["resilience"]["reconnects"], 0);
  EXPECT_EQ(f["sent"], f["answered"].get<std::uint64_t>() + f["lost"].get<std::uint64_t>()) << f;
}

// The last replica gone: the streams look for a working call for --reconnect-timeout, then give
// up and report every frame sent and unanswered as lost. No frame is unaccounted for.
TEST_F(LoadReplicasTest, WithNoReplicaLeftStreamsGiveUpReportingEveryUnansweredFrame) {
  StartReplicas(1);
  load::FleetOptions o = Options(2, 2 * 1000);
  o.reconnect_timeout = std::chrono::milliseconds(1500);
  const Outcome out = RunStopping(o, replicas_[0].get(), SIGKILL, 10);
  const json& j = out.report;
  const json& f = j["frames"];
  EXPECT_EQ(j["resilience"]["streamsGivenUp"], 2);
  EXPECT_GT(f["lost"].get<std::uint64_t>(), 0u) << f;
  EXPECT_EQ(f["duplicates"], 0) << f;
  EXPECT_EQ(f["sent"], f["answered"].get<std::uint64_t>() + f["lost"].get<std::uint64_t>()) << f;
  for (const json& s : j["streams"]) {
    EXPECT_TRUE(s["gaveUp"].get<bool>()) << s;
    EXPECT_EQ(s["endStatus"], "UNAVAILABLE") << s;
  }
  bool named = false;
  for (const auto& [message, n] : j["errorDistribution"].items()) {
    named = named || message.find("--reconnect-timeout") != std::string::npos;
  }
  EXPECT_TRUE(named) << j["errorDistribution"];
}

}  // namespace
}  // namespace cloudcast
