// A sender's rate control: from what each reply tells (its round trip, and the request bytes the
// server had received and when), it estimates the link and sets two things: the bitrate frames
// are made at (the encoder follows it: JPEG quality today) and how many frames may be in flight
// (written and not yet answered). gRPC-free and clock-free: times come in as arguments, so
// rate_controller_test drives it through steps and outages.
//
// Delay-based, in the spirit of WebRTC's GCC (Carlucci et al., 2016): the queueing delay is the
// growth of each frame's one-way delay (our write to the server's receive time, two clocks
// whose constant offset cancels) over its windowed minimum; the reply's way back and the
// server's processing stay out of it. While it stays under
// most of the target delay the bitrate grows multiplicatively (never past a margin over the
// delivered rate); above the target it falls to a fraction of the rate the server saw delivered
// (CloudReply.stream_bytes_received over receive_time_unix_ns), at most once a round trip. Loss
// does not steer it: TCP hides loss as delay, which this sees.
//
// The in-flight window is what keeps latency bounded while the encoder catches up (a step down,
// an outage): a frame past the window waits in the sender, where DELIVERY_LATEST replaces it with
// a newer one, instead of queueing behind the link in TCP's buffers. It holds the target's bytes
// for one minimum round trip (all of it: serialization and the server's time included) plus
// twice the target delay, rounded up, at least `min_frames_in_flight`.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <optional>
#include <utility>

namespace cloudcast::client {

struct RateControlOptions {
  double start_bps = 4e6;
  double min_bps = 0.25e6;
  double max_bps = 100e6;
  // Queueing delay over which the link counts as overused.
  std::chrono::milliseconds target_delay{30};
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
  };
  void OnReply(const Reply& reply);
  // A new call: the server's byte count starts again.
  void OnCallOpened();

  const RateEstimate& estimate() const { return estimate_; }
  int frames_in_flight() const { return estimate_.frames_in_flight; }
  // The bytes a frame may take at `fps` frames a second.
  std::size_t FrameBudgetBytes(double fps) const;

 private:
  void UpdateWindow();

  const RateControlOptions options_;
  RateEstimate estimate_;
  double mean_frame_bytes_ = 0;
  // Windowed minima (deques ascending in value, oldest first): of the frames' one-way delay
  // (server receive time less write time, plus the clocks' constant offset), which measures
  // queueing, and of the whole round trip, which sizes the window (a frame in flight spends all
  // of it).
  std::deque<std::pair<Clock::time_point, double>> delays_;
  std::deque<std::pair<Clock::time_point, double>> round_trips_;
  bool server_clock_ = false;     // replies carry the server's receive time
  double last_queue_sample_ = 0;  // the last reply's delay over the minimum, ms
  int over_streak_ = 0;           // replies in a row that saw overuse
  std::deque<std::pair<std::int64_t, std::uint64_t>> delivered_;  // server time, bytes
  std::optional<Clock::time_point> last_update_;
  std::optional<Clock::time_point> last_decrease_;
  bool seen_overuse_ = false;
  double capacity_bps_ = 0;  // delivered at the last overuse (0: none yet)
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
