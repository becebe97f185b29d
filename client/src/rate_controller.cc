#include "cloudcast/client/rate_controller.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace cloudcast::client {
namespace {

double Ms(RateController::Clock::duration d) {
  return std::chrono::duration<double, std::milli>(d).count();
}

std::int64_t Ns(RateController::Clock::time_point t) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(t.time_since_epoch()).count();
}

// The delivered rate is measured over this much of the far end's clock (at least the shorter
// span below, so that two messages back to back do not make a rate of their own).
constexpr std::int64_t kDeliveredSpanNs = 400'000'000;
constexpr std::int64_t kMinDeliveredSpanNs = 150'000'000;

// How far over the delivered rate the replies' bitrate may grow before the downlink first shows
// overuse (DirectionRate's free start).
constexpr double kFreeStartOverDelivered = 4;

}  // namespace

DirectionRate::DirectionRate(const RateControlOptions& options, double start_bps, bool free_start)
    : options_(options),
      target_bps_(std::clamp(start_bps, options.min_bps, options.max_bps)),
      start_bps_(target_bps_),
      free_start_(free_start) {}

void DirectionRate::Restart() {
  delivered_.clear();
  delays_.clear();
  over_streak_ = 0;
}

void DirectionRate::AddDelivered(std::int64_t at_ns, std::uint64_t cumulative_bytes) {
  if (at_ns <= 0 || cumulative_bytes == 0) return;
  delivered_.emplace_back(at_ns, cumulative_bytes);
  while (delivered_.size() > 2 &&
         delivered_.back().first - delivered_[1].first >= kDeliveredSpanNs) {
    delivered_.pop_front();
  }
  const std::int64_t span = delivered_.back().first - delivered_.front().first;
  if (span >= kMinDeliveredSpanNs && delivered_.back().second > delivered_.front().second) {
    delivered_bps_ = static_cast<double>(delivered_.back().second - delivered_.front().second) *
                     8e9 / static_cast<double>(span);
  }
}

void DirectionRate::AddDelay(Clock::time_point now, double one_way_ms) {
  while (!delays_.empty() && delays_.back().second >= one_way_ms) delays_.pop_back();
  delays_.emplace_back(now, one_way_ms);
  while (now - delays_.front().first > options_.min_rtt_window) delays_.pop_front();
  const double sample = one_way_ms - delays_.front().second;
  queue_delay_ms_ = 0.7 * queue_delay_ms_ + 0.3 * sample;
  last_queue_sample_ = sample;
}

void DirectionRate::Control(Clock::time_point now, double rtt_ms) {
  const double target_delay = static_cast<double>(options_.target_delay.count());
  double dt = last_update_ ? std::chrono::duration<double>(now - *last_update_).count() : 0;
  dt = std::clamp(dt, 0.0, 0.2);  // a long silence is no licence to grow
  last_update_ = now;
  // Overuse on the smoothed delay, or on a sample four times the target (a step down to a third
  // of the rate shows there within a frame or two), seen on two messages in a row: one frame late
  // by a retransmission (TCP hides a lost packet as a round trip's delay, 0.1 % loss does that to
  // a frame or two a second) is not a full link.
  const bool over = queue_delay_ms_ > target_delay || last_queue_sample_ > 4 * target_delay;
  over_streak_ = over ? over_streak_ + 1 : 0;
  overuse_ = over_streak_ >= 2;
  if (overuse_) {
    seen_overuse_ = true;
    const auto since = last_decrease_ ? now - *last_decrease_ : Clock::duration::max();
    const auto once_a_round_trip = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double, std::milli>(std::max(rtt_ms, 100.0)));
    if (since >= once_a_round_trip) {
      double cut = delivered_bps_ > 0 ? options_.backoff * delivered_bps_ : 0.5 * target_bps_;
      // The replies' first cut stops at their start rate: before it they were capped by the
      // growing target, so what they delivered says what was allowed, not what the downlink
      // carries (a fresh connection's first windows queue them too). A downlink under the start
      // rate shows overuse again a round trip later, and that cut goes below. Nor is that
      // delivered rate the link's capacity, near which growth slows: it held replies that cannot
      // shrink near the start's rate (docs/links.md, round seven).
      const bool first_of_free_start = free_start_ && !last_decrease_;
      if (first_of_free_start) cut = std::max(cut, std::min(target_bps_, start_bps_));
      target_bps_ = std::min(target_bps_, cut);
      last_decrease_ = now;
      capacity_bps_ = first_of_free_start ? 0 : delivered_bps_;
    }
  } else if (queue_delay_ms_ < options_.grow_below * target_delay) {
    const bool near_capacity = capacity_bps_ > 0 && target_bps_ >= 0.95 * capacity_bps_ &&
                               target_bps_ <= 1.3 * capacity_bps_;
    const double growth = !seen_overuse_  ? options_.startup_growth_per_second
                          : near_capacity ? options_.near_capacity_growth_per_second
                                          : options_.growth_per_second;
    // Never more than a probe's margin over what the link delivered: a sender held back by its
    // window sees no queueing delay, so the delay alone would let the target drift up (GCC caps
    // its estimate at 1.5 times the received rate for the same reason).
    // The replies before their first overuse grow further, to four times what they delivered:
    // their size is the scene's, and a near scene's cloud is several times the mean of far ones.
    const double over_delivered =
        free_start_ && !seen_overuse_ ? kFreeStartOverDelivered : options_.max_over_delivered;
    const double grown = target_bps_ * (1 + growth * dt);
    const double cap = delivered_bps_ > 0 ? over_delivered * delivered_bps_ : grown;
    target_bps_ = std::max(target_bps_, std::min(grown, cap));
  }
  target_bps_ = std::clamp(target_bps_, options_.min_bps, options_.max_bps);
}

