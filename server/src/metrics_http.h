// The /metrics endpoint: a small event-driven HTTP/1.x server on one thread. A connection costs a
// file descriptor and a few hundred bytes, never a thread, so slow or idle clients (or an
// attacker renewing them) cannot keep a Prometheus scrape from being answered. Each connection
// must send its request within `request_timeout` and gets one response, then is closed.
#pragma once

#include <atomic>
#include <chrono>
#include <cstddef>
#include <functional>
#include <memory>
#include <string>
#include <thread>

#include "absl/status/statusor.h"

namespace cloudcast::server {

class MetricsHttpServer {
 public:
  struct Options {
    // host:port; port 0 picks a free one. IPv4 and IPv6 literals, "localhost" and "0.0.0.0" /
    // "[::]".
    std::string listen;
    std::chrono::milliseconds request_timeout{5000};
    // Connections open at once; past it the one idle the longest is closed.
    std::size_t max_connections = 512;
  };

  // Serves GET /metrics with `body()` (Prometheus' text format), called once per scrape on the
  // server's thread. UNAVAILABLE when the address cannot be bound.
  static absl::StatusOr<std::unique_ptr<MetricsHttpServer>> Start(
      const Options& options, std::function<std::string()> body);
  ~MetricsHttpServer();  // stops the thread and closes every connection
  MetricsHttpServer(const MetricsHttpServer&) = delete;
  MetricsHttpServer& operator=(const MetricsHttpServer&) = delete;

  int port() const { return port_; }

 private:
  MetricsHttpServer() = default;
  void Loop();

  Options options_;
  std::function<std::string()> body_;
  int listen_fd_ = -1;
  int wake_fd_[2] = {-1, -1};  // a pipe that wakes the loop to stop
  int port_ = 0;
  std::thread thread_;
};

}  // namespace cloudcast::server
