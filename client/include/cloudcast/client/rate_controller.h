// A sender's rate control: from what each reply tells (its round trip, and the request bytes the
// server had received and when), it estimates the link and sets two things: the bitrate frames
// are made at (the encoder follows it: JPEG quality today) and how many frames may be in flight
// (written and not yet answered). It watches the way back too, and sets the bitrate the replies
// may take (the stream core caps each reply's cloud at it). gRPC-free and clock-free: times come
// in as arguments, so rate_controller_test drives it through steps and outages.
//
// Delay-based, in the spirit of WebRTC's GCC (Carlucci et al., 2016), once per direction
// (DirectionRate): a direction's queueing delay is the growth of its one-way delay over its
// windowed minimum; the uplink's is our write to the server's receive time, the downlink's the
// server's send time to our receipt of the reply (two clocks whose constant offset cancels), so
// neither sees the other's queue nor the server's processing. While the delay stays under
// most of the target delay the bitrate grows multiplicatively (never past a margin over the
// delivered rate); above the target it falls to a fraction of the rate delivered (the uplink's
// as the server counted it, CloudReply.stream_bytes_received over receive_time_unix_ns; the
// downlink's as we counted the replies), at most once a round trip. Loss does not steer it: TCP
// hides loss as delay, which this sees.
//
// Why the replies need their own bitrate: on a thin link the clouds coming back (15 to 20 KB a
// frame, 4 to 5 Mbit/s at 30 fps) can fill the downlink, and the uplink's acknowledgements then
// queue behind them: the uplink's one-way delay grows whatever the frames' bitrate, and a
// controller that only cuts the uplink cuts it to its floor (docs/links.md, round three).
//
// The in-flight window is what keeps latency bounded while the encoder catches up (a step down,
// an outage): a frame past the window waits in the sender, where DELIVERY_LATEST replaces it with
// a newer one, instead of queueing behind the link in TCP's buffers. It holds the target's bytes
// for one minimum round trip (all of it: serialization and the server's time included) plus
// twice the target delay, rounded up, at least `min_frames_in_flight`; and no more than the
// replies' bitrate carries back in that time (replies the server cannot shrink to their cap would
// otherwise queue on the way back).
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <optional>
#include <utility>

namespace cloudcast::client {

struct RateControlOptions {
  // Both ways: the frames' bitrate and the replies' (cap_replies) start here.
  double start_bps = 4e6;
  double min_bps = 0.25e6;
  double max_bps = 100e6;
  // Queueing delay over which the link counts as overused. 15 ms: on the emulated 10 Mbit/s,
  // 40 ms link it keeps latency at p50 69 ms and p99 125 to 141 ms where 30 ms gave 84 to 96 and
  // 169 to 193, at the same camera rate; its cost is bytes per frame, and a slower climb back
  // after a link recovers (docs/links.md, round four).
  std::chrono::milliseconds target_delay{15};
  // The same for the downlink (the replies). Longer: a reply's size is the scene's, not ours (a
  // near scene's cloud is eight times a far one's, 5 to 43 ms apart on a 3 Mbit/s downlink), so
  // its one-way delay varies more than a frame's, whose size the encoder sets; at 15 ms the
  // replies' bitrate fell to two thirds of what they needed on a downlink that carried them
  // (rate_controller_test).
  std::chrono::milliseconds reply_target_delay{30};
  // The bitrate grows while the queueing delay is under this fraction of target_delay, and holds
  // between it and target_delay. Frames in flight queue behind one another by design (a 23 KB
  // frame is 18 ms at 10 Mbit/s, its reply takes the downlink's time): a narrow band would hold
  // the bitrate far under the link.
  double grow_below = 0.8;
  // After overuse: this fraction of the delivered rate.
  double backoff = 0.85;
  // Growth while the delay is low, per second: faster until the first overuse (a start-up
  // probe), then gentler.
  double startup_growth_per_second = 1.0;
  double growth_per_second = 0.4;
  // Near the rate delivered at the last overuse (0.95 to 1.3 times it) it grows this slowly,
  // as GCC does near its last maximum: the link's rate is probably there.
  double near_capacity_growth_per_second = 0.1;
  // Growth stops at this multiple of the delivered rate (the probe's margin).
  double max_over_delivered = 1.6;
  // The window covers the minimum round trip plus twice target_delay, and at least this much
  // beyond it: after a lost packet TCP makes a frame take a round trip more whatever the target.
  std::chrono::milliseconds min_window_slack{60};
  int min_frames_in_flight = 2;
  int max_frames_in_flight = 8;
  std::chrono::seconds min_rtt_window{10};
  // The replies follow the downlink: the stream core caps each reply's cloud
  // (DracoConfig.max_cloud_bytes, at most the cap the stream's own config sets) at the replies'
  // bitrate over the frame rate, from the stream's first frames (the replies start at
  // start_bps too). Off: replies take what they take.
  bool cap_replies = true;
};

// What the controller knows now (the library's results, cloudcast-load's report).
struct RateEstimate {
  double target_bps = 0;
  double delivered_bps = 0;   // uplink, as the server counted it (0: not known yet)
  double rtt_ms = 0;          // smoothed: a frame's write to its reply
  double min_rtt_ms = 0;      // the round trip's minimum over min_rtt_window
  double queue_delay_ms = 0;  // smoothed rtt growth over the minimum
  int frames_in_flight = 0;   // the window
  bool overuse = false;       // the last reply saw the delay over its target
  // The downlink, from the replies: the bitrate they may take (0: no limit: cap_replies is off,
  // or the server sends no send time), what came back, and its queueing delay.
  double reply_target_bps = 0;
  double reply_delivered_bps = 0;
  double reply_queue_delay_ms = 0;
  bool reply_overuse = false;
  // The cap on each reply's cloud the stream core asked for (ReplyCapFollower; 0: none).
  std::uint64_t reply_cap_bytes = 0;
};

// One direction of the link: its queueing delay, its delivered rate and the bitrate that keeps
// its queue under the target delay (RateController's rules). Times in, no clock of its own.
class DirectionRate {
 public:
  using Clock = std::chrono::steady_clock;

