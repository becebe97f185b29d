// The server's resident memory over a run, read from its Prometheus endpoint every few seconds
// (cloudcast_process_resident_memory_bytes), so a soak sees growth wherever the server runs:
// a process here, a container, a pod behind a port-forward.
//
// And the soak's verdict: a run passes when no frame was lost, left unsent or answered with an
// error (in DELIVERY_ALL: every frame answered), and the memory after the warm-up never rose more
// than a bound above what it was when the warm-up ended.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/load/recorder.h"

namespace cloudcast::load {

struct MemorySample {
  double t_s = 0;               // seconds since the watch started
  std::uint64_t rss_bytes = 0;  // 0 when the scrape failed (then `error` says why)
  std::string error;
};

// The value of `metric` (no labels) in a Prometheus text exposition.
absl::StatusOr<double> MetricValue(const std::string& exposition, const std::string& metric);

class MemoryWatch {
 public:
  // Samples `url` (http://host:port/metrics) now and then every `interval` until Stop().
  MemoryWatch(std::string url, std::chrono::milliseconds interval);
  ~MemoryWatch();  // stops
  MemoryWatch(const MemoryWatch&) = delete;
  MemoryWatch& operator=(const MemoryWatch&) = delete;

  // One scrape, on the caller's thread: how the program checks the URL before a run.
  static absl::StatusOr<std::uint64_t> Scrape(const std::string& url);

  void Stop();  // takes a last sample
  std::vector<MemorySample> samples() const;

 private:
  void Run();
  void SampleNow();

  const std::string url_;
  const std::chrono::milliseconds interval_;
  const std::chrono::steady_clock::time_point start_;
  mutable std::mutex mu_;
  std::condition_variable wake_;
  bool stop_ = false;
  std::vector<MemorySample> samples_;
  std::thread thread_;
};

struct SoakBounds {
  double warmup_s = 15;              // growth counts from the last sample at or before this
  double max_growth_bytes = 64e6;    // allowed rise above that baseline
  bool lossless = true;              // DELIVERY_ALL: every frame sent must be answered
};

struct SoakVerdict {
  bool passed = false;
  std::uint64_t baseline_bytes = 0, peak_bytes = 0;  // after the warm-up
  std::vector<std::string> failures;                 // each says what and by how much
};

SoakVerdict JudgeSoak(const std::vector<MemorySample>& samples, const Totals& totals,
                      const SoakBounds& bounds);

}  // namespace cloudcast::load
