// The link emulator's pure parts with an injected clock (times are arguments): units, loss
// models, rate schedules, outages and Mahimahi traces, the queue's scheduling arithmetic, and the
// flag checks. The packet path itself: linkemu_selftest.
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "cloudcast/linkemu/capacity.h"
#include "cloudcast/linkemu/direction.h"
#include "cloudcast/linkemu/link_spec.h"
#include "cloudcast/linkemu/loss.h"
#include "cloudcast/linkemu/units.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace cloudcast::linkemu {
namespace {

using ::testing::HasSubstr;
constexpr Nanos kMs = kMillisecond;

TEST(LinkUnitsTest, ParsesRatesDurationsAndQueues) {
  EXPECT_DOUBLE_EQ(*ParseRate("r", "10mbit"), 10e6);
  EXPECT_DOUBLE_EQ(*ParseRate("r", "3.5Mbit/s"), 3.5e6);
  EXPECT_DOUBLE_EQ(*ParseRate("r", "500kbps"), 500e3);
  EXPECT_DOUBLE_EQ(*ParseRate("r", "1gbit"), 1e9);
  EXPECT_DOUBLE_EQ(*ParseRate("r", "1200"), 1200);
  EXPECT_EQ(*ParseDuration("d", "40ms"), 40 * kMs);
  EXPECT_EQ(*ParseDuration("d", "1.5s"), 1500 * kMs);
  EXPECT_EQ(*ParseDuration("d", "250us"), 250'000);
  EXPECT_EQ(ParseQueueLimit("q", "150kB")->bytes, 150000);
  EXPECT_EQ(ParseQueueLimit("q", "64KiB")->bytes, 65536);
  EXPECT_EQ(ParseQueueLimit("q", "100p")->packets, 100);
  EXPECT_EQ(ParseQueueLimit("q", "100p")->bytes, 0);
}

TEST(LinkUnitsTest, ErrorsNameTheFieldAndWhatWasWrong) {
  EXPECT_THAT(ParseRate("--up-rate", "fast").status().message(), HasSubstr("--up-rate"));
  EXPECT_THAT(ParseRate("--rate", "10furlongs").status().message(), HasSubstr("unknown rate unit"));
  EXPECT_THAT(ParseRate("--rate", "-1mbit").status().message(), HasSubstr("negative"));
  EXPECT_THAT(ParseDuration("--delay", "40").status().message(), HasSubstr("needs a unit"));
  EXPECT_THAT(ParseDuration("--delay", "-4ms").status().message(), HasSubstr("negative"));
  EXPECT_THAT(ParseQueueLimit("--queue", "0p").status().message(), HasSubstr("--queue"));
  EXPECT_THAT(ParseQueueLimit("--queue", "5 bananas").status().message(),
              HasSubstr("unknown unit"));
  EXPECT_THAT(ParseProbability("--loss", "101%").status().message(), HasSubstr("outside"));
  EXPECT_THAT(ParseProbability("--loss", "x").status().message(), HasSubstr("--loss"));
  EXPECT_DOUBLE_EQ(*ParseProbability("--loss", "0.1%"), 0.001);
  EXPECT_DOUBLE_EQ(*ParseProbability("--loss", "0.02"), 0.02);
}

TEST(LossModelTest, RandomLossMatchesItsProbability) {
  LossModel model(0.01, {}, 7);
  int lost = 0;
  constexpr int kPackets = 200000;
  for (int i = 0; i < kPackets; ++i) lost += model.Lose() ? 1 : 0;
  EXPECT_NEAR(static_cast<double>(lost) / kPackets, 0.01, 0.001);
}

// Gilbert-Elliott with loss only in the bad state: the stationary loss rate p / (p + r) and bursts
// of 1 / r packets on average, where random loss of the same rate gives bursts of about 1.
TEST(LossModelTest, GilbertElliottLosesInBurstsAtItsStationaryRate) {
  const GilbertElliott ge = *ParseGilbertElliott("--burst-loss", "p=1%,r=25%");
  EXPECT_NEAR(ge.StationaryLoss(), 0.01 / 0.26, 1e-12);
  auto measure = [](LossModel model, double* rate, double* mean_burst) {
    constexpr int kPackets = 400000;
    int lost = 0, bursts = 0;
    bool previous = false;
    for (int i = 0; i < kPackets; ++i) {
      const bool now = model.Lose();
      lost += now ? 1 : 0;
      bursts += (now && !previous) ? 1 : 0;
      previous = now;
    }
    *rate = static_cast<double>(lost) / kPackets;
    *mean_burst = static_cast<double>(lost) / bursts;
  };
  double rate = 0, burst = 0;
  measure(LossModel(0, ge, 3), &rate, &burst);
  EXPECT_NEAR(rate, ge.StationaryLoss(), 0.004);
  EXPECT_NEAR(burst, 4.0, 0.3);
  measure(LossModel(ge.StationaryLoss(), {}, 3), &rate, &burst);
  EXPECT_NEAR(burst, 1.04, 0.05);
}

TEST(LossModelTest, GilbertElliottErrorsNameTheKey) {
  EXPECT_THAT(ParseGilbertElliott("--burst-loss", "p=1%").status().message(),
              HasSubstr("needs both p"));
  EXPECT_THAT(ParseGilbertElliott("--burst-loss", "p=1%,r=2%,q=3%").status().message(),
              HasSubstr("unknown key 'q'"));
  EXPECT_THAT(ParseGilbertElliott("--burst-loss", "p=1%,r=200%").status().message(),
              HasSubstr("--burst-loss.r"));
  EXPECT_THAT(ParseGilbertElliott("--burst-loss", "p=1%,r=0").status().message(),
              HasSubstr("never ends"));
  const GilbertElliott full = *ParseGilbertElliott("x", "p=5%,r=50%,bad=80%,good=1%");
  EXPECT_DOUBLE_EQ(full.loss_bad, 0.8);
  EXPECT_DOUBLE_EQ(full.loss_good, 0.01);
}

TEST(RateScheduleTest, SerializesAtTheRateAndAcrossASteps) {
  auto schedule = *RateSchedule::Make({{0, 12e6}});
  EXPECT_EQ(schedule->Finish(0, 1500), 1 * kMs);  // 12,000 bits at 12 Mbit/s
  EXPECT_EQ(schedule->Finish(1 * kMs, 1500), 2 * kMs);
  // 8 Mbit/s until 1 ms, then 16: 1,000 bytes go in the first ms, the other 1,000 in 0.5 ms.
  auto step = *RateSchedule::Make({{0, 8e6}, {1 * kMs, 16e6}});
  EXPECT_EQ(step->Finish(0, 2000), 1500'000);
  EXPECT_EQ(step->Finish(2 * kMs, 2000), 3 * kMs);
}

TEST(RateScheduleTest, AnOutageHoldsPacketsUntilItEnds) {
  std::vector<RateStep> steps = WithOutage({{0, 12e6}}, 5 * kMs, 3 * kMs);
  ASSERT_EQ(steps.size(), 3u);
  EXPECT_EQ(steps[1].at, 5 * kMs);
  EXPECT_EQ(steps[1].bits_per_second, 0);
  EXPECT_EQ(steps[2].at, 8 * kMs);
  EXPECT_EQ(steps[2].bits_per_second, 12e6);
  auto schedule = *RateSchedule::Make(steps);
  EXPECT_EQ(schedule->Finish(4500'000, 1500), 8500'000);  // half before, half after the outage
  EXPECT_EQ(schedule->Finish(8500'000, 1500), 9500'000);
  // A link that goes down for good never finishes.
  auto down = *RateSchedule::Make({{0, 12e6}, {1 * kMs, 0}});
  EXPECT_EQ(down->Finish(2 * kMs, 1500), kNever);
}

TEST(RateScheduleTest, ParsesAScheduleAndNamesBadEntries) {
  const std::vector<RateStep> steps =
      *ParseSchedule("--schedule", "5s=3mbit, 10s=down # comment\n12s=10mbit", 10e6);
  ASSERT_EQ(steps.size(), 4u);
  EXPECT_EQ(steps[0].bits_per_second, 10e6);
  EXPECT_EQ(steps[1].at, 5 * kSecond);
  EXPECT_EQ(steps[1].bits_per_second, 3e6);
  EXPECT_EQ(steps[2].bits_per_second, 0);
  EXPECT_EQ(steps[3].at, 12 * kSecond);
  EXPECT_EQ((*ParseSchedule("s", "0s=2mbit", 10e6))[0].bits_per_second, 2e6);
  EXPECT_THAT(ParseSchedule("--schedule", "5s=3mbit,4s=2mbit", 1).status().message(),
              HasSubstr("must increase"));
  EXPECT_THAT(ParseSchedule("--schedule", "5s", 1).status().message(), HasSubstr("not TIME=RATE"));
  EXPECT_THAT(ParseSchedule("--schedule", "5=3mbit", 1).status().message(),
              HasSubstr("needs a unit"));
}

TEST(DeliveryTraceTest, UsesOpportunitiesAsMahimahiDoesAndRepeats) {
  auto trace = *DeliveryTrace::Parse("t", "1\n1\n2\n");
  EXPECT_EQ(trace->period(), 2 * kMs);
  EXPECT_NEAR(trace->MeanRate(), 3 * 1504 * 8 / 0.002, 1e-6);
  EXPECT_EQ(trace->Finish(0, 1500), 1 * kMs);  // 4 bytes of the 1 ms opportunity left
  // Waiting already: uses those 4 bytes and the second opportunity at 1 ms.
  EXPECT_EQ(trace->Finish(1 * kMs, 1500), 1 * kMs);
  // 3,000 bytes: 8 left at 1 ms, then 2 ms, then the repeat's first (2 + 1 ms).
  EXPECT_EQ(trace->Finish(1 * kMs, 3000), 3 * kMs);
  // After an idle time, the leftover is gone: the first opportunity at or after 10 ms is 11 ms.
  EXPECT_EQ(trace->Finish(10 * kMs, 100), 11 * kMs);
}

TEST(DeliveryTraceTest, ErrorsNameTheLine) {
  EXPECT_THAT(DeliveryTrace::Parse("--trace f", "1\nx\n").status().message(),
              HasSubstr("--trace f line 2"));
  EXPECT_THAT(DeliveryTrace::Parse("--trace f", "5\n3\n").status().message(),
              HasSubstr("must not decrease"));
  EXPECT_THAT(DeliveryTrace::Parse("--trace f", "\n0\n").status().message(),
              HasSubstr("no delivery opportunity"));
}

std::unique_ptr<LinkDirection> Link(double rate, Nanos delay, QueueLimit queue) {
  DirectionConfig config;
  config.delay = delay;
  config.queue = queue;
  return std::make_unique<LinkDirection>(config, *RateSchedule::Make({{0, rate}}));
}

TEST(LinkDirectionTest, QueuesAtTheRateAddsTheDelayAndDropsAtTheTail) {
  auto link = Link(12e6, 20 * kMs, {0, 3});  // 1 ms per 1500-byte packet, 3 packets of queue
  using Fate = LinkDirection::Fate;
  for (int i = 0; i < 3; ++i) {
    const auto d = link->Offer(0, 1500);
    EXPECT_EQ(d.fate, Fate::kDeliver);
    EXPECT_EQ(d.release_at, (i + 1) * kMs + 20 * kMs);
  }
  EXPECT_EQ(link->Offer(0, 1500).fate, Fate::kQueueDrop);
  EXPECT_EQ(link->QueuedPackets(0), 3);
  EXPECT_EQ(link->QueuedBytes(1 * kMs), 3000);  // the first has left at 1 ms
  const auto d = link->Offer(1 * kMs, 1500);
  EXPECT_EQ(d.fate, Fate::kDeliver);
  EXPECT_EQ(d.release_at, 4 * kMs + 20 * kMs);
  // An idle link starts a packet at once.
  EXPECT_EQ(link->Offer(100 * kMs, 1500).release_at, 101 * kMs + 20 * kMs);
  const DirectionStats& s = link->stats();
  EXPECT_EQ(s.packets, 6);
  EXPECT_EQ(s.delivered, 5);
  EXPECT_EQ(s.queue_drops, 1);
  EXPECT_EQ(s.max_queue_packets, 3);
  EXPECT_EQ(s.max_queue_delay, 2 * kMs);
}

TEST(LinkDirectionTest, ByteBoundCountsBytes) {
  auto link = Link(8e6, 0, {2500, 0});
  EXPECT_EQ(link->Offer(0, 1000).fate, LinkDirection::Fate::kDeliver);
  EXPECT_EQ(link->Offer(0, 1000).fate, LinkDirection::Fate::kDeliver);
  EXPECT_EQ(link->Offer(0, 1000).fate, LinkDirection::Fate::kQueueDrop);
  EXPECT_EQ(link->Offer(0, 500).fate, LinkDirection::Fate::kDeliver);
}

TEST(LinkDirectionTest, JitterNeverReordersAndNeverReleasesEarly) {
  DirectionConfig config;
  config.delay = 20 * kMs;
  config.jitter = 10 * kMs;
  LinkDirection link(config, nullptr);  // no rate limit
  Nanos previous = 0, spread_min = kNever, spread_max = 0;
  for (int i = 0; i < 2000; ++i) {
    const Nanos now = i * kMs;
    const auto d = link.Offer(now, 200);
    ASSERT_GE(d.release_at, previous);
    ASSERT_GE(d.release_at, now);
    previous = d.release_at;
    spread_min = std::min(spread_min, d.release_at - now);
    spread_max = std::max(spread_max, d.release_at - now);
  }
  EXPECT_GT(spread_max - spread_min, 20 * kMs);  // it does vary
}

TEST(LinkDirectionTest, LostPacketsUseTheLinkAndAreCounted) {
  DirectionConfig config;
  config.loss = 1.0;
  LinkDirection link(config, *RateSchedule::Make({{0, 12e6}}));
  const auto d = link.Offer(0, 1500);
  EXPECT_EQ(d.fate, LinkDirection::Fate::kLose);
  EXPECT_EQ(d.release_at, 1 * kMs);
  EXPECT_EQ(link.Offer(0, 1500).release_at, 2 * kMs);  // it took the link's time
  EXPECT_EQ(link.stats().lost, 2);
}

TEST(LinkSpecTest, BuildsFromFlagsAndNamesTheFlagInErrors) {
  DirectionSpec both;
  both.rate = "10mbit";
  both.delay = "20ms";
  DirectionSpec up;
  up.rate = "5mbit";
  up.outages = {"5s:300ms"};
  absl::StatusOr<BuiltDirection> built = BuildDirection("up", both.OverriddenBy(up), 1);
  ASSERT_TRUE(built.ok()) << built.status();
  EXPECT_EQ(built->description["delay_ms"], 20.0);
  EXPECT_EQ(built->description["schedule"].size(), 3u);
  EXPECT_EQ(built->description["schedule"][0]["rate_bps"], 5e6);
  EXPECT_EQ(built->description["queue_bytes"], DefaultQueueLimit(5e6).bytes);
  DirectionSpec bad = both;
  bad.delay = "20";
  EXPECT_THAT(BuildDirection("down", bad, 1).status().message(), HasSubstr("--down-delay"));
  DirectionSpec outage_only;
  outage_only.outages = {"1s"};
  EXPECT_THAT(BuildDirection("up", outage_only, 1).status().message(), HasSubstr("--up-outage"));
  outage_only.rate = "1mbit";
  EXPECT_THAT(BuildDirection("up", outage_only, 1).status().message(), HasSubstr("AT:LENGTH"));
  DirectionSpec conflict = both;
  conflict.trace = "/nonexistent";
  EXPECT_THAT(BuildDirection("up", conflict, 1).status().message(), HasSubstr("--up-trace"));
}

}  // namespace
}  // namespace cloudcast::linkemu
