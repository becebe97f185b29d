#include "metrics.h"

#include <sys/resource.h>
#include <unistd.h>

#include <cstdint>
#include <fstream>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "prometheus/collectable.h"
#include "prometheus/metric_family.h"
#include "prometheus/text_serializer.h"

namespace cloudcast::server {
namespace {

prometheus::Counter& NewCounter(prometheus::Registry& r, const std::string& name,
                                const std::string& help) {
  return prometheus::BuildCounter().Name(name).Help(help).Register(r).Add({});
}

// 50 us .. ~3.3 s in factors of 2: a 640x480 frame's stages sit around 0.3 .. 10 ms.
prometheus::Histogram::BucketBoundaries LatencyBuckets() {
  prometheus::Histogram::BucketBoundaries b;
  for (double v = 50e-6; v < 4.0; v *= 2) b.push_back(v);
  return b;
}

prometheus::Histogram& StageHistogram(prometheus::Family<prometheus::Histogram>& family,
                                      const std::string& stage) {
  return family.Add({{"stage", stage}}, LatencyBuckets());
}

// The process' user + system CPU time and its resident memory, read when scraped
// (prometheus-cpp has no process collector of its own). A soak watches the memory for growth.
class ProcessCollectable : public prometheus::Collectable {
 public:
  std::vector<prometheus::MetricFamily> Collect() const override {
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    auto seconds = [](const timeval& t) { return t.tv_sec + t.tv_usec * 1e-6; };
    std::vector<prometheus::MetricFamily> families(2);
    families[0].name = "cloudcast_process_cpu_seconds_total";
    families[0].help = "User and system CPU time of the whole server process";
    families[0].type = prometheus::MetricType::Counter;
    prometheus::ClientMetric cpu;
    cpu.counter.value = seconds(usage.ru_utime) + seconds(usage.ru_stime);
    families[0].metric.push_back(cpu);
    families[1].name = "cloudcast_process_resident_memory_bytes";
    families[1].help = "Resident memory of the server process (/proc/self/statm)";
    families[1].type = prometheus::MetricType::Gauge;
    prometheus::ClientMetric rss;
    rss.gauge.value = static_cast<double>(ResidentBytes());
    families[1].metric.push_back(rss);
    return families;
  }

