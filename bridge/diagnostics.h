// What the bridge reports on /diagnostics: its counters and the per-stage times of the replies
// (the server's decode, rectify and match (stereo pairs), pipeline, encode and queue times, the
// round trip, the bridge's own Draco decode), as means and maxima over each diagnostics period.
#pragma once

#include <cstdint>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "cloudcast/client/result.h"

namespace cloudcast::ros_bridge {

// One diagnostic_msgs/DiagnosticStatus, as either transport publishes it (in a DiagnosticArray
// stamped with the report's time).
struct DiagnosticReport {
  enum Level : std::uint8_t { kOk = 0, kWarn = 1, kError = 2, kStale = 3 };
  Level level = kOk;
  std::string name, message, hardware_id;
  std::vector<std::pair<std::string, std::string>> values;
};

// Thread-safe: the ROS thread counts inputs and sends, the stream's receiver thread the replies.
class BridgeStats {
 public:
  void FrameIn();                          // a synchronized set of input messages
  void InputError(const absl::Status& s);  // ... that could not become a frame
  void Sent();                             // a frame handed to the stream
  void NotSent(const absl::Status& s);     // no stream to send it on, or Send failed
  // The server did not answer the bridge's first call, or refused it (a wrong token): the link
  // is down and says why from the first report on, before any frame comes.
  void LinkDown(const absl::Status& s);
  void Reply(const client::Result& r);     // a reply (cloud or frame error)
  // Frames dropped so far on the current stream (a reply's count), and one more reconnect of it.
  void StreamDropped(std::uint64_t frames_dropped);
  void Reconnected();
  void StreamClosed();  // the stream ended: its drops are added to those of the streams before
  // ~encoding jpeg: the coder's last frame after a reply (its JPEG quality, and whether it went
  // at half resolution).
  void JpegCoded(int quality, bool half_resolution);
  void Published();     // a PointCloud2 went out
  void PublishError(const absl::Status& s);  // a reply's extra (the disparity map) was unusable

  // The report for the period since the previous one (which it starts anew), made at `now_s`
  // (seconds on the transport's clock). `name` is the status's name, `hardware_id` the server
  // target.
  DiagnosticReport Report(double now_s, const std::string& name, const std::string& hardware_id);

 private:
  struct Stage {
    double sum = 0, max = 0;
    void Add(double v) {
      sum += v;
      if (v > max) max = v;
    }
  };
  std::mutex mu_;
  // Totals since start.
  std::uint64_t frames_in_ = 0, input_errors_ = 0, frames_sent_ = 0, not_sent_ = 0;
  std::uint64_t clouds_ = 0, frame_errors_ = 0, published_ = 0, publish_errors_ = 0;
  std::uint64_t dropped_before_ = 0, dropped_now_ = 0;
  std::uint64_t reconnects_ = 0;
  std::string last_error_;
  bool link_down_ = false;  // the last send found no stream
  // This period.
  std::uint64_t period_clouds_ = 0, period_errors_ = 0, period_sent_ = 0;
  Stage decode_, rectify_, match_, pipeline_, encode_, queue_, round_trip_, bridge_decode_, points_,
      draco_bytes_;
  float position_error_bound_ = 0;
  // The last reply's Draco quantization (what a downlink cap made the server choose), and the
  // replies that came back over the cap.
  int position_bits_ = 0, color_bits_ = 0;
  std::uint64_t over_cap_ = 0;
  // The uplink: the bytes the server counted on the stream (CloudReply.stream_bytes_received,
  // a running total per stream) since the period began, and the last total seen.
  std::uint64_t period_uplink_bytes_ = 0, last_stream_bytes_ = 0;
  // rate_control: the rate controller's estimate after the last reply (its target is what the
  // video encoder follows).
  std::optional<client::RateEstimate> rate_;
  // ~encoding jpeg: the coder's last quality and resolution (unset before a reply), and the
  // clouds made from half-resolution frames (Result::resolution_divisor), in total.
  std::optional<std::pair<int, bool>> jpeg_;
  std::uint64_t half_resolution_clouds_ = 0;
  double period_start_s_ = -1;  // none yet
};

}  // namespace cloudcast::ros_bridge
