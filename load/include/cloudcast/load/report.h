// A load run's report, and its three renderings: a table for the terminal, ghz's JSON report
// shape (so ghz tooling reads it) with the per-frame figures ghz cannot give in extra fields, and
// a self-contained HTML page with SVG charts (no scripts, no fonts, nothing from the network).
#pragma once

#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "cloudcast/load/fleet.h"
#include "cloudcast/load/histogram.h"
#include "cloudcast/load/memory_watch.h"
#include "cloudcast/load/recorder.h"

namespace cloudcast::load {

struct Report {
  // What ran.
  std::string target;
  std::string frames;    // FrameStore::description()
  std::string encoding;  // FrameStore::encoding(): raw, zstd, png, jpeg, h264, adaptive
  std::optional<VideoSequence> video;  // --encoding h264: the picture sequence the streams sent
  // --encoding h264 --rate-control: the settings of the encoder each stream ran live.
  std::optional<std::string> live_video;
  // --max-point-error: what the bound saved (FrameStore::near_lossless()).
  std::optional<NearLosslessSummary> near_lossless;
  std::string schedule;  // e.g. "const 30 fps per stream" or "closed loop, 2 in flight"
  std::string delivery;  // "DELIVERY_ALL" / "DELIVERY_LATEST"
  int streams = 0, connections = 0;
  nlohmann::json options;  // echoed as ghz's "options"
  // How it went.
  FleetResult result;
  Totals totals;
  Histogram latency, service;
  Histogram live_encode_us;  // --encoding h264 --rate-control: the encoder's CPU time a frame
  std::map<std::string, std::uint64_t> per_instance, status_codes, errors, call_status;
  std::vector<SecondStats> series;
  RateSummary rate;  // --rate-control: the controllers over the run (samples 0: none)
  // Resilience and spread: the channels' policy, each stream's account, and per replica.
  std::string lb_policy;
  bool resilient = false;
  double reconnect_timeout_s = 0;
  std::vector<std::string> replicas_at_start;  // answered GetInfo before the streams opened
  int addresses_answering = 0;                 // distinct addresses that answered then
  std::vector<StreamStats> streams_detail;
  struct Replica {
    int streams = 0;           // streams that one of its calls answered
    int streams_at_start = 0;  // streams whose first call it answered
    std::uint64_t frames = 0;  // replies (clouds and frame errors) it sent
  };
  std::map<std::string, Replica> replicas;
  std::vector<std::int64_t> reconnect_ns;  // every stream's reconnect times, sorted
  // The server's memory (--watch-memory) and, for a soak (--soak), its verdict.
  std::string memory_url;
  std::vector<MemorySample> memory;
  bool soak = false;
  SoakBounds soak_bounds;
  SoakVerdict soak_verdict;

  // The request bytes a frame sent, mean (image bytes and the message around them).
  double bytes_per_frame() const {
    return totals.sent + totals.resent > 0
               ? static_cast<double>(totals.bytes_sent) / (totals.sent + totals.resent)
               : 0;
  }
  // The generator's CPU ms per frame sent, and the streams at `fps` one of its cores could drive
  // at that cost (0 when nothing was sent).
  double generator_ms_per_frame() const {
    return totals.sent > 0 ? result.cpu_s * 1e3 / static_cast<double>(totals.sent) : 0;
  }
  // Live video: the pictures' bytes a frame encoded (0 when none was).
  double live_picture_bytes_per_frame() const {
    return totals.live_encoded > 0
               ? static_cast<double>(totals.live_picture_bytes) / totals.live_encoded
               : 0;
  }
  double answered_fps() const {
    return result.elapsed_s > 0 ? totals.answered / result.elapsed_s : 0;
  }
};

// Gathers the figures of a finished run.
Report MakeReport(Fleet& fleet, const FleetResult& result, const std::string& frames,
                  const std::string& schedule, nlohmann::json options);

// The p-th percentile (0-100, nearest rank) of sorted values; 0 when empty.
std::int64_t PercentileOf(const std::vector<std::int64_t>& sorted, double p);

// The percentiles every rendering shows.
const std::vector<double>& ReportPercentiles();  // 50, 90, 99, 99.9

std::string FormatTable(const Report& report);
nlohmann::json GhzJson(const Report& report);
std::string Html(const Report& report);

// The per-second line printed while a run goes on.
std::string ProgressLine(const SecondStats& s, std::uint64_t errors_so_far,
                         std::uint64_t drops_so_far);

}  // namespace cloudcast::load
