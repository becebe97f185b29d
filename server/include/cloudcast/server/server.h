// cloudcast's gRPC server: the CloudCast service, health checking, reflection and the
// Prometheus exporter, built, started and shut down as one object. The cloudcast-server binary
// is a thin main() around it; tests run it in-process on an ephemeral port.
#pragma once

#include <grpcpp/grpcpp.h>

#include <chrono>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <string>

#include "absl/status/statusor.h"
#include "cloudcast/server/options.h"

namespace cloudcast::server {

class CloudCastService;
class Metrics;
class MetricsHttpServer;
class ServerTls;

class Server {
 public:
  // Builds and starts a server on options.listen (port 0: a free port, see port()). Errors:
  // invalid options (INVALID_ARGUMENT, naming the flag), or an address that cannot be bound
  // (UNAVAILABLE), for gRPC or for the metrics exporter.
  static absl::StatusOr<std::unique_ptr<Server>> Start(const ServerOptions& options);

  ~Server();  // Shutdown() if it has not run
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  int port() const { return port_; }
  // options.listen with the bound port, e.g. "127.0.0.1:43121".
  const std::string& address() const { return address_; }
  // The metrics exporter's bound port and host:port; 0 and "" when it is switched off.
  int metrics_port() const { return metrics_port_; }
  const std::string& metrics_address() const { return metrics_address_; }
  const ServerOptions& options() const { return options_; }

  // Shutdown, first step (Shutdown() does it too): health checks answer NOT_SERVING, new calls
  // get UNAVAILABLE, open streams stop reading, answer what they hold and end (UNAVAILABLE).
  void StartDraining();

  // Graceful shutdown: StartDraining(), then gRPC's Shutdown with a deadline of `grace` (frames
  // still in flight then are cancelled), then the worker pool is drained and joined. Returns
  // within about `grace` plus one frame's processing time. Idempotent; thread-safe.
  void Shutdown(std::chrono::milliseconds grace);
  void Shutdown() { Shutdown(options_.shutdown_grace); }

  // Blocks until Shutdown() has finished.
  void Wait();

  // SIGHUP: reads the TLS files and the tokens file again. Each that reads and checks well
  // replaces the one in use (new connections get the new certificate within about a second,
  // open ones keep theirs; new calls get the new tokens); one that does not is logged and the
  // old one stays. Returns the first error. Thread-safe.
  absl::Status ReloadSecurity();

  CloudCastService& service() { return *service_; }
  Metrics& metrics() { return *metrics_; }
  // The most frames one stream held at once (see CloudCastService::queued_frames_high_water).
  std::uint32_t queued_frames_high_water() const;

 private:
  explicit Server(const ServerOptions& options);
  // Undoes a Start() that failed half-way.
  void Abandon();

  const ServerOptions options_;
  // Before server_: gRPC's certificate watcher reads the copies it holds until the server is gone.
  std::unique_ptr<ServerTls> tls_;
  std::unique_ptr<Metrics> metrics_;
  std::unique_ptr<CloudCastService> service_;
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<MetricsHttpServer> metrics_http_;
  int port_ = 0;
  int metrics_port_ = 0;
  std::string metrics_address_;
  std::string address_;

  std::mutex shutdown_mu_;
  std::condition_variable shutdown_cv_;
  bool shut_down_ = false;
};

// The health-checking service name of CloudCast ("cloudcast.v1.CloudCast"); the empty name
// stands for the whole server.
const char* HealthServiceName();

}  // namespace cloudcast::server
