#include "diagnostics.h"

#include <cstdio>
#include <string>

namespace cloudcast::ros_bridge {
namespace {

void Add(DiagnosticReport* s, const std::string& key, const std::string& value) {
  s->values.emplace_back(key, value);
}

std::string Fixed(double v, int digits = 3) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

}  // namespace

void BridgeStats::FrameIn() {
  std::lock_guard<std::mutex> lock(mu_);
  ++frames_in_;
}

void BridgeStats::InputError(const absl::Status& s) {
  std::lock_guard<std::mutex> lock(mu_);
  ++input_errors_;
  ++period_errors_;
  last_error_ = s.ToString();  // with the code: UNAUTHENTICATED, ...
}

void BridgeStats::Sent() {
  std::lock_guard<std::mutex> lock(mu_);
  ++frames_sent_;
  ++period_sent_;
  link_down_ = false;
}

void BridgeStats::NotSent(const absl::Status& s) {
  std::lock_guard<std::mutex> lock(mu_);
  ++not_sent_;
  ++period_errors_;
  link_down_ = true;
  last_error_ = s.ToString();  // with the code: UNAUTHENTICATED, ...
}

void BridgeStats::LinkDown(const absl::Status& s) {
  std::lock_guard<std::mutex> lock(mu_);
  link_down_ = true;
  last_error_ = s.ToString();
}

void BridgeStats::Reply(const client::Result& r) {
  std::lock_guard<std::mutex> lock(mu_);
  if (!r.ok()) {
    ++frame_errors_;
    ++period_errors_;
    last_error_ = r.status.ToString();
    return;
  }
  ++clouds_;
  ++period_clouds_;
  const auto& t = r.reply.times();
  decode_.Add(t.decode_us() / 1000.0);
  rectify_.Add(t.rectify_us() / 1000.0);
  match_.Add(t.match_us() / 1000.0);
  pipeline_.Add(t.pipeline_us() / 1000.0);
  encode_.Add(t.encode_us() / 1000.0);
  queue_.Add(t.queue_us() / 1000.0);
  round_trip_.Add(std::chrono::duration<double, std::milli>(r.round_trip()).count());
  bridge_decode_.Add(r.times.decode_us / 1000.0);
  points_.Add(r.reply.point_count());
  draco_bytes_.Add(static_cast<double>(r.draco_bytes()));
  position_error_bound_ = r.reply.position_error_bound();
  // A smaller total is a new stream's (after a lost one): all of it is new bytes.
  const std::uint64_t total = r.reply.stream_bytes_received();
  period_uplink_bytes_ += total >= last_stream_bytes_ ? total - last_stream_bytes_ : total;
  last_stream_bytes_ = total;
  position_bits_ = r.reply.position_bits();
  color_bits_ = r.reply.color_bits();
  if (r.reply.has_over_cap()) ++over_cap_;
  if (r.rate) rate_ = *r.rate;
  if (r.resolution_divisor > 1) ++half_resolution_clouds_;
}

void BridgeStats::JpegCoded(int quality, bool half_resolution) {
  std::lock_guard<std::mutex> lock(mu_);
  jpeg_ = std::make_pair(quality, half_resolution);
}

void BridgeStats::StreamDropped(std::uint64_t frames_dropped) {
  std::lock_guard<std::mutex> lock(mu_);
  dropped_now_ = frames_dropped;
}

void BridgeStats::Reconnected() {
  std::lock_guard<std::mutex> lock(mu_);
  ++reconnects_;
}

void BridgeStats::StreamClosed() {
  std::lock_guard<std::mutex> lock(mu_);
  dropped_before_ += dropped_now_;
  dropped_now_ = 0;
}

void BridgeStats::Published() {
  std::lock_guard<std::mutex> lock(mu_);
  ++published_;
}

void BridgeStats::PublishError(const absl::Status& s) {
  std::lock_guard<std::mutex> lock(mu_);
  ++publish_errors_;
  ++period_errors_;
  last_error_ = s.ToString();
}

DiagnosticReport BridgeStats::Report(double now_s, const std::string& name,
                                     const std::string& hardware_id) {
  std::lock_guard<std::mutex> lock(mu_);
  DiagnosticReport s;
  s.name = name;
  s.hardware_id = hardware_id;
  if (link_down_) {
    s.level = DiagnosticReport::kError;
    s.message = "no stream to the server: " + last_error_;
  } else if (period_errors_ > 0) {
    s.level = DiagnosticReport::kWarn;
    s.message = "errors in this period; last: " + last_error_;
  } else if (period_sent_ > 0 && period_clouds_ == 0) {
    s.level = DiagnosticReport::kWarn;
    s.message = "frames sent, no cloud back in this period";
  } else {
    s.level = DiagnosticReport::kOk;
    s.message = period_clouds_ > 0 ? "streaming" : "waiting for frames";
  }
  const double seconds = period_start_s_ < 0 ? 0.0 : now_s - period_start_s_;
  Add(&s, "clouds_per_s", Fixed(seconds > 0 ? period_clouds_ / seconds : 0.0, 2));
  Add(&s, "frames_in", std::to_string(frames_in_));
  Add(&s, "input_errors", std::to_string(input_errors_));
  Add(&s, "frames_sent", std::to_string(frames_sent_));
  Add(&s, "frames_not_sent", std::to_string(not_sent_));
  Add(&s, "clouds", std::to_string(clouds_));
  Add(&s, "frame_errors", std::to_string(frame_errors_));
  Add(&s, "clouds_published", std::to_string(published_));
  Add(&s, "publish_errors", std::to_string(publish_errors_));
  Add(&s, "frames_dropped", std::to_string(dropped_before_ + dropped_now_));
  Add(&s, "reconnects", std::to_string(reconnects_));
  const double n = static_cast<double>(period_clouds_);
  const std::pair<const char*, Stage*> stages[] = {
      {"decode_ms", &decode_},         {"rectify_ms", &rectify_},
      {"match_ms", &match_},           {"pipeline_ms", &pipeline_},
      {"encode_ms", &encode_},         {"queue_ms", &queue_},
      {"round_trip_ms", &round_trip_}, {"bridge_decode_ms", &bridge_decode_}};
  for (const auto& [key, stage] : stages) {
    Add(&s, std::string(key) + "_mean", Fixed(n > 0 ? stage->sum / n : 0.0));
    Add(&s, std::string(key) + "_max", Fixed(stage->max));
  }
  Add(&s, "points_mean", Fixed(n > 0 ? points_.sum / n : 0.0, 0));
  Add(&s, "draco_bytes_mean", Fixed(n > 0 ? draco_bytes_.sum / n : 0.0, 0));
  Add(&s, "position_error_bound", Fixed(position_error_bound_, 6));
  // What the uplink carried this period (~encoding): per cloud (the bytes of frames the server
  // skipped or refused count with the next cloud's; frames replaced in the bridge never went),
  // and as a rate.
  Add(&s, "uplink_bytes_per_cloud",
      Fixed(n > 0 ? static_cast<double>(period_uplink_bytes_) / n : 0.0, 0));
  Add(&s, "uplink_kbps",
      Fixed(seconds > 0 ? static_cast<double>(period_uplink_bytes_) * 8 / 1000 / seconds : 0.0, 0));
  Add(&s, "position_bits", std::to_string(position_bits_));
  Add(&s, "color_bits", std::to_string(color_bits_));
  Add(&s, "replies_over_cap", std::to_string(over_cap_));
  if (rate_) {
    Add(&s, "target_kbps", Fixed(rate_->target_bps / 1000.0, 0));
    Add(&s, "delivered_kbps", Fixed(rate_->delivered_bps / 1000.0, 0));
    Add(&s, "rtt_ms", Fixed(rate_->rtt_ms));
    Add(&s, "queue_delay_ms", Fixed(rate_->queue_delay_ms));
  }
  if (jpeg_) {
    // What the JPEG coder made last (under rate_control, what the target carried), and how
    // many clouds came from frames at half resolution (a point per 2x2 block of the camera's).
    Add(&s, "jpeg_quality", std::to_string(jpeg_->first));
    Add(&s, "half_resolution", jpeg_->second ? "true" : "false");
    Add(&s, "half_resolution_clouds", std::to_string(half_resolution_clouds_));
  }
  if (!last_error_.empty()) Add(&s, "last_error", last_error_);

  period_clouds_ = period_errors_ = period_sent_ = 0;
  period_uplink_bytes_ = 0;
  decode_ = rectify_ = match_ = pipeline_ = encode_ = queue_ = round_trip_ = bridge_decode_ =
      points_ = draco_bytes_ = Stage{};
  period_start_s_ = now_s;
  return s;
}

}  // namespace cloudcast::ros_bridge