// The downlink's bitrate is not the sender's to bound (--rate-max-mbps is the uplink's). The
// replies start at the uplink's starting bitrate, a guess as good as any about a link nothing has
// crossed yet, and grow as fast as the frames' start-up probe until the downlink first shows
// overuse, to four times the rate they delivered (not the frames' 1.6: a reply's size is the
// scene's, so that rate says little of what the downlink could carry): on a fat link the cap soon
// stops binding, growing 2.7 times a second. Whole replies until that first overuse came back late
// for the stream's first second on a thin link: TCP's first congestion windows and the link's queue
// took them at once (docs/links.md, round seven).
static RateControlOptions DownlinkOptions(RateControlOptions options) {
  options.max_bps = std::numeric_limits<double>::max();
  options.target_delay = options.reply_target_delay;
  return options;
}

RateController::RateController(RateControlOptions options)
    : options_(options),
      up_(options_, options_.start_bps),
      down_(DownlinkOptions(options_), options_.start_bps, /*free_start=*/true) {
  estimate_.target_bps = up_.target_bps();
  estimate_.reply_target_bps = ReplyTargetBps();
  estimate_.frames_in_flight = options_.min_frames_in_flight;
}

void RateController::OnFrameWritten(std::size_t bytes) {
  const double b = static_cast<double>(bytes);
  mean_frame_bytes_ = mean_frame_bytes_ == 0 ? b : 0.8 * mean_frame_bytes_ + 0.2 * b;
  UpdateWindow();
}

void RateController::OnCallOpened() {
  // A new call may reach another replica: another byte count, and another clock.
  up_.Restart();
  down_.Restart();
  reply_bytes_total_ = 0;
}

void RateController::OnReply(const Reply& reply) {
  const Clock::time_point received = reply.received;
  up_.AddDelivered(reply.server_receive_unix_ns, reply.stream_bytes_received);

  // The uplink's queueing delay is read from the frame's one-way delay: the server's clock when
  // the frame had arrived whole less ours when its write started. The two clocks' offset is
  // unknown but constant, so only the delay's growth over its windowed minimum is used. One way,
  // because the uplink is what this sender's bitrate fills: the reply's way back (its size, the
  // downlink's own queue) and the server's processing time say nothing about it, and in a round
  // trip they made up most of the variation (replies of 15 to 30 KB, frames processed in 1 to
  // 10 ms). The frame's own serialization stays in: a frame that takes longer to cross the link
  // than the target delay is latency the bitrate should answer, whether or not anything queued.
  const double rtt = std::max(0.0, Ms(received - reply.written));
  const double in_server =
      reply.server_receive_unix_ns > 0 && reply.server_send_unix_ns > reply.server_receive_unix_ns
          ? static_cast<double>(reply.server_send_unix_ns - reply.server_receive_unix_ns) / 1e6
          : 0;
  const bool server_clock = reply.server_receive_unix_ns > 0;
  if (server_clock && !server_clock_) {
    server_clock_ = true;
    up_.Restart();  // round trips measured before are on another scale
  }
  while (!round_trips_.empty() && round_trips_.back().second >= rtt) round_trips_.pop_back();
  round_trips_.emplace_back(received, rtt);
  while (received - round_trips_.front().first > options_.min_rtt_window) round_trips_.pop_front();
  estimate_.rtt_ms = estimate_.rtt_ms == 0 ? rtt : 0.875 * estimate_.rtt_ms + 0.125 * rtt;
  estimate_.min_rtt_ms = round_trips_.front().second;
  // A reply without the server's clock (an error) has no one-way delay to add; an older server
  // that never sends it leaves the round trip less the server's time as the measure.
  if (server_clock || !server_clock_) {
    up_.AddDelay(received,
                 server_clock
                     ? static_cast<double>(reply.server_receive_unix_ns - Ns(reply.written)) / 1e6
                     : std::max(0.0, rtt - in_server));
  }
  up_.Control(received, estimate_.rtt_ms);

  // The downlink: the reply's one-way delay (the server's send time to our receipt) and the
  // reply bytes we counted, on our clock. Only replies that carry the server's send time.
  if (reply.server_send_unix_ns > 0 && reply.reply_bytes > 0) {
    reply_bytes_total_ += reply.reply_bytes;
    const double b = static_cast<double>(reply.reply_bytes);
    mean_reply_bytes_ = mean_reply_bytes_ == 0 ? b : 0.8 * mean_reply_bytes_ + 0.2 * b;
    down_.AddDelivered(Ns(received), reply_bytes_total_);
    down_.AddDelay(received, static_cast<double>(Ns(received) - reply.server_send_unix_ns) / 1e6);
    down_.Control(received, estimate_.rtt_ms);
    reply_clock_ = true;
  } else {
    reply_without_clock_ = true;
  }

  estimate_.target_bps = up_.target_bps();
  estimate_.delivered_bps = up_.delivered_bps();
  estimate_.queue_delay_ms = up_.queue_delay_ms();
  estimate_.overuse = up_.overuse();
  estimate_.reply_target_bps = ReplyTargetBps();
  estimate_.reply_delivered_bps = down_.delivered_bps();
  estimate_.reply_queue_delay_ms = down_.queue_delay_ms();
  estimate_.reply_overuse = down_.overuse();
  UpdateWindow();
}