 private:
  static std::uint64_t ResidentBytes() {
    std::ifstream statm("/proc/self/statm");
    std::uint64_t size_pages = 0, resident_pages = 0;
    statm >> size_pages >> resident_pages;
    return resident_pages * static_cast<std::uint64_t>(sysconf(_SC_PAGESIZE));
  }
};

}  // namespace

Metrics::Metrics()
    : registry_(std::make_shared<prometheus::Registry>()),
      process_(std::make_shared<ProcessCollectable>()),
      frame_errors_family_(prometheus::BuildCounter()
                               .Name("cloudcast_frame_errors_total")
                               .Help("Frames and configs answered with a FrameError (or a Process "
                                     "error status), by status code")
                               .Register(*registry_)),
      frames_processed(NewCounter(*registry_, "cloudcast_frames_processed_total",
                                  "Frames turned into a cloud and answered")),
      frames_dropped(NewCounter(*registry_, "cloudcast_frames_dropped_total",
                                "Frames replaced by a newer one before a worker took them "
                                "(DELIVERY_LATEST)")),
      bytes_received(NewCounter(*registry_, "cloudcast_bytes_received_total",
                                "Serialized size of the requests read")),
      bytes_sent(NewCounter(*registry_, "cloudcast_bytes_sent_total",
                            "Serialized size of the replies written")),
      replies_over_cap(NewCounter(*registry_, "cloudcast_replies_over_cap_total",
                                  "Clouds sent over the client's cap (max_cloud_bytes) at the "
                                  "floors of its bounds")),
      replies_voxels_dropped(NewCounter(*registry_, "cloudcast_replies_voxels_dropped_total",
                                        "Clouds the client's cap thinned by raising the voxel "
                                        "minimum (cap_min_points_per_voxel)")),
      active_streams(prometheus::BuildGauge()
                         .Name("cloudcast_active_streams")
                         .Help("Stream calls open now")
                         .Register(*registry_)
                         .Add({})),
      streams_accepted(
          NewCounter(*registry_, "cloudcast_streams_accepted_total", "Stream calls accepted")),
      streams_rejected_limit(NewCounter(*registry_, "cloudcast_streams_rejected_limit_total",
                                        "Stream calls refused: --max-streams reached")),
      streams_rejected_shutdown(NewCounter(*registry_, "cloudcast_streams_rejected_shutdown_total",
                                           "Stream calls refused: shutting down")),
      process_rejected_limit(NewCounter(*registry_, "cloudcast_process_rejected_limit_total",
                                        "Process calls refused: the server's or the client's "
                                        "limit of Process calls in flight reached")),
      process_rejected_shutdown(NewCounter(*registry_, "cloudcast_process_rejected_shutdown_total",
                                           "Process calls refused: shutting down")),
      streams_idle_timeout(NewCounter(*registry_, "cloudcast_streams_idle_timeout_total",
                                      "Stream calls ended by the idle timeout")),
      streams_cancelled(NewCounter(*registry_, "cloudcast_streams_cancelled_total",
                                   "Stream calls the client cancelled")),
      streams_shed(NewCounter(*registry_, "cloudcast_streams_shed_total",
                              "Quiet Stream calls ended to make room for a new client while the "
                              "server was full (--shed-quiet-after)")),
      log_lines_suppressed(NewCounter(*registry_, "cloudcast_log_lines_suppressed_total",
                                      "Per-call log lines left out by the log rate limit")),
      calls_unauthenticated(NewCounter(*registry_, "cloudcast_calls_unauthenticated_total",
                                       "Calls refused for a missing or invalid bearer token")),
      unparsable_family_(prometheus::BuildCounter()
                             .Name("cloudcast_requests_unparsable_total")
                             .Help("Requests whose bytes did not parse as their RPC's message; "
                                   "the call ends with INVALID_ARGUMENT")
                             .Register(*registry_)),
      stream_requests_unparsable(unparsable_family_.Add({{"method", "Stream"}})),
      process_requests_unparsable(unparsable_family_.Add({{"method", "Process"}})),
      refused_family_(prometheus::BuildCounter()
                          .Name("cloudcast_frames_refused_total")
                          .Help("Frames refused for memory before anything was decoded, by the "
                                "limit: memory_budget (frames held, --memory-budget-mb) or "
                                "work_memory (more than --work-memory-mb to process)")
                          .Register(*registry_)),
      frames_refused_memory_budget(refused_family_.Add({{"limit", "memory_budget"}})),
      frames_refused_work_memory(refused_family_.Add({{"limit", "work_memory"}})),
      stage_family_(prometheus::BuildHistogram()
                        .Name("cloudcast_stage_seconds")
                        .Help("Time per frame in each stage: decode (PNG/JPEG, frames that had "
                              "any), pipeline, encode (Draco), match (stereo pairs: rectification, "
                              "grey and the "
                              "matcher), queue (received -> a worker "
                              "starts), total (received -> reply handed to gRPC)")
                        .Register(*registry_)),
      decode_seconds(StageHistogram(stage_family_, "decode")),
      pipeline_seconds(StageHistogram(stage_family_, "pipeline")),
      encode_seconds(StageHistogram(stage_family_, "encode")),
      match_seconds(StageHistogram(stage_family_, "match")),
      queue_seconds(StageHistogram(stage_family_, "queue")),
      total_seconds(StageHistogram(stage_family_, "total")),
      core_cpu_seconds(NewCounter(*registry_, "cloudcast_core_cpu_seconds_total",
                                  "Worker thread CPU time inside the core pipeline and Draco "
                                  "encoding")),
      worker_cpu_seconds(NewCounter(*registry_, "cloudcast_worker_cpu_seconds_total",
                                    "Worker thread CPU time per frame task, all of it (decode, "
                                    "checks, pipeline, Draco, reply)")) {}

prometheus::Counter& Metrics::FrameErrors(absl::StatusCode code) {
  // Family::Add returns the existing counter for known labels; errors are rare enough for its
  // lock.
  return frame_errors_family_.Add({{"code", absl::StatusCodeToString(code)}});
}

std::string Metrics::Serialize() const {
  std::vector<prometheus::MetricFamily> families = registry_->Collect();
  for (auto& f : process_->Collect()) families.push_back(std::move(f));
  return prometheus::TextSerializer().Serialize(families);
}

}  // namespace cloudcast::server
