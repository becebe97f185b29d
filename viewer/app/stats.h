// cloudcast-client's statistics: what was sent, received, dropped and displayed, end-to-end
// latency percentiles and per-frame sizes, as progress lines, a summary and JSON.
//
// Thread-safe: the sender, the receiver and the viewer each record into one StreamStats.
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "cloudcast/client/result.h"

namespace cloudcast::client::app {

using Json = nlohmann::ordered_json;

// Nearest-rank percentile (p in [0, 100]) of `values`; 0 when empty. Sorts a copy.
double Percentile(std::vector<double> values, double p);

// Exponential moving average for the overlay: steady enough to read, quick to follow changes.
class Smoothed {
 public:
  explicit Smoothed(double alpha = 0.1) : alpha_(alpha) {}
  void Add(double v) {
    value_ = has_ ? value_ + alpha_ * (v - value_) : v;
    has_ = true;
  }
  double value() const { return value_; }
  bool has_value() const { return has_; }

 private:
  double alpha_;
  double value_ = 0;
  bool has_ = false;
};

// Everything counted so far, copied out at once.
struct StatsSnapshot {
  double elapsed_s = 0;  // since the first frame was sent
  std::uint64_t sent = 0;
  std::uint64_t received = 0;  // clouds
  std::uint64_t errors = 0;    // frames the server answered with an error (or undecodable)
  std::uint64_t dropped = 0;   // frames the server skipped (DELIVERY_LATEST)
  std::uint64_t displayed = 0;
  std::uint64_t uplink_bytes = 0;  // pixel or file bytes handed to the stream
  std::uint64_t points = 0;        // total over received clouds
  std::uint64_t draco_bytes = 0;
  // The downlink cap (--max-reply-kb): the bits the server chose for the latest cloud, and the
  // clouds it could not bring under the cap (CloudReply.over_cap).
  int position_bits = 0, color_bits = 0;
  std::uint64_t over_cap = 0;
  // Clouds by the voxel minimum they were made with (CloudReply.min_points_per_voxel): above the
  // stream's own when the cap thinned them (--cap-min-points-per-voxel, contract revision 5).
  std::map<std::uint32_t, std::uint64_t> clouds_by_min_points;
  // Clouds of frames sent at half resolution (--rate-control's floor: Result::resolution_divisor
  // 2), and the resolution divisor of the latest (1: the camera's).
  std::uint64_t half_resolution = 0;
  int resolution_divisor = 1;
  double received_fps = 0;   // clouds per second, first send to last reply
  double displayed_fps = 0;  // new clouds drawn per second, first to last display
  double latency_smoothed_ms = 0;
  double latency_p50_ms = 0, latency_p90_ms = 0, latency_p99_ms = 0;
  double latency_mean_ms = 0, latency_max_ms = 0;
  // Means per received cloud, in microseconds: the server's stages and this machine's decode.
  double server_decode_us = 0, server_pipeline_us = 0, server_encode_us = 0, server_queue_us = 0;
  double client_decode_us = 0;
};

class StreamStats {
 public:
  using Clock = std::chrono::steady_clock;

  // A frame was handed to the stream; `bytes` is its uplink payload (pixels or encoded files).
  void RecordSent(std::uint64_t bytes);
  // A reply: a cloud (ok) or a frame error; config errors are not frames and are not counted.
  void RecordResult(const Result& result);
  // The viewer drew a new cloud.
  void RecordDisplayed();
  // --rate-control: the controller's estimate with a reply, and the JPEG quality in force.
  void RecordRate(const RateEstimate& estimate, int jpeg_quality);

  StatsSnapshot Snapshot() const;

  // One line for periodic logging: rates over the time since the previous call, plus totals.
  std::string ProgressLine();

  // The end-of-run summary, several lines, for stdout.
  static std::string SummaryText(const StatsSnapshot& s, bool with_display);
  static Json ToJson(const StatsSnapshot& s, bool with_display);

 private:
  mutable std::mutex mu_;
  bool started_ = false;
  Clock::time_point first_send_, last_receive_, first_display_, last_display_;
  std::uint64_t sent_ = 0, received_ = 0, errors_ = 0, dropped_ = 0, displayed_ = 0;
  std::uint64_t uplink_bytes_ = 0, points_ = 0, draco_bytes_ = 0;
  int position_bits_ = 0, color_bits_ = 0;
  std::uint64_t over_cap_ = 0;
  std::map<std::uint32_t, std::uint64_t> clouds_by_min_points_;
  std::uint64_t half_resolution_ = 0;
  int resolution_divisor_ = 1;
  std::vector<double> latencies_ms_;
  Smoothed latency_smoothed_;
  double sum_server_decode_us_ = 0, sum_pipeline_us_ = 0, sum_encode_us_ = 0, sum_queue_us_ = 0;
  double sum_client_decode_us_ = 0;
  std::optional<RateEstimate> rate_;
  int jpeg_quality_ = 0;

  // ProgressLine's previous totals.
  Clock::time_point progress_at_;
  std::uint64_t progress_received_ = 0, progress_displayed_ = 0, progress_sent_ = 0;
};

}  // namespace cloudcast::client::app
