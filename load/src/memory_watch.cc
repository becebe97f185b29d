#include "cloudcast/load/memory_watch.h"

#include <curl/curl.h>
#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <sstream>

namespace cloudcast::load {
namespace {

constexpr char kRssMetric[] = "cloudcast_process_resident_memory_bytes";

std::size_t Append(char* data, std::size_t size, std::size_t count, void* out) {
  static_cast<std::string*>(out)->append(data, size * count);
  return size * count;
}

// libcurl's global state, set up once before any thread uses it.
void InitCurlOnce() {
  static const bool done = [] {
    curl_global_init(CURL_GLOBAL_DEFAULT);
    return true;
  }();
  (void)done;
}

double Mb(double bytes) { return bytes / 1e6; }

}  // namespace

absl::StatusOr<double> MetricValue(const std::string& exposition, const std::string& metric) {
  std::istringstream lines(exposition);
  std::string line;
  while (std::getline(lines, line)) {
    if (line.empty() || line[0] == '#') continue;
    // "name value" or "name{labels} value": only the unlabelled sample counts.
    if (line.compare(0, metric.size(), metric) != 0 || line.size() <= metric.size() ||
        line[metric.size()] != ' ') {
      continue;
    }
    char* end = nullptr;
    const double v = std::strtod(line.c_str() + metric.size() + 1, &end);
    if (end == line.c_str() + metric.size() + 1 || !std::isfinite(v)) {
      return absl::InvalidArgumentError(fmt::format("'{}' has no number: {}", metric, line));
    }
    return v;
  }
  return absl::NotFoundError(fmt::format("no '{}' in the exposition", metric));
}

absl::StatusOr<std::uint64_t> MemoryWatch::Scrape(const std::string& url) {
  InitCurlOnce();
  CURL* curl = curl_easy_init();
  if (curl == nullptr) return absl::InternalError("curl_easy_init failed");
  std::string body;
  curl_easy_setopt(curl, CURLOPT_URL, url.c_str());
  curl_easy_setopt(curl, CURLOPT_WRITEFUNCTION, Append);
  curl_easy_setopt(curl, CURLOPT_WRITEDATA, &body);
  curl_easy_setopt(curl, CURLOPT_TIMEOUT_MS, 3000L);
  curl_easy_setopt(curl, CURLOPT_NOSIGNAL, 1L);  // timeouts without SIGALRM, from any thread
  curl_easy_setopt(curl, CURLOPT_PROTOCOLS_STR, "http,https");
  const CURLcode rc = curl_easy_perform(curl);
  long http_code = 0;
  curl_easy_getinfo(curl, CURLINFO_RESPONSE_CODE, &http_code);
  curl_easy_cleanup(curl);
  if (rc != CURLE_OK) {
    return absl::UnavailableError(fmt::format("{}: {}", url, curl_easy_strerror(rc)));
  }
  if (http_code != 200) {
    return absl::UnavailableError(fmt::format("{}: HTTP {}", url, http_code));
  }
  auto v = MetricValue(body, kRssMetric);
  if (!v.ok()) return absl::NotFoundError(fmt::format("{}: {}", url, std::string(v.status().message())));
  return static_cast<std::uint64_t>(*v);
}

MemoryWatch::MemoryWatch(std::string url, std::chrono::milliseconds interval)
    : url_(std::move(url)), interval_(interval), start_(std::chrono::steady_clock::now()) {
  thread_ = std::thread([this] { Run(); });
}

MemoryWatch::~MemoryWatch() { Stop(); }

void MemoryWatch::Stop() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stop_) return;
    stop_ = true;
  }
  wake_.notify_all();
  thread_.join();
  SampleNow();
}

std::vector<MemorySample> MemoryWatch::samples() const {
  std::lock_guard<std::mutex> lock(mu_);
  return samples_;
}

void MemoryWatch::SampleNow() {
  MemorySample s;
  auto rss = Scrape(url_);
  s.t_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  if (rss.ok()) {
    s.rss_bytes = *rss;
  } else {
    s.error = std::string(rss.status().message());
  }
  std::lock_guard<std::mutex> lock(mu_);
  samples_.push_back(std::move(s));
}

void MemoryWatch::Run() {
  // Samples on a fixed grid (start + k * interval), so a slow scrape does not shift the rest.
  std::chrono::steady_clock::time_point next = start_;
  while (true) {
    SampleNow();
    next += interval_;
    std::unique_lock<std::mutex> lock(mu_);
    if (wake_.wait_until(lock, next, [this] { return stop_; })) return;
  }
}

SoakVerdict JudgeSoak(const std::vector<MemorySample>& samples, const Totals& totals,
                      const SoakBounds& bounds) {
  SoakVerdict v;
  if (totals.lost + totals.unsent > 0) {
    v.failures.push_back(fmt::format("{} frames lost and {} unsent of {} due", totals.lost,
                                     totals.unsent, totals.sent + totals.unsent));
  }
  if (totals.frame_errors > 0) {
    v.failures.push_back(fmt::format("{} frames answered with an error", totals.frame_errors));
  }
  // DELIVERY_LATEST may skip stale frames (drops); DELIVERY_ALL answers every one.
  if (bounds.lossless && totals.answered != totals.sent) {
    v.failures.push_back(fmt::format("{} frames sent, {} answered", totals.sent, totals.answered));
  }
  std::size_t failed_scrapes = 0;
  bool have_baseline = false, after_warmup = false;
  for (const MemorySample& s : samples) {
    if (s.rss_bytes == 0) {
      ++failed_scrapes;
      continue;
    }
    if (s.t_s <= bounds.warmup_s || !have_baseline) {
      v.baseline_bytes = s.rss_bytes;  // the last sample of the warm-up
      have_baseline = true;
      if (s.t_s <= bounds.warmup_s) continue;
    }
    after_warmup = true;
    v.peak_bytes = std::max(v.peak_bytes, s.rss_bytes);
  }
  if (failed_scrapes > 0) {
    v.failures.push_back(fmt::format("{} of {} memory samples failed", failed_scrapes,
                                     samples.size()));
  }
  if (!after_warmup) {
    v.failures.push_back(fmt::format("no memory sample after the {:g} s warm-up",
                                     bounds.warmup_s));
  } else if (v.peak_bytes > v.baseline_bytes + bounds.max_growth_bytes) {
    v.failures.push_back(fmt::format(
        "server memory grew {:.1f} MB after the warm-up ({:.1f} -> {:.1f} MB), over the {:.1f} MB "
        "bound",
        Mb(v.peak_bytes - v.baseline_bytes), Mb(v.baseline_bytes), Mb(v.peak_bytes),
        Mb(bounds.max_growth_bytes)));
  }
  v.passed = v.failures.empty();
  return v;
}

}  // namespace cloudcast::load
