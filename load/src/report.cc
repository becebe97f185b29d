#include "cloudcast/load/report.h"

#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <set>

namespace cloudcast::load {
namespace {

double Ms(std::int64_t ns) { return ns / 1e6; }

// "replica-1 > replica-3": the replicas that answered a stream's calls, in order.
std::string Path(const std::vector<std::string>& replicas) {
  std::string out;
  for (const std::string& r : replicas) out += (out.empty() ? "" : " > ") + r;
  return out.empty() ? "-" : out;
}

std::string Millis(const std::vector<std::int64_t>& ns) {
  std::string out;
  for (std::int64_t v : ns) out += fmt::format("{}{:.0f}", out.empty() ? "" : " ", v / 1e6);
  return out.empty() ? "-" : out;
}

std::string Rfc3339(std::chrono::system_clock::time_point t) {
  const std::time_t secs = std::chrono::system_clock::to_time_t(t);
  std::tm tm{};
  gmtime_r(&secs, &tm);
  char buf[64];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

nlohmann::json RateJson(const RateSummary& r) {
  return {{"samples", r.samples},
          {"targetBps", r.target_bps},
          {"rttMs", r.rtt_ms},
          {"queueDelayMs", r.queue_delay_ms},
          {"window", r.window},
          {"frameBytes", r.frame_bytes},
          {"replyTargetBps", r.reply_target_bps},
          {"replyCapBytes", r.reply_cap_bytes},
          {"replyQueueDelayMs", r.reply_queue_delay_ms}};
}

nlohmann::json Percentiles(const Histogram& h) {
  nlohmann::json j;
  j["count"] = h.count();
  j["p50"] = h.Percentile(50);
  j["p90"] = h.Percentile(90);
  j["p99"] = h.Percentile(99);
  j["p99.9"] = h.Percentile(99.9);
  j["max"] = h.max();
  j["min"] = h.min();
  j["mean"] = static_cast<std::int64_t>(h.mean());
  j["unit"] = "ns";
  return j;
}

}  // namespace

std::int64_t PercentileOf(const std::vector<std::int64_t>& sorted, double p) {
  if (sorted.empty()) return 0;
  const double rank = std::ceil(p / 100 * static_cast<double>(sorted.size()));
  const std::size_t i = static_cast<std::size_t>(std::clamp(rank, 1.0, 1.0 * sorted.size())) - 1;
  return sorted[i];
}

const std::vector<double>& ReportPercentiles() {
  static const std::vector<double> k = {50, 90, 99, 99.9};
  return k;
}

Report MakeReport(Fleet& fleet, const FleetResult& result, const std::string& frames,
                  const std::string& schedule, nlohmann::json options) {
  Report r;
  const FleetOptions& o = fleet.options();
  r.target = o.server;
  r.frames = frames;
  r.schedule = schedule;
  r.delivery = o.config.delivery() == v1::DELIVERY_ALL ? "DELIVERY_ALL" : "DELIVERY_LATEST";
  r.streams = o.streams;
  r.connections = o.connections == 0 ? o.streams : std::min(o.connections, o.streams);
  r.options = std::move(options);
  r.result = result;
  Recorder& rec = fleet.recorder();
  r.totals = rec.totals();
  r.latency = rec.latency();
  r.service = rec.service();
  r.live_encode_us = rec.live_encode();
  r.per_instance = rec.per_instance();
  r.status_codes = rec.status_codes();
  r.errors = rec.errors();
  r.call_status = rec.call_status();
  r.series = rec.series();
  r.rate = rec.rate();
  r.lb_policy = fleet.lb_policy();
  r.resilient = o.resilient;
  r.reconnect_timeout_s = o.reconnect_timeout.count() / 1e9;
  r.replicas_at_start = fleet.replicas_at_start();
  r.addresses_answering = fleet.replicas_answering();
  r.streams_detail = fleet.streams();
  for (const auto& [name, n] : r.per_instance) r.replicas[name].frames = n;
  for (const StreamStats& s : r.streams_detail) {
    std::set<std::string> on(s.replicas.begin(), s.replicas.end());
    for (const std::string& name : on) ++r.replicas[name].streams;
    if (!s.replicas.empty()) ++r.replicas[s.replicas.front()].streams_at_start;
    r.reconnect_ns.insert(r.reconnect_ns.end(), s.reconnect_ns.begin(), s.reconnect_ns.end());
  }
  std::sort(r.reconnect_ns.begin(), r.reconnect_ns.end());
  return r;
}

std::string FormatTable(const Report& r) {
  const Totals& t = r.totals;
  std::string out;
  out += fmt::format("cloudcast-load: {} streams over {} connections to {}\n", r.streams,
                     r.connections, r.target);
  out += fmt::format("  schedule  {}, {}\n", r.schedule, r.delivery);
  out += fmt::format("  frames    {}\n", r.frames);
  out += fmt::format("  ended     {} after {:.2f} s (last frame sent at {:.2f} s)\n",
                     Name(r.result.end_reason), r.result.elapsed_s, r.result.sending_s);
  out += fmt::format(
      "\n  sent {}  answered {}  frame errors {}  lost {}  unsent {}  dropped {} (server says "
      "{})\n",
      t.sent, t.answered, t.frame_errors, t.lost, t.unsent, t.drops, t.server_dropped);
  out += fmt::format("  late sends {} (previous write not done {}, generator behind {})\n",
                     t.late(), t.late_flow_control, t.late_scheduler);
  out +=
      fmt::format("  balancing {}{}\n", r.lb_policy,
                  r.replicas_at_start.empty()
                      ? std::string()
                      : fmt::format(", {} addresses answering at the start ({})",
                                    r.addresses_answering, fmt::join(r.replicas_at_start, ", ")));
  if (r.resilient) {
    out += fmt::format(
        "  resilient: resent {}  duplicates {}  reconnects {} of {} attempts (ms p50 {:.1f}, max "
        "{:.1f})  streams given up {} (--reconnect-timeout {:g} s)\n",
        t.resent, t.duplicates, t.reconnects, t.reconnect_attempts,
        Ms(PercentileOf(r.reconnect_ns, 50)),
        Ms(r.reconnect_ns.empty() ? 0 : r.reconnect_ns.back()), t.streams_given_up,
        r.reconnect_timeout_s);
  }
  out += fmt::format("  throughput {:.1f} frames/s answered, {:.1f} MB/s up, {:.2f} MB/s down\n",
                     r.answered_fps(),
                     r.result.elapsed_s > 0 ? t.bytes_sent / 1e6 / r.result.elapsed_s : 0.0,
                     r.result.elapsed_s > 0 ? t.bytes_received / 1e6 / r.result.elapsed_s : 0.0);
  out += fmt::format(
      "  encoding  {}, {:.1f} KB sent a frame; generator CPU {:.2f} s ({:.3f} ms a frame)\n",
      r.encoding.empty() ? "?" : r.encoding, r.bytes_per_frame() / 1024, r.result.cpu_s,
      r.generator_ms_per_frame());
  if (t.answered > 0) {
    out += fmt::format("  downlink  Draco colour bits {} (median of the clouds), {} over the cap\n",
                       t.color_bits_median(), t.over_cap);
  }
  if (r.live_video) {
    out += fmt::format(
        "  video     {}, encoded live per stream: {} frames, {:.1f} KB of pictures a frame, "
        "encoder CPU {:.2f} ms a frame median ({:.2f} p99); {} IDRs ({} asked for)\n",
        *r.live_video, t.live_encoded, r.live_picture_bytes_per_frame() / 1024,
        r.live_encode_us.Percentile(50) / 1e3, r.live_encode_us.Percentile(99) / 1e3,
        t.keyframes_sent, t.keyframe_restarts);
  }
  if (r.near_lossless) {
    const NearLosslessSummary& n = *r.near_lossless;
    out += fmt::format(
        "  bound     {}; {:.1f} KB a request (lossless {:.1f} KB)\n", Describe(n),
        n.request_bytes / 1024, n.request_bytes_lossless / 1024);
  }
  if (r.video) {
    out += fmt::format(
        "  video     IDRs sent {} ({} asked for)  replies asking for an IDR {}  skipped before "
        "encoding {}\n",
        t.keyframes_sent, t.keyframe_restarts, t.keyframe_needed, t.skipped);
  }
  out += "\n  ms                         p50       p90       p99     p99.9       max      mean\n";
  auto row = [&](const char* name, const Histogram& h) {
    out += fmt::format("  {:<22} {:>9.2f} {:>9.2f} {:>9.2f} {:>9.2f} {:>9.2f} {:>9.2f}\n", name,
                       Ms(h.Percentile(50)), Ms(h.Percentile(90)), Ms(h.Percentile(99)),
                       Ms(h.Percentile(99.9)), Ms(h.max()), h.mean() / 1e6);
  };
  row("latency (intended)", r.latency);
  row("service time", r.service);
  if (!r.replicas.empty()) {
    out += "\n  per replica (server_instance)   streams  at start     frames   share\n";
    std::uint64_t sum = 0;
    for (const auto& [name, rep] : r.replicas) sum += rep.frames;
    for (const auto& [name, rep] : r.replicas) {
      out += fmt::format("    {:<28} {:>8} {:>9} {:>10} {:>6.1f}%\n", name, rep.streams,
                         rep.streams_at_start, rep.frames, sum ? 100.0 * rep.frames / sum : 0.0);
    }
  }
  // Per stream: all of them for a small fleet; for a large one, those that reconnected.
  constexpr std::size_t kAllStreamsUpTo = 64, kMaxRows = 64;
  std::vector<const StreamStats*> rows;
  for (const StreamStats& s : r.streams_detail) {
    if (r.streams_detail.size() <= kAllStreamsUpTo || s.reconnect_attempts > 0 || s.gave_up) {
      if (rows.size() < kMaxRows) rows.push_back(&s);
    }
  }
  if (!rows.empty()) {
    out += fmt::format("\n  per stream{}:\n",
                       r.streams_detail.size() <= kAllStreamsUpTo
                           ? ""
                           : fmt::format(" (those that reconnected, at most {})", kMaxRows));
    out +=
        "    stream    sent  answered  resent  lost  errors  dropped  reconnects  reconnect ms"
        "  replicas\n";
    for (const StreamStats* s : rows) {
      out +=
          fmt::format("    {:>6} {:>7} {:>9} {:>7} {:>5} {:>7} {:>8} {:>7}/{:<3}  {:<12}  {}{}\n",
                      s->index, s->sent, s->answered, s->resent, s->lost, s->frame_errors,
                      s->dropped, s->reconnect_ns.size(), s->reconnect_attempts,
                      Millis(s->reconnect_ns), Path(s->replicas), s->gave_up ? "  (gave up)" : "");
    }
  }
  if (!r.errors.empty()) {
    out += "\n  errors:\n";
    for (const auto& [message, n] : r.errors) out += fmt::format("    {:>7}  {}\n", n, message);
  }
  out += "  calls:";
  for (const auto& [code, n] : r.call_status) out += fmt::format(" {} {}", code, n);
  out += "\n";
  if (!r.memory.empty()) {
    out += fmt::format("\n  server memory (RSS, {}):\n       s        MB\n", r.memory_url);
    for (const MemorySample& m : r.memory) {
      if (m.rss_bytes == 0) {
        out += fmt::format("    {:5.0f}   failed: {}\n", m.t_s, m.error);
      } else {
        out += fmt::format("    {:5.0f}  {:8.1f}\n", m.t_s, m.rss_bytes / 1e6);
      }
    }
  }
  if (r.soak) {
    const SoakVerdict& v = r.soak_verdict;
    out += fmt::format(
        "\n  soak {}: after the {:g} s warm-up memory {:.1f} -> peak {:.1f} MB (bound +{:.1f} "
        "MB); {} of {} frames answered\n",
        v.passed ? "PASSED" : "FAILED", r.soak_bounds.warmup_s, v.baseline_bytes / 1e6,
        v.peak_bytes / 1e6, r.soak_bounds.max_growth_bytes / 1e6, t.answered, t.sent);
    for (const std::string& f : v.failures) out += "    " + f + "\n";
  }
  return out;
}

nlohmann::json GhzJson(const Report& r) {
  using nlohmann::json;
  const Totals& t = r.totals;
  const Histogram& h = r.latency;
  json j;
  j["date"] = Rfc3339(r.result.start);
  j["endReason"] = Name(r.result.end_reason);
  j["options"] = r.options;
  // ghz's fields: count of frames (not calls), latencies from the intended send time.
  j["count"] = t.sent;
  j["total"] = static_cast<std::int64_t>(r.result.elapsed_s * 1e9);
  j["average"] = static_cast<std::int64_t>(h.mean());
  j["fastest"] = h.min();
  j["slowest"] = h.max();
  j["rps"] = r.answered_fps();
  json distribution = json::array();
  for (double p : {10.0, 25.0, 50.0, 75.0, 90.0, 95.0, 99.0, 99.9}) {
    distribution.push_back({{"percentage", p}, {"latency", h.Percentile(p)}});
  }
  j["latencyDistribution"] = distribution;
  // ghz's histogram: 11 marks evenly spaced from fastest to slowest, in seconds.
  json buckets = json::array();
  if (h.count() > 0) {
    const int kBuckets = 10;
    const double lo = static_cast<double>(h.min()), hi = static_cast<double>(h.max());
    const double width = (hi - lo) / kBuckets;
    std::vector<std::int64_t> bounds;
    for (int i = 0; i <= kBuckets; ++i) bounds.push_back(static_cast<std::int64_t>(lo + width * i));
    bounds.push_back(h.max() + 1);
    std::vector<std::uint64_t> counts = h.CountBetween(bounds);
    for (std::size_t i = 0; i < counts.size(); ++i) {
      buckets.push_back({{"mark", bounds[i] / 1e9},
                         {"count", counts[i]},
                         {"frequency", static_cast<double>(counts[i]) / h.count()}});
    }
  }
  j["histogram"] = buckets;
  j["statusCodeDistribution"] = r.status_codes;
  j["errorDistribution"] = r.errors;
  j["details"] = json::array();  // per-frame details are not kept; see timeSeries

  // What ghz cannot give: per-frame figures.
  j["intendedLatency"] = Percentiles(r.latency);
  j["serviceTime"] = Percentiles(r.service);
  j["frames"] = {{"sent", t.sent},
                 {"answered", t.answered},
                 {"frameErrors", t.frame_errors},
                 {"lost", t.lost},
                 {"unsent", t.unsent},
                 {"replaced", t.replaced},
                 {"dropped", t.drops},
                 {"serverReportedDropped", t.server_dropped},
                 {"resent", t.resent},
                 {"duplicates", t.duplicates},
                 {"bytesSent", t.bytes_sent},
                 {"bytesReceived", t.bytes_received}};
  j["frames"]["skipped"] = t.skipped;
  j["frames"]["bytesPerFrame"] = r.bytes_per_frame();
  j["encoding"] = {{"name", r.encoding}, {"bytesPerFrame", r.bytes_per_frame()}};
  if (r.video) {
    j["encoding"]["video"] = {{"codec", "h264"},
                              {"settings", r.video->settings},
                              {"sequenceFrames", r.video->length},
                              {"sourceFrames", r.video->source_frames},
                              {"pictureBytesPerFrame", r.video->video_bytes_mean},
                              {"encodeMsPerFrameMedian", r.video->encode_ms_median},
                              {"encodeMsPerFrameMean", r.video->encode_ms_mean},
                              {"keyframesSent", t.keyframes_sent},
                              {"keyframesAskedFor", t.keyframe_restarts},
                              {"repliesAskingForKeyframe", t.keyframe_needed},
                              {"skippedBeforeEncoding", t.skipped}};
  }
  if (r.live_video) {
    j["encoding"]["video"] = {{"codec", "h264"},
                              {"live", true},
                              {"settings", *r.live_video},
                              {"encodedFrames", t.live_encoded},
                              {"pictureBytesPerFrame", r.live_picture_bytes_per_frame()},
                              {"encodeMsPerFrameMedian", r.live_encode_us.Percentile(50) / 1e3},
                              {"encodeMsPerFrameP99", r.live_encode_us.Percentile(99) / 1e3},
                              {"keyframesSent", t.keyframes_sent},
                              {"keyframesAskedFor", t.keyframe_restarts},
                              {"repliesAskingForKeyframe", t.keyframe_needed}};
  }
  if (r.near_lossless) {
    const NearLosslessSummary& n = *r.near_lossless;
    j["encoding"]["nearLossless"] = {{"maxPointErrorM", n.max_point_error},
                                     {"geometry", n.geometry},
                                     {"geometryBytesPerFrame", n.geometry_bytes},
                                     {"geometryBytesPerFrameLossless", n.geometry_bytes_lossless},
                                     {"requestBytesPerFrame", n.request_bytes},
                                     {"requestBytesPerFrameLossless", n.request_bytes_lossless},
                                     {"halfGeometryBytesPerFrame", n.half_geometry_bytes},
                                     {"halfGeometryBytesPerFrameLossless",
                                      n.half_geometry_bytes_lossless},
                                     {"valuesValid", n.values},
                                     {"valuesChanged", n.changed}};
  }
  json color_bits = json::object();
  for (const auto& [bits, clouds] : t.color_bits) color_bits[std::to_string(bits)] = clouds;
  j["downlink"] = {{"colorBitsMedian", t.color_bits_median()},
                   {"colorBits", color_bits},
                   {"overCap", t.over_cap}};
  j["generator"] = {{"cpuSeconds", r.result.cpu_s},
                    {"cpuMsPerFrameSent", r.generator_ms_per_frame()}};
  j["drops"] = t.drops;
  j["lateSends"] = {{"total", t.late()},
                    {"previousWriteNotDone", t.late_flow_control},
                    {"generatorBehind", t.late_scheduler}};
  j["framesPerReplica"] = r.per_instance;
  json replicas = json::object();
  for (const auto& [name, rep] : r.replicas) {
    replicas[name] = {
        {"streams", rep.streams}, {"streamsAtStart", rep.streams_at_start}, {"frames", rep.frames}};
  }
  j["replicas"] = replicas;
  j["loadBalancing"] = {{"policy", r.lb_policy},
                        {"replicasAtStart", r.replicas_at_start},
                        {"addressesAnsweringAtStart", r.addresses_answering}};
  j["resilience"] = {{"enabled", r.resilient},
                     {"reconnectTimeoutSeconds", r.reconnect_timeout_s},
                     {"reconnects", t.reconnects},
                     {"reconnectAttempts", t.reconnect_attempts},
                     {"resent", t.resent},
                     {"duplicates", t.duplicates},
                     {"streamsGivenUp", t.streams_given_up},
                     {"reconnectTime",
                      {{"count", r.reconnect_ns.size()},
                       {"p50", PercentileOf(r.reconnect_ns, 50)},
                       {"p90", PercentileOf(r.reconnect_ns, 90)},
                       {"max", r.reconnect_ns.empty() ? 0 : r.reconnect_ns.back()},
                       {"unit", "ns"}}}};
  json streams = json::array();
  for (const StreamStats& s : r.streams_detail) {
    streams.push_back({{"stream", s.index},
                       {"sent", s.sent},
                       {"answered", s.answered},
                       {"frameErrors", s.frame_errors},
                       {"resent", s.resent},
                       {"lost", s.lost},
                       {"dropped", s.dropped},
                       {"unsent", s.unsent},
                       {"replaced", s.replaced},
                       {"skipped", s.skipped},
                       {"keyframeNeeded", s.keyframe_needed},
                       {"duplicates", s.duplicates},
                       {"calls", s.calls},
                       {"reconnects", s.reconnect_ns.size()},
                       {"reconnectAttempts", s.reconnect_attempts},
                       {"reconnectNs", s.reconnect_ns},
                       {"replicas", s.replicas},
                       {"endStatus", s.end_status},
                       {"gaveUp", s.gave_up}});
  }
  j["streams"] = streams;
  j["callStatusDistribution"] = r.call_status;
  j["sendingSeconds"] = r.result.sending_s;
  json series = json::array();
  for (const SecondStats& s : r.series) {
    series.push_back({{"t", s.t_end_s},
                      {"seconds", s.duration_s},
                      {"sent", s.sent},
                      {"answered", s.answered},
                      {"fps", s.fps()},
                      {"errors", s.errors},
                      {"drops", s.drops},
                      {"late", s.late},
                      {"resent", s.resent},
                      {"reconnects", s.reconnects},
                      {"openStreams", s.open_streams},
                      {"bytesReceived", s.bytes_received},
                      {"p50", s.p50},
                      {"p90", s.p90},
                      {"p99", s.p99},
                      {"max", s.max},
                      {"serviceP50", s.service_p50},
                      {"serviceP99", s.service_p99}});
    if (s.rate.samples > 0) series.back()["rate"] = RateJson(s.rate);
  }
  j["timeSeries"] = series;
  if (r.rate.samples > 0) j["rateControl"] = RateJson(r.rate);
  if (!r.memory.empty()) {
    json memory = json::array();
    for (const MemorySample& m : r.memory) {
      json sample = {{"t", m.t_s}, {"rssBytes", m.rss_bytes}};
      if (!m.error.empty()) sample["error"] = m.error;
      memory.push_back(sample);
    }
    j["serverMemory"] = {{"url", r.memory_url}, {"samples", memory}};
  }
  if (r.soak) {
    j["soak"] = {{"passed", r.soak_verdict.passed},
                 {"warmupSeconds", r.soak_bounds.warmup_s},
                 {"maxGrowthBytes", r.soak_bounds.max_growth_bytes},
                 {"baselineBytes", r.soak_verdict.baseline_bytes},
                 {"peakBytes", r.soak_verdict.peak_bytes},
                 {"failures", r.soak_verdict.failures}};
  }
  return j;
}

std::string ProgressLine(const SecondStats& s, std::uint64_t errors, std::uint64_t drops) {
  std::string line = fmt::format(
      "{:7.1f} s  {:7.1f} frames/s  p50 {:7.2f} ms  p99 {:7.2f} ms  errors {}  drops {}  late {}  "
      "open streams {}",
      s.t_end_s, s.fps(), Ms(s.p50), Ms(s.p99), errors, drops, s.late, s.open_streams);
  if (s.reconnects > 0 || s.resent > 0) {
    line += fmt::format("  reconnects {}  resent {}", s.reconnects, s.resent);
  }
  if (s.rate.samples > 0) {
    line += fmt::format(
        "  target {:.1f} Mbit/s  rtt {:.0f} ms  queueing {:.0f} ms  {:.0f} KB/frame",
        s.rate.target_bps / 1e6, s.rate.rtt_ms, s.rate.queue_delay_ms, s.rate.frame_bytes / 1024);
    if (s.rate.reply_target_bps > 0) {
      line += fmt::format("  replies {:.1f} Mbit/s, cap {:.0f} KB, queueing {:.0f} ms",
                          s.rate.reply_target_bps / 1e6, s.rate.reply_cap_bytes / 1024,
                          s.rate.reply_queue_delay_ms);
    }
  }
  return line;
}

}  // namespace cloudcast::load
