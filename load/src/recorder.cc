#include "cloudcast/load/recorder.h"

namespace cloudcast::load {

void Recorder::Sent(std::size_t bytes) {
  std::lock_guard<std::mutex> lock(mu_);
  ++totals_.sent;
  ++interval_.sent;
  totals_.bytes_sent += bytes;
}

void Recorder::Late(bool flow_control) {
  std::lock_guard<std::mutex> lock(mu_);
  ++(flow_control ? totals_.late_flow_control : totals_.late_scheduler);
  ++interval_.late;
}

void Recorder::Answered(std::int64_t latency_ns, std::int64_t service_ns,
                        const std::string& instance, std::size_t bytes) {
  std::lock_guard<std::mutex> lock(mu_);
  ++totals_.answered;
  ++interval_.answered;
  totals_.bytes_received += bytes;
  interval_.bytes_received += bytes;
  latency_.Record(latency_ns);
  service_.Record(service_ns);
  interval_latency_.Record(latency_ns);
  interval_service_.Record(service_ns);
  ++per_instance_[instance.empty() ? "(unnamed)" : instance];
  ++status_codes_["OK"];
}

void Recorder::Downlink(int color_bits, bool over_cap) {
  std::lock_guard<std::mutex> lock(mu_);
  ++totals_.color_bits[color_bits];
  if (over_cap) ++totals_.over_cap;
}

int Totals::color_bits_median() const {
  std::uint64_t n = 0;
  for (const auto& [bits, clouds] : color_bits) n += bits > 0 ? clouds : 0;
  // Nearest rank, as the latency percentiles.
  std::uint64_t seen = 0;
  for (const auto& [bits, clouds] : color_bits) {
    if (bits <= 0) continue;
    seen += clouds;
    if (2 * seen >= n) return bits;
  }
  return 0;
}

void Recorder::FrameError(const std::string& code, const std::string& message,
                          const std::string& instance) {
  std::lock_guard<std::mutex> lock(mu_);
  ++totals_.frame_errors;
  ++interval_.errors;
  ++status_codes_[code];
  ++errors_[code + ": " + message];
  ++per_instance_[instance.empty() ? "(unnamed)" : instance];
}

void Recorder::Dropped(std::uint64_t frames) {
  std::lock_guard<std::mutex> lock(mu_);
  totals_.drops += frames;
  interval_.drops += frames;
}

void Recorder::StreamEnded(std::uint64_t server_dropped) {
  std::lock_guard<std::mutex> lock(mu_);
  totals_.server_dropped += server_dropped;
}

void Recorder::Lost(std::uint64_t frames, const std::string& code, const std::string& message) {
  if (frames == 0) return;
  std::lock_guard<std::mutex> lock(mu_);
  totals_.lost += frames;
  interval_.errors += frames;
  status_codes_[code == "OK" ? "UNANSWERED" : code] += frames;
  errors_[(code == "OK" ? std::string("UNANSWERED") : code) + ": " +
          (message.empty() ? std::string("the call ended before the frame was answered")
                           : message)] += frames;
}

void Recorder::Unsent(std::uint64_t frames) {
  std::lock_guard<std::mutex> lock(mu_);
  totals_.unsent += frames;
}

void Recorder::Replaced(std::uint64_t frames) {
  std::lock_guard<std::mutex> lock(mu_);
  totals_.replaced += frames;
}

void Recorder::Skipped(std::uint64_t frames) {
  std::lock_guard<std::mutex> lock(mu_);
  totals_.skipped += frames;
}

void Recorder::KeyframeNeeded() {
  std::lock_guard<std::mutex> lock(mu_);
  ++totals_.keyframe_needed;
}

void Recorder::KeyframeSent(bool asked) {
  std::lock_guard<std::mutex> lock(mu_);
  ++totals_.keyframes_sent;
  if (asked) ++totals_.keyframe_restarts;
}

void Recorder::LiveEncoded(double encode_ms, std::size_t picture_bytes) {
  std::lock_guard<std::mutex> lock(mu_);
  ++totals_.live_encoded;
  totals_.live_picture_bytes += picture_bytes;
  live_encode_us_.Record(static_cast<std::int64_t>(encode_ms * 1e3));
}

void Recorder::CallStatus(const std::string& code) {
  std::lock_guard<std::mutex> lock(mu_);
  ++call_status_[code];
}

void Recorder::Resent(std::size_t bytes) {
  std::lock_guard<std::mutex> lock(mu_);
  ++totals_.resent;
  ++interval_.resent;
  totals_.bytes_sent += bytes;
}

void Recorder::Duplicate() {
  std::lock_guard<std::mutex> lock(mu_);
  ++totals_.duplicates;
}

void Recorder::ReconnectAttempt() {
  std::lock_guard<std::mutex> lock(mu_);
  ++totals_.reconnect_attempts;
}

void Recorder::Reconnected() {
  std::lock_guard<std::mutex> lock(mu_);
  ++totals_.reconnects;
  ++interval_.reconnects;
}

void Recorder::GaveUp() {
  std::lock_guard<std::mutex> lock(mu_);
  ++totals_.streams_given_up;
}

SecondStats Recorder::CloseInterval(double t_end_s, int open_streams) {
  std::lock_guard<std::mutex> lock(mu_);
  SecondStats s = interval_;
  s.t_end_s = t_end_s;
  s.duration_s = t_end_s - interval_start_s_;
  s.open_streams = open_streams;
  s.p50 = interval_latency_.Percentile(50);
  s.p90 = interval_latency_.Percentile(90);
  s.p99 = interval_latency_.Percentile(99);
  s.max = interval_latency_.max();
  s.service_p50 = interval_service_.Percentile(50);
  s.service_p99 = interval_service_.Percentile(99);
  s.rate = interval_rate_.Summary();
  interval_rate_ = RateSums{};
  series_.push_back(s);
  interval_ = SecondStats{};
  interval_latency_.Reset();
  interval_service_.Reset();
  interval_start_s_ = t_end_s;
  return s;
}

Totals Recorder::totals() const {
  std::lock_guard<std::mutex> lock(mu_);
  return totals_;
}
Histogram Recorder::latency() const {
  std::lock_guard<std::mutex> lock(mu_);
  return latency_;
}
Histogram Recorder::service() const {
  std::lock_guard<std::mutex> lock(mu_);
  return service_;
}
Histogram Recorder::live_encode() const {
  std::lock_guard<std::mutex> lock(mu_);
  return live_encode_us_;
}
std::map<std::string, std::uint64_t> Recorder::per_instance() const {
  std::lock_guard<std::mutex> lock(mu_);
  return per_instance_;
}
std::map<std::string, std::uint64_t> Recorder::status_codes() const {
  std::lock_guard<std::mutex> lock(mu_);
  return status_codes_;
}
std::map<std::string, std::uint64_t> Recorder::errors() const {
  std::lock_guard<std::mutex> lock(mu_);
  return errors_;
}
std::map<std::string, std::uint64_t> Recorder::call_status() const {
  std::lock_guard<std::mutex> lock(mu_);
  return call_status_;
}
std::vector<SecondStats> Recorder::series() const {
  std::lock_guard<std::mutex> lock(mu_);
  return series_;
}

void Recorder::RateSample(int stream, const client::RateEstimate& rate, std::size_t frame_bytes) {
  std::lock_guard<std::mutex> lock(mu_);
  for (RateSums* sums : {&interval_rate_, &run_rate_}) {
    ++sums->n;
    sums->rtt += rate.rtt_ms;
    sums->queue += rate.queue_delay_ms;
    sums->window += rate.frames_in_flight;
    sums->bytes += static_cast<double>(frame_bytes);
    sums->reply_cap += static_cast<double>(rate.reply_cap_bytes);
    sums->reply_queue += rate.reply_queue_delay_ms;
    sums->target_sum[stream] += rate.target_bps;
    sums->reply_target_sum[stream] += rate.reply_target_bps;
    ++sums->target_n[stream];
  }
}

RateSummary Recorder::RateSums::Summary() const {
  RateSummary r;
  if (n == 0) return r;
  const double count = static_cast<double>(n);
  r.samples = n;
  r.rtt_ms = rtt / count;
  r.queue_delay_ms = queue / count;
  r.window = window / count;
  r.frame_bytes = bytes / count;
  r.reply_cap_bytes = reply_cap / count;
  r.reply_queue_delay_ms = reply_queue / count;
  for (const auto& [stream, sum] : target_sum) {
    r.target_bps += sum / static_cast<double>(target_n.at(stream));
  }
  for (const auto& [stream, sum] : reply_target_sum) {
    r.reply_target_bps += sum / static_cast<double>(target_n.at(stream));
  }
  return r;
}

RateSummary Recorder::rate() const {
  std::lock_guard<std::mutex> lock(mu_);
  return run_rate_.Summary();
}

}  // namespace cloudcast::load
