// The cap the stream core puts on each reply's cloud (DracoConfig.max_cloud_bytes) so that the
// replies follow the downlink: the rate controller's reply bitrate (RateEstimate::
// reply_target_bps) over the camera's frame rate (every frame submitted, sent or not), never
// above the cap the stream's own config asks for. The camera's rate, not the rate frames go out
// at: over the latter, fewer frames would make a larger cap, larger replies, and fewer frames
// again (measured: 14 answered frames a second where 21 fit); replies made small enough for
// every frame leave the window (RateController) to drop frames only when the server's floors
// stop the clouds shrinking. It decides what to send and when; the core sends it (a StreamConfig
// written in order with the frames, which the server applies to the frames after it).
//
// A change is sent when the cap falls by a tenth (a queue is building: at once), or grows by a
// fifth and the last change is half a second old (growth can wait: each change is a config
// message, and the controller grows in small steps). gRPC-free and clock-free, like the
// controller: reply_cap_test drives it.
#pragma once

#include <chrono>
#include <cstdint>
#include <deque>
#include <optional>

#include "cloudcast/client/rate_controller.h"

namespace cloudcast::client {

class ReplyCapFollower {
 public:
  using Clock = std::chrono::steady_clock;

  // The smallest cap sent: below it the server's floors (its error bound, min_color_bits) set
  // the size anyway, so a smaller number would only say less.
  static constexpr std::uint64_t kMinCapBytes = 1000;

  // The stream's own cap (its config's max_cloud_bytes; 0: none). The core's cap never exceeds it.
  void SetStreamCap(std::uint64_t stream_cap) { stream_cap_ = stream_cap; }
  // The camera made a frame (submitted, or replaced before it was made).
  void OnFrame(Clock::time_point now);
  // After the controller saw a reply: the cap the stream should have now, when it differs
  // enough from the one sent last (0: back to the stream's own); nullopt: keep what was sent.
  std::optional<std::uint64_t> Update(const RateEstimate& estimate, Clock::time_point now);
  // The cap in force: the last one Update returned, never above the stream's own; the stream's
  // own before any (0: none).
  std::uint64_t cap() const;
  // The camera's frames per second over the last second (0 before two frames).
  double frame_rate() const;

 private:
  std::uint64_t stream_cap_ = 0;
  std::optional<std::uint64_t> sent_;
  std::optional<Clock::time_point> last_change_;
  std::deque<Clock::time_point> frames_;  // the last second's
};

}  // namespace cloudcast::client