  // `free_start` (the replies, whose size is not ours to set: RateController): until the first
  // overuse the bitrate grows to four times the delivered rate, not max_over_delivered, and the
  // first cut stops at `start_bps` and sets no capacity.
  DirectionRate(const RateControlOptions& options, double start_bps, bool free_start = false);

  // The far end's count of this direction's bytes (cumulative) at `at_ns` on its clock.
  void AddDelivered(std::int64_t at_ns, std::uint64_t cumulative_bytes);
  // One message's one-way delay (any constant offset), seen at `now`.
  void AddDelay(Clock::time_point now, double one_way_ms);
  // Overuse or growth after a message seen at `now`; cuts at most once per `rtt_ms`.
  void Control(Clock::time_point now, double rtt_ms);
  // A new call (another replica perhaps): byte counts and the delay's minimum start again.
  void Restart();

  double target_bps() const { return target_bps_; }
  double delivered_bps() const { return delivered_bps_; }
  double queue_delay_ms() const { return queue_delay_ms_; }
  bool overuse() const { return overuse_; }

 private:
  RateControlOptions options_;
  double target_bps_;
  double delivered_bps_ = 0;
  double queue_delay_ms_ = 0;     // smoothed
  double last_queue_sample_ = 0;  // the last message's delay over the minimum, ms
  bool overuse_ = false;
  int over_streak_ = 0;  // messages in a row that saw overuse
  // Windowed minimum of the one-way delay (ascending in value, oldest first).
  std::deque<std::pair<Clock::time_point, double>> delays_;
  std::deque<std::pair<std::int64_t, std::uint64_t>> delivered_;  // far end's time, bytes
  std::optional<Clock::time_point> last_update_;
  std::optional<Clock::time_point> last_decrease_;
  bool seen_overuse_ = false;
  double start_bps_;
  bool free_start_ = false;
  double capacity_bps_ = 0;  // delivered at the last overuse (0: none yet)
};

class RateController {
 public:
  using Clock = std::chrono::steady_clock;

  explicit RateController(RateControlOptions options = {});

  // A frame's bytes went out (for the mean frame size the window is counted in).
  void OnFrameWritten(std::size_t bytes);
  // What a reply tells about its frame.
  struct Reply {
    Clock::time_point written;   // the frame's write started
    Clock::time_point received;  // its reply arrived
    std::size_t frame_bytes = 0;
    // The server's (CloudReply receive_time_unix_ns, send_time_unix_ns, stream_bytes_received);
    // 0 when the server sends none (an error reply, an older server): the delivered rate then
    // stays unknown and overuse halves the target instead.
    std::int64_t server_receive_unix_ns = 0;
    std::int64_t server_send_unix_ns = 0;
    std::uint64_t stream_bytes_received = 0;
    // The reply's own bytes (the downlink's count); 0: not counted.
    std::size_t reply_bytes = 0;
  };
  void OnReply(const Reply& reply);
  // A new call: the server's byte count starts again.
  void OnCallOpened();

  const RateEstimate& estimate() const { return estimate_; }
  int frames_in_flight() const { return estimate_.frames_in_flight; }
  // The bytes a frame may take at `fps` frames a second.
  std::size_t FrameBudgetBytes(double fps) const;
  // The bytes a reply may take at `fps` replies a second; 0: no limit.
  std::size_t ReplyBudgetBytes(double fps) const;

 private:
  void UpdateWindow();
  // The bitrate the replies may take (RateEstimate::reply_target_bps).
  double ReplyTargetBps() const;

  const RateControlOptions options_;
  RateEstimate estimate_;
  DirectionRate up_;
  DirectionRate down_;
  double mean_frame_bytes_ = 0;
  double mean_reply_bytes_ = 0;
  // Windowed minimum of the whole round trip, which sizes the window (a frame in flight spends
  // all of it).
  std::deque<std::pair<Clock::time_point, double>> round_trips_;
  bool server_clock_ = false;            // replies carry the server's receive time
  std::uint64_t reply_bytes_total_ = 0;  // the downlink's count, this call
  // Whether replies carried the server's send time (the downlink's delay), and whether one came
  // without it: a server that never sends it leaves the replies uncapped, their rate unknown.
  bool reply_clock_ = false;
  bool reply_without_clock_ = false;
};

// An encoder quality (JPEG's 1..100, or any scale where higher means more bytes) that follows a
// byte budget frame by frame: down when a frame came out over its budget, up when it came out well
// under, a few steps at a time. For senders that encode each frame themselves (cloudcast-client);
// cloudcast-load picks from frames it encoded beforehand at fixed qualities instead.
class QualityFollower {
 public:
  QualityFollower(int start, int min_quality, int max_quality)
      : quality_(start), min_(min_quality), max_(max_quality) {}
  int quality() const { return quality_; }
  // The frame just made at quality() took `bytes`; the next may take `budget_bytes`.
  void Encoded(std::size_t bytes, std::size_t budget_bytes);

 private:
  int quality_, min_, max_;
};

}  // namespace cloudcast::client
