// The replies' cap (cloudcast/client/reply_cap.h): what the stream core asks the server for, from
// the rate controller's reply bitrate and the rate frames go out at, and when it writes a change.
// Times are arguments: these assert decisions, never speed.
#include "cloudcast/client/reply_cap.h"

#include <gtest/gtest.h>

namespace cloudcast::client {
namespace {

using Clock = ReplyCapFollower::Clock;
using std::chrono::milliseconds;

Clock::time_point At(int ms) { return Clock::time_point(milliseconds(ms)); }

// The camera's 30 frames a second from `from_ms`, `count` frames.
void Write30(ReplyCapFollower& f, int from_ms, int count) {
  for (int i = 0; i < count; ++i) f.OnFrame(At(from_ms + i * 1000 / 30));
}

RateEstimate WithReplyTarget(double bps) {
  RateEstimate e;
  e.reply_target_bps = bps;
  return e;
}

TEST(ReplyCapTest, NothingIsSentUntilTheDownlinkShowsOveruse) {
  ReplyCapFollower f;
  Write30(f, 0, 31);
  EXPECT_NEAR(f.frame_rate(), 30, 0.5);
  EXPECT_FALSE(f.Update(WithReplyTarget(0), At(1000)));
  EXPECT_EQ(f.cap(), 0u);
}

TEST(ReplyCapTest, TheCapIsTheRepliesBitrateOverTheFrameRate) {
  ReplyCapFollower f;
  Write30(f, 0, 31);
  // 3 Mbit/s at 30 replies a second: 12.5 KB each, sent at once (the first cap).
  auto cap = f.Update(WithReplyTarget(3e6), At(1000));
  ASSERT_TRUE(cap);
  EXPECT_NEAR(static_cast<double>(*cap), 12'500, 300);
  EXPECT_EQ(f.cap(), *cap);
}

TEST(ReplyCapTest, ACutGoesAtOnceGrowthWaitsAndSmallChangesAreNotSent) {
  ReplyCapFollower f;
  Write30(f, 0, 31);
  ASSERT_TRUE(f.Update(WithReplyTarget(3e6), At(1000)));
  const std::uint64_t first = f.cap();
  // 5 % less: not worth a config message.
  EXPECT_FALSE(f.Update(WithReplyTarget(2.85e6), At(1010)));
  // A fifth less, 20 ms later: at once.
  auto cut = f.Update(WithReplyTarget(2.4e6), At(1020));
  ASSERT_TRUE(cut);
  EXPECT_LT(*cut, first);
  // Half again more, 100 ms after the cut: waits for half a second since the last change.
  EXPECT_FALSE(f.Update(WithReplyTarget(3.6e6), At(1120)));
  auto grown = f.Update(WithReplyTarget(3.6e6), At(1530));
  ASSERT_TRUE(grown);
  EXPECT_GT(*grown, *cut);
}

TEST(ReplyCapTest, NeverAboveTheStreamsOwnCapAndNeverBelowTheFloor) {
  ReplyCapFollower f;
  f.SetStreamCap(8'000);
  Write30(f, 0, 31);
  EXPECT_EQ(f.cap(), 8'000u);
  // The downlink would allow 12.5 KB: the stream's own 8 KB stays, nothing to send.
  EXPECT_FALSE(f.Update(WithReplyTarget(3e6), At(1000)));
  // 0.1 Mbit/s: 417 bytes a reply, below what a cap can say; the floor goes.
  auto low = f.Update(WithReplyTarget(0.1e6), At(1100));
  ASSERT_TRUE(low);
  EXPECT_EQ(*low, ReplyCapFollower::kMinCapBytes);
  // The owner lowers its own cap below the core's: its own wins.
  f.SetStreamCap(900);
  EXPECT_EQ(f.cap(), 900u);
}

TEST(ReplyCapTest, WithoutFramesThereIsNoRateAndNoCap) {
  ReplyCapFollower f;
  EXPECT_EQ(f.frame_rate(), 0);
  EXPECT_FALSE(f.Update(WithReplyTarget(3e6), At(0)));
}

}  // namespace
}  // namespace cloudcast::client
