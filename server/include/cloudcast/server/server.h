// cloudcast's gRPC server: the CloudCast service, health checking, reflection and the
// Prometheus exporter, built, started and shut down as one object. The cloudcast-server binary
// is a thin main() around it; tests run it in-process on an ephemeral port.
#pragma once

#include <grpcpp/grpcpp.h>

#include <chrono>
#include <condition_variable>
#include <future>
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
  // get UNAVAILABLE, open streams stop reading, answer what they hold (and the message they were
  // reading, which their client sent before it could know) and end (UNAVAILABLE).
  void StartDraining();

  // Graceful shutdown, in at most `grace` + kShutdownOverrun:
  //   1. StartDraining(), and gRPC stops taking connections and calls (GOAWAY on every
  //      connection; the calls it made but had not handed to the service yet are failed);
  //   2. every call that can still deliver something is waited for, until `grace` is over;
  //   3. gRPC's Shutdown cancels the calls left and waits for gRPC to finish every call it made,
  //      until `grace` + kShutdownOverrun; then the worker pool is drained and joined.
  // Returns true when all of it is done. False when gRPC had not finished by then: calls that
  // nobody waits for any more (a rapid reset leaves gRPC thousands, which 1.51 cannot bound)
  // still hold it. Every reply and status the service wrote is out by then; the process may exit
  // without destroying the server (cloudcast-server's main does). The destructor waits for gRPC.
  // Idempotent (a second call returns the first one's result); thread-safe.
  bool Shutdown(std::chrono::milliseconds grace);
  bool Shutdown() { return Shutdown(options_.shutdown_grace); }
  // How long past its grace a Shutdown may last: gRPC's own part, after the calls left are
  // cancelled.
  static constexpr std::chrono::milliseconds kShutdownOverrun{500};
  // How long a drain waits for the message a stream was reading when it began (at most half the
  // grace).
  static constexpr std::chrono::milliseconds kDrainReadWait{1000};

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
  // StartDraining, waiting at most `read_wait` for the messages the streams were reading.
  void Drain(std::chrono::milliseconds read_wait);
  // Shutdown's last step, once gRPC's Shutdown has returned.
  void StopAfterGrpc();

  const ServerOptions options_;
  // Before server_: gRPC's certificate watcher reads the copies it holds until the server is gone.
  std::unique_ptr<ServerTls> tls_;
  std::unique_ptr<Metrics> metrics_;
  std::unique_ptr<CloudCastService> service_;
  std::unique_ptr<grpc::Server> server_;
  // Shutdown's: the queue of gRPC's shutdown notification, and gRPC's Shutdown running on a
  // thread of its own (it has no bound under a flood).
  grpc_completion_queue* shutdown_cq_ = nullptr;
  std::future<void> grpc_shutdown_;
  std::unique_ptr<MetricsHttpServer> metrics_http_;
  int port_ = 0;
  int metrics_port_ = 0;
  std::string metrics_address_;
  std::string address_;

  std::mutex shutdown_mu_;
  std::condition_variable shutdown_cv_;
  bool shut_down_ = false;
  bool grpc_finished_ = false;  // Shutdown's result
};

// The health-checking service name of CloudCast ("cloudcast.v1.CloudCast"); the empty name
// stands for the whole server.
const char* HealthServiceName();

}  // namespace cloudcast::server
