#include "app/stats.h"

#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <cmath>

namespace cloudcast::client::app {
namespace {

double Seconds(StreamStats::Clock::duration d) { return std::chrono::duration<double>(d).count(); }

double PerFrame(double total, std::uint64_t n) { return n == 0 ? 0.0 : total / n; }

}  // namespace

double Percentile(std::vector<double> values, double p) {
  if (values.empty()) return 0;
  std::sort(values.begin(), values.end());
  // Nearest rank: the smallest value with at least p% of the samples at or below it.
  const double rank = std::ceil(p / 100.0 * static_cast<double>(values.size()));
  const std::size_t i = static_cast<std::size_t>(std::max(rank, 1.0)) - 1;
  return values[std::min(i, values.size() - 1)];
}

void StreamStats::RecordSent(std::uint64_t bytes) {
  std::lock_guard<std::mutex> lock(mu_);
  if (!started_) {
    started_ = true;
    first_send_ = progress_at_ = Clock::now();
  }
  ++sent_;
  uplink_bytes_ += bytes;
}

void StreamStats::RecordResult(const Result& result) {
  if (result.config_rejected) return;
  std::lock_guard<std::mutex> lock(mu_);
  // The server's count is cumulative for the stream, so the largest one seen is the total.
  dropped_ = std::max<std::uint64_t>(dropped_, result.frames_dropped);
  if (!result.ok()) {
    ++errors_;
    return;
  }
  ++received_;
  last_receive_ =
      result.times.receive.time_since_epoch().count() != 0 ? result.times.receive : Clock::now();
  points_ += result.reply.point_count();
  draco_bytes_ += result.draco_bytes();
  position_bits_ = result.reply.position_bits();
  color_bits_ = result.reply.color_bits();
  if (result.reply.has_over_cap()) ++over_cap_;
  ++clouds_by_min_points_[result.reply.min_points_per_voxel()];
  resolution_divisor_ = result.resolution_divisor;
  if (result.resolution_divisor == 2) ++half_resolution_;
  if (result.capture_time_unix_ns != 0 && result.times.receive_unix_ns != 0) {
    const double ms = std::chrono::duration<double, std::milli>(result.latency()).count();
    latencies_ms_.push_back(ms);
    latency_smoothed_.Add(ms);
  }
  sum_server_decode_us_ += result.reply.times().decode_us();
  sum_pipeline_us_ += result.reply.times().pipeline_us();
  sum_encode_us_ += result.reply.times().encode_us();
  sum_queue_us_ += result.reply.times().queue_us();
  sum_client_decode_us_ += static_cast<double>(result.times.decode_us);
}

void StreamStats::RecordDisplayed() {
  std::lock_guard<std::mutex> lock(mu_);
  const Clock::time_point now = Clock::now();
  if (displayed_ == 0) first_display_ = now;
  last_display_ = now;
  ++displayed_;
}

StatsSnapshot StreamStats::Snapshot() const {
  std::lock_guard<std::mutex> lock(mu_);
  StatsSnapshot s;
  s.elapsed_s = started_ ? Seconds(Clock::now() - first_send_) : 0;
  s.sent = sent_;
  s.received = received_;
  s.errors = errors_;
  s.dropped = dropped_;
  s.displayed = displayed_;
  s.uplink_bytes = uplink_bytes_;
  s.points = points_;
  s.draco_bytes = draco_bytes_;
  s.position_bits = position_bits_;
  s.color_bits = color_bits_;
  s.over_cap = over_cap_;
  s.clouds_by_min_points = clouds_by_min_points_;
  s.half_resolution = half_resolution_;
  s.resolution_divisor = resolution_divisor_;
  if (received_ > 0) {
    const double span = Seconds(last_receive_ - first_send_);
    s.received_fps = span > 0 ? received_ / span : 0;
  }
  if (displayed_ > 1) {
    // Intervals between displays: n displays span n - 1 of them.
    const double span = Seconds(last_display_ - first_display_);
    s.displayed_fps = span > 0 ? (displayed_ - 1) / span : 0;
  }
  s.latency_smoothed_ms = latency_smoothed_.value();
  if (!latencies_ms_.empty()) {
    s.latency_p50_ms = Percentile(latencies_ms_, 50);
    s.latency_p90_ms = Percentile(latencies_ms_, 90);
    s.latency_p99_ms = Percentile(latencies_ms_, 99);
    double sum = 0, max = 0;
    for (double v : latencies_ms_) sum += v, max = std::max(max, v);
    s.latency_mean_ms = sum / latencies_ms_.size();
    s.latency_max_ms = max;
  }
  s.server_decode_us = PerFrame(sum_server_decode_us_, received_);
  s.server_pipeline_us = PerFrame(sum_pipeline_us_, received_);
  s.server_encode_us = PerFrame(sum_encode_us_, received_);
  s.server_queue_us = PerFrame(sum_queue_us_, received_);
  s.client_decode_us = PerFrame(sum_client_decode_us_, received_);
  return s;
}

void StreamStats::RecordRate(const RateEstimate& estimate, int jpeg_quality) {
  std::lock_guard<std::mutex> lock(mu_);
  rate_ = estimate;
  jpeg_quality_ = jpeg_quality;
}

std::string StreamStats::ProgressLine() {
  const StatsSnapshot s = Snapshot();
  const Clock::time_point now = Clock::now();
  double dt = 0;
  std::uint64_t d_received = 0, d_displayed = 0, d_sent = 0;
  {
    std::lock_guard<std::mutex> lock(mu_);
    dt = started_ ? Seconds(now - progress_at_) : 0;
    d_received = s.received - progress_received_;
    d_displayed = s.displayed - progress_displayed_;
    d_sent = s.sent - progress_sent_;
    progress_at_ = now;
    progress_received_ = s.received;
    progress_displayed_ = s.displayed;
    progress_sent_ = s.sent;
  }
  auto rate = [dt](std::uint64_t n) { return dt > 0 ? n / dt : 0.0; };
  std::string line =
      fmt::format("sent {} ({:.1f}/s), received {} ({:.1f}/s), dropped {}, errors {}", s.sent,
                  rate(d_sent), s.received, rate(d_received), s.dropped, s.errors);
  if (s.displayed > 0) line += fmt::format(", displayed {:.1f}/s", rate(d_displayed));
  if (s.received > 0) {
    line += fmt::format(" | latency {:.1f} ms | {:.0f} points, {:.1f} KB per cloud",
                        s.latency_smoothed_ms, PerFrame(s.points, s.received),
                        PerFrame(s.draco_bytes, s.received) / 1024.0);
    // A server before contract revision 4 sends no colour bits.
    if (s.color_bits > 0) {
      line += fmt::format(" ({}/{} position/colour bits", s.position_bits, s.color_bits);
      line += s.over_cap > 0 ? fmt::format(", {} over the cap)", s.over_cap) : ")";
    }
  }
  std::lock_guard<std::mutex> lock(mu_);
  if (rate_) {
    line += fmt::format(
        " | target {:.1f} Mbit/s, rtt {:.0f} ms, queueing {:.0f} ms, {} in flight, {:.1f} KB per "
        "frame",
        rate_->target_bps / 1e6, rate_->rtt_ms, rate_->queue_delay_ms, rate_->frames_in_flight,
        PerFrame(s.uplink_bytes, s.sent) / 1024.0);
    if (jpeg_quality_ > 0) {
      line += fmt::format(", JPEG quality {} at {} resolution", jpeg_quality_,
                          s.resolution_divisor == 2 ? "half" : "full");
    }
    if (rate_->reply_target_bps > 0) {
      // The downlink limits the replies (RateControlOptions::cap_replies).
      line += fmt::format(
          " | replies {:.1f} Mbit/s allowed, capped at {:.1f} KB, queueing {:.0f} ms",
          rate_->reply_target_bps / 1e6, static_cast<double>(rate_->reply_cap_bytes) / 1000.0,
          rate_->reply_queue_delay_ms);
    }
  }
  return line;
}

std::string StreamStats::SummaryText(const StatsSnapshot& s, bool with_display) {
  std::string out;
  out += fmt::format("frames: sent {}, received {}, dropped {}, errors {}\n", s.sent, s.received,
                     s.dropped, s.errors);
  out += fmt::format("rate:   {:.1f} clouds/s received over {:.2f} s", s.received_fps, s.elapsed_s);
  if (with_display) {
    out += fmt::format(", {:.1f} displayed/s ({} displayed)", s.displayed_fps, s.displayed);
  }
  out += "\n";
  out += fmt::format(
      "latency (capture to reply, ms): p50 {:.2f}, p90 {:.2f}, p99 {:.2f}, "
      "mean {:.2f}, max {:.2f}\n",
      s.latency_p50_ms, s.latency_p90_ms, s.latency_p99_ms, s.latency_mean_ms, s.latency_max_ms);
  out += fmt::format("per cloud: {:.0f} points, {:.1f} KB Draco; {:.1f} KB sent per frame\n",
                     PerFrame(s.points, s.received), PerFrame(s.draco_bytes, s.received) / 1024.0,
                     PerFrame(s.uplink_bytes, s.sent) / 1024.0);
  if (s.half_resolution > 0) {
    out += fmt::format("resolution: {} of {} clouds from frames sent at half resolution\n",
                       s.half_resolution, s.received);
  }
  if (s.color_bits > 0) {
    out += fmt::format("Draco bits (last cloud): {} position, {} colour; {} clouds over the cap\n",
                       s.position_bits, s.color_bits, s.over_cap);
  }
  if (s.clouds_by_min_points.size() > 1) {  // the cap thinned some clouds
    std::string by;
    for (const auto& [min_points, clouds] : s.clouds_by_min_points) {
      by += fmt::format("{}{} at {}", by.empty() ? "" : ", ", clouds, min_points);
    }
    out += fmt::format("clouds by voxel minimum (points a voxel needed): {}\n", by);
  }
  out += fmt::format(
      "time per cloud (ms): server decode {:.2f}, pipeline {:.2f}, Draco encode "
      "{:.2f}, queue {:.2f}; client Draco decode {:.2f}\n",
      s.server_decode_us / 1000, s.server_pipeline_us / 1000, s.server_encode_us / 1000,
      s.server_queue_us / 1000, s.client_decode_us / 1000);
  return out;
}

Json StreamStats::ToJson(const StatsSnapshot& s, bool with_display) {
  Json j;
  j["frames"] = {
      {"sent", s.sent}, {"received", s.received}, {"dropped", s.dropped}, {"errors", s.errors}};
  if (with_display) j["frames"]["displayed"] = s.displayed;
  j["elapsed_s"] = s.elapsed_s;
  j["fps"] = s.received_fps;
  if (with_display) j["displayed_fps"] = s.displayed_fps;
  j["latency_ms"] = {{"p50", s.latency_p50_ms},
                     {"p90", s.latency_p90_ms},
                     {"p99", s.latency_p99_ms},
                     {"mean", s.latency_mean_ms},
                     {"max", s.latency_max_ms}};
  j["mean_points_per_frame"] = PerFrame(s.points, s.received);
  j["mean_draco_bytes_per_frame"] = PerFrame(s.draco_bytes, s.received);
  j["mean_uplink_bytes_per_frame"] = PerFrame(s.uplink_bytes, s.sent);
  j["draco_bits"] = {{"position", s.position_bits}, {"color", s.color_bits}};
  j["frames_over_cap"] = s.over_cap;
  Json by_min = Json::object();
  for (const auto& [min_points, clouds] : s.clouds_by_min_points) {
    by_min[std::to_string(min_points)] = clouds;
  }
  j["clouds_by_min_points_per_voxel"] = by_min;
  j["half_resolution_frames"] = s.half_resolution;
  j["mean_us_per_frame"] = {{"server_decode", s.server_decode_us},
                            {"server_pipeline", s.server_pipeline_us},
                            {"server_draco_encode", s.server_encode_us},
                            {"server_queue", s.server_queue_us},
                            {"client_draco_decode", s.client_decode_us}};
  return j;
}

}  // namespace cloudcast::client::app
