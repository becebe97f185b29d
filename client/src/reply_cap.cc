#include "cloudcast/client/reply_cap.h"

#include <algorithm>

namespace cloudcast::client {
namespace {

constexpr auto kRateWindow = std::chrono::seconds(1);
constexpr auto kGrowEvery = std::chrono::milliseconds(500);
constexpr double kCutBelow = 0.9;   // a cap this much smaller is sent at once
constexpr double kGrowAbove = 1.2;  // a cap this much larger waits for kGrowEvery

}  // namespace

void ReplyCapFollower::OnFrame(Clock::time_point now) {
  frames_.push_back(now);
  while (now - frames_.front() > kRateWindow) frames_.pop_front();
}

std::uint64_t ReplyCapFollower::cap() const {
  if (!sent_ || *sent_ == 0) return stream_cap_;
  return stream_cap_ == 0 ? *sent_ : std::min(*sent_, stream_cap_);
}

double ReplyCapFollower::frame_rate() const {
  if (frames_.size() < 2) return 0;
  const double span = std::chrono::duration<double>(frames_.back() - frames_.front()).count();
  return span > 0 ? static_cast<double>(frames_.size() - 1) / span : 0;
}

std::optional<std::uint64_t> ReplyCapFollower::Update(const RateEstimate& estimate,
                                                      Clock::time_point now) {
  const double fps = frame_rate();
  std::uint64_t want = stream_cap_;
  if (estimate.reply_target_bps > 0 && fps > 0) {
    auto follow = static_cast<std::uint64_t>(estimate.reply_target_bps / 8 / fps);
    follow = std::max(follow, kMinCapBytes);
    want = stream_cap_ == 0 ? follow : std::min(follow, stream_cap_);
  }
  const std::uint64_t now_cap = cap();
  if (want == now_cap) return std::nullopt;
  const bool lifted = want == 0;      // no cap at all: the downlink's overuse is over
  const bool imposed = now_cap == 0;  // the first cap
  const auto w = static_cast<double>(want), c = static_cast<double>(now_cap);
  const bool since_ok = !last_change_ || now - *last_change_ >= kGrowEvery;
  const bool send = imposed || w < kCutBelow * c || ((lifted || w > kGrowAbove * c) && since_ok);
  if (!send) return std::nullopt;
  sent_ = want;
  last_change_ = now;
  return want;
}

}  // namespace cloudcast::client
