#include "cloudcast/server/options.h"

#include <arpa/inet.h>
#include <unistd.h>

#include <algorithm>
#include <limits>
#include <thread>

#include "absl/strings/str_cat.h"

namespace cloudcast::server {
namespace {

absl::Status Invalid(const std::string& message) { return absl::InvalidArgumentError(message); }

}  // namespace

absl::Status ServerOptions::Validate() const {
  if (listen.empty()) return Invalid("--listen must not be empty");
  if (threads < 0 || threads > 1024) {
    return Invalid(absl::StrCat("--threads is ", threads, "; it must be in [0, 1024]"));
  }
  if (max_message_bytes < 1024 || max_message_bytes > (std::uint64_t{1} << 31) - 1) {
    // gRPC takes an int.
    return Invalid(absl::StrCat("--max-message-bytes is ", max_message_bytes,
                                "; it must be in [1024, 2^31 - 1]"));
  }
  if (limits.max_side == 0) return Invalid("--max-side must be at least 1");
  if (limits.max_pixels == 0 || limits.max_pixels > (std::uint64_t{1} << 24)) {
    // Beyond 2^24 pixels the core's per-voxel colour sums could overflow (core/limits.h).
    return Invalid(absl::StrCat("--max-pixels is ", limits.max_pixels,
                                "; it must be in [1, 2^24 = 16777216]"));
  }
  // The matcher's volume: at least one 16-disparity row, at most what stereo/ will allocate.
  if (limits.max_stereo_volume < 16 || limits.max_stereo_volume > (std::uint64_t{1} << 30)) {
    return Invalid(absl::StrCat("--max-stereo-volume is ", limits.max_stereo_volume,
                                "; it must be in [16, 2^30 = 1073741824]"));
  }
  if (max_streams == 0) return Invalid("--max-streams must be at least 1");
  if (idle_timeout.count() <= 0) return Invalid("--idle-timeout must be positive");
  if (first_message_timeout.count() <= 0) {
    return Invalid("--first-message-timeout must be positive");
  }
  if (max_queued_frames == 0 || max_queued_frames > 1024) {
    return Invalid(
        absl::StrCat("--max-queued-frames is ", max_queued_frames, "; it must be in [1, 1024]"));
  }
  if (shutdown_grace.count() < 0) return Invalid("--shutdown-grace must not be negative");
  if (memory_budget_bytes < (std::uint64_t{1} << 20)) {
    return Invalid("--memory-budget-mb must be at least 1");
  }
  if (work_memory_bytes < (std::uint64_t{16} << 20)) {
    return Invalid("--work-memory-mb must be at least 16");
  }
  if (refusal_delay.count() < 0 || refusal_delay > std::chrono::minutes(1)) {
    return Invalid("--refusal-delay must be in [0, 60] seconds");
  }
  if (large_frame_pixels == 0) return Invalid("--large-frame-pixels must be at least 1");
  if (shed_quiet_after.count() < 0) return Invalid("--shed-quiet-after must not be negative");
  for (const std::string& proxy : trusted_proxies) {
    in6_addr v6{};
    in_addr v4{};
    if (inet_pton(AF_INET, proxy.c_str(), &v4) != 1 &&
        inet_pton(AF_INET6, proxy.c_str(), &v6) != 1) {
      return Invalid(absl::StrCat("--trusted-proxy '", proxy,
                                  "' is not an IP address (e.g. 127.0.0.1 or ::1)"));
    }
  }
  if (http2_max_concurrent_streams == 0) {
    return Invalid("--http2-max-concurrent-streams must be at least 1");
  }
  if (http2_max_metadata_bytes != 0 && http2_max_metadata_bytes < 1024) {
    return Invalid(absl::StrCat("--http2-max-metadata-bytes is ", http2_max_metadata_bytes,
                                "; it must be 0 (gRPC's default) or at least 1024"));
  }
  if (transport_memory_bytes != 0 && transport_memory_bytes < (std::uint64_t{16} << 20)) {
    return Invalid("--transport-memory-mb must be 0 (no quota) or at least 16");
  }
  if (log_calls_per_second == 0) return Invalid("--log-calls-per-second must be at least 1");
  if (stream_window_bytes < 65536 || stream_window_bytes > (1u << 30)) {
    return Invalid(absl::StrCat("--stream-window-bytes is ", stream_window_bytes,
                                "; it must be in [65536, 2^30]"));
  }
  // gRPC takes both as int milliseconds.
  constexpr std::int64_t kMaxMs = std::numeric_limits<int>::max();
  if (max_connection_age.count() < 0 || max_connection_age.count() > kMaxMs) {
    return Invalid("--max-connection-age must be in [0, 2^31 ms)");
  }
  if (max_connection_age_grace.count() < 0 || max_connection_age_grace.count() > kMaxMs) {
    return Invalid("--max-connection-age-grace must be in [0, 2^31 ms)");
  }
  if (ping_after.count() > kMaxMs) return Invalid("--ping-after must be under 2^31 ms");
  if (ping_timeout.count() <= 0 || ping_timeout.count() > kMaxMs) {
    return Invalid("--ping-timeout must be in (0, 2^31 ms)");
  }
  if (tls_cert_file.empty() != tls_key_file.empty()) {
    return Invalid(tls_cert_file.empty()
                       ? "--tls-key needs --tls-cert (the certificate it belongs to)"
                       : "--tls-cert needs --tls-key (its private key)");
  }
  if (!tls_client_ca_file.empty() && tls_cert_file.empty()) {
    return Invalid("--tls-client-ca (mutual TLS) needs --tls-cert and --tls-key");
  }
  if (auto s = defaults.frame.Validate("defaults"); !s.ok()) {
    return Invalid(absl::StrCat("stream defaults: ", s.message()));
  }
  return absl::OkStatus();
}

int ServerOptions::ResolvedThreads() const {
  if (threads > 0) return threads;
  return std::max(1u, std::thread::hardware_concurrency());
}

std::uint32_t ServerOptions::ResolvedMaxStreamsPerClient() const {
  return max_streams_per_client > 0 ? max_streams_per_client : std::max(1u, max_streams / 2);
}

std::uint32_t ServerOptions::ResolvedMaxProcessPerClient() const {
  return max_process_per_client > 0 ? max_process_per_client : std::max(1u, max_streams / 2);
}

std::uint64_t ServerOptions::ResolvedReadingBytesPerClient() const {
  return std::max(reading_bytes_per_client > 0 ? reading_bytes_per_client : 2 * max_message_bytes,
                  max_message_bytes);
}

std::string ServerOptions::ResolvedInstance() const {
  if (!instance.empty()) return instance;
  char host[256] = {};
  if (gethostname(host, sizeof host - 1) != 0 || host[0] == '\0') return "cloudcast";
  return host;
}

StreamSettings ServerOptions::StreamDefaults() const {
  StreamSettings s = defaults;
  s.frame.pipeline.limits = limits;
  return s;
}

}  // namespace cloudcast::server