double RateController::ReplyTargetBps() const {
  return options_.cap_replies && (reply_clock_ || !reply_without_clock_) ? down_.target_bps() : 0;
}

void RateController::UpdateWindow() {
  if (mean_frame_bytes_ <= 0 || round_trips_.empty()) {
    estimate_.frames_in_flight = options_.min_frames_in_flight;
    return;
  }
  // The minimum round trip, plus the delay the controller lets build before it acts, plus as
  // much again for the round trip its cut takes to show (and TCP's own hiccups: after a lost
  // packet CUBIC's smaller window makes a frame take a round trip more, 0.1 % loss does that a
  // few times a second at 10 Mbit/s). Less than that and the camera's 30 frames a second do not
  // fit in flight on a 40 ms link.
  const double slack = std::max(2 * static_cast<double>(options_.target_delay.count()),
                                static_cast<double>(options_.min_window_slack.count()));
  const double seconds = (round_trips_.front().second + slack) / 1000;
  double frames = estimate_.target_bps / 8 * seconds / mean_frame_bytes_;
  // The replies too: when the downlink limits them and they cannot shrink enough (the server's
  // cap meets its floors: CloudReply.over_cap), fewer frames in flight is what keeps their queue
  // short.
  if (estimate_.reply_target_bps > 0 && mean_reply_bytes_ > 0) {
    frames = std::min(frames, estimate_.reply_target_bps / 8 * seconds / mean_reply_bytes_);
  }
  estimate_.frames_in_flight =
      std::clamp(static_cast<int>(std::ceil(frames)), options_.min_frames_in_flight,
                 options_.max_frames_in_flight);
}

std::size_t RateController::FrameBudgetBytes(double fps) const {
  if (fps <= 0) return static_cast<std::size_t>(estimate_.target_bps / 8);
  return static_cast<std::size_t>(estimate_.target_bps / 8 / fps);
}

std::size_t RateController::ReplyBudgetBytes(double fps) const {
  if (estimate_.reply_target_bps <= 0) return 0;
  return static_cast<std::size_t>(estimate_.reply_target_bps / 8 / std::max(fps, 1.0));
}

void QualityFollower::Encoded(std::size_t bytes, std::size_t budget_bytes) {
  const double ratio =
      static_cast<double>(bytes) / static_cast<double>(std::max<std::size_t>(1, budget_bytes));
  // JPEG's size roughly doubles from quality 50 to 90: steps of 2 to 10 settle in a few frames.
  int step = 0;
  if (ratio > 1.0)
    step = -std::clamp(static_cast<int>((ratio - 1.0) * 20), 2, 10);
  else if (ratio < 0.8)
    step = std::clamp(static_cast<int>((0.8 - ratio) * 20), 1, 5);
  quality_ = std::clamp(quality_ + step, min_, max_);
}

}  // namespace cloudcast::client
