#include "cloudcast/server/server.h"

#include <arpa/inet.h>
#include <grpc/grpc.h>
#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/resource_quota.h>
#include <netinet/in.h>
#include <spdlog/spdlog.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <exception>
#include <thread>
#include <utility>

#include "absl/strings/str_cat.h"
#include "metrics.h"
#include "metrics_http.h"
#include "service.h"
#include "tenants.h"
#include "tls.h"

namespace cloudcast::server {
namespace {

// "host:port" -> "host:<port>"; IPv6 hosts keep their brackets.
std::string WithPort(const std::string& listen, int port) {
  const std::size_t colon = listen.rfind(':');
  const std::string host = colon == std::string::npos ? listen : listen.substr(0, colon);
  return absl::StrCat(host, ":", port);
}

// The metrics address: ":PORT" takes the gRPC address' host, so metrics are reachable exactly
// where the service is (all interfaces for 0.0.0.0:50051, loopback only for 127.0.0.1:50051).
std::string MetricsAddress(const ServerOptions& options) {
  if (options.metrics_listen.empty() || options.metrics_listen.front() != ':') {
    return options.metrics_listen;
  }
  const std::size_t colon = options.listen.rfind(':');
  return options.listen.substr(0, colon == std::string::npos ? 0 : colon) + options.metrics_listen;
}

// Reflection for this server only. gRPC's reflection plugin registers itself for every server
// of the process once linked in, so it is added here when wanted and removed when not.
class ReflectionOption final : public grpc::ServerBuilderOption {
 public:
  explicit ReflectionOption(bool enabled) : enabled_(enabled) {}
  void UpdateArguments(grpc::ChannelArguments* /*args*/) override {}
  void UpdatePlugins(std::vector<std::unique_ptr<grpc::ServerBuilderPlugin>>* plugins) override {
    const std::string name = grpc::reflection::ProtoServerReflectionPlugin().name();
    plugins->erase(std::remove_if(plugins->begin(), plugins->end(),
                                  [&](const auto& p) { return p->name() == name; }),
                   plugins->end());
    if (enabled_)
      plugins->push_back(std::make_unique<grpc::reflection::ProtoServerReflectionPlugin>());
  }

 private:
  const bool enabled_;
};

// How long a drain waits for the messages its streams were reading when it began.
std::chrono::milliseconds DrainReadWait(std::chrono::milliseconds grace) {
  return std::min(Server::kDrainReadWait, grace / 2);
}

}  // namespace

const char* HealthServiceName() { return "cloudcast.v1.CloudCast"; }

Server::Server(const ServerOptions& options) : options_(options) {}

absl::StatusOr<std::unique_ptr<Server>> Server::Start(const ServerOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  // The security files first: a bad one is the operator's error, named before anything starts.
  std::unique_ptr<ServerTls> tls;
  if (!options.tls_cert_file.empty()) {
    auto loaded = ServerTls::Load(
        TlsFiles{options.tls_cert_file, options.tls_key_file, options.tls_client_ca_file});
    if (!loaded.ok()) return loaded.status();
    tls = *std::move(loaded);
  }
  std::shared_ptr<const TenantDirectory> tenants;
  if (!options.tokens_file.empty()) {
    auto loaded = TenantDirectory::Load(options.tokens_file, options.limits.max_pixels);
    if (!loaded.ok()) return loaded.status();
    tenants = *std::move(loaded);
  }
  std::unique_ptr<Server> server(new Server(options));
  server->tls_ = std::move(tls);
  server->metrics_ = std::make_unique<Metrics>();
  server->service_ = std::make_unique<CloudCastService>(options, server->metrics_.get());
  server->service_->SetTenants(tenants);

  // A process-wide switch read when a server is built.
  grpc::EnableDefaultHealthCheckService(true);

  grpc::ServerBuilder builder;
  builder.AddListeningPort(
      options.listen,
      server->tls_ != nullptr ? server->tls_->Credentials() : grpc::InsecureServerCredentials(),
      &server->port_);
  builder.SetOption(std::make_unique<ReflectionOption>(options.reflection));
  builder.SetMaxReceiveMessageSize(static_cast<int>(options.max_message_bytes));
  // gRPC sets SO_REUSEPORT by default, so a second server on a busy port would silently share
  // it; an operator wants "address in use" instead.
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  // Bounded transport buffers per stream: a fixed receive window instead of one that BDP probing
  // grows to many megabytes, so a stream whose frames wait (its client sends faster than it is
  // served, or stopped reading) holds about max_queued_frames frames, not 30 MB more.
  builder.AddChannelArgument(GRPC_ARG_HTTP2_BDP_PROBE, 0);
  builder.AddChannelArgument(GRPC_ARG_HTTP2_STREAM_LOOKAHEAD_BYTES,
                             static_cast<int>(options.stream_window_bytes));
  // Clients may send DATA frames of up to 256 KB instead of HTTP/2's default 16 KB. A message
  // reaches us as one slice per frame, and a raw 640x480 frame's rows that cross slices are
  // copied to be read whole: 72 slices of its colour plane become about 20, and gRPC parses a
  // quarter of the frame headers. Measured (cloudcast-e2e-bench, 4 alternating rounds): server
  // CPU per raw frame -2%, per zstd frame -6%; 4 raw streams +4%, 4 zstd streams +7% frames/s.
  // Flow control still bounds each stream by stream_window_bytes (64 KB at least). Larger frames
  // only interleave the streams of one connection more coarsely (one robot's own streams).
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MAX_FRAME_SIZE, 256 * 1024);
  if (options.max_connection_age.count() > 0) {
    builder.AddChannelArgument(GRPC_ARG_MAX_CONNECTION_AGE_MS,
                               static_cast<int>(options.max_connection_age.count()));
  }
  if (options.max_connection_age_grace.count() > 0) {
    builder.AddChannelArgument(GRPC_ARG_MAX_CONNECTION_AGE_GRACE_MS,
                               static_cast<int>(options.max_connection_age_grace.count()));
  }
  // A peer that has stopped reading its connection (a proxy whose client is stuck or gone: issue
  // 30, defect 7) loses it, with its calls: a PING after ping_after of silence, unanswered within
  // ping_timeout. gRPC stops pinging after 2 PINGs with no data sent between them and spaces them
  // 5 minutes apart without data; a connection stuck that way sends no data: both are lifted.
  if (const auto ping_after = options.EffectivePingAfter(); ping_after.count() > 0) {
    builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIME_MS, static_cast<int>(ping_after.count()));
    builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIMEOUT_MS,
                               static_cast<int>(options.ping_timeout.count()));
    builder.AddChannelArgument(GRPC_ARG_HTTP2_MAX_PINGS_WITHOUT_DATA, 0);
    builder.AddChannelArgument(GRPC_ARG_HTTP2_MIN_SENT_PING_INTERVAL_WITHOUT_DATA_MS,
                               static_cast<int>(ping_after.count()));
  }
  // HTTP/2 limits (docs/http2-hardening.md has what each bounds, measured): streams open at once
  // per connection, the size of a call's header block, and the transport's memory quota.
  builder.AddChannelArgument(GRPC_ARG_MAX_CONCURRENT_STREAMS,
                             static_cast<int>(options.http2_max_concurrent_streams));
  if (options.http2_max_metadata_bytes > 0) {
    builder.AddChannelArgument(GRPC_ARG_MAX_METADATA_SIZE,
                               static_cast<int>(options.http2_max_metadata_bytes));
  }
  if (options.transport_memory_bytes > 0) {
    grpc::ResourceQuota quota("cloudcast-transport");
    quota.Resize(static_cast<std::size_t>(options.transport_memory_bytes));
    builder.SetResourceQuota(quota);
  }
  builder.RegisterService(server->service_.get());
  builder.RegisterCallbackGenericService(server->service_->process_service());
  server->server_ = builder.BuildAndStart();
  if (server->server_ == nullptr || server->port_ == 0) {
    server->Abandon();
    return absl::UnavailableError(absl::StrCat("cannot serve gRPC on ", options.listen,
                                               " (--listen): address in use, or "
                                               "not an address of this machine"));
  }
  server->address_ = WithPort(options.listen, server->port_);

  if (!options.metrics_listen.empty()) {
    const std::string metrics_address = MetricsAddress(options);
    Metrics* metrics = server->metrics_.get();
    auto http =
        MetricsHttpServer::Start({metrics_address}, [metrics] { return metrics->Serialize(); });
    if (!http.ok()) {
      server->Abandon();
      return absl::UnavailableError(absl::StrCat(http.status().message(), " (--metrics-listen)"));
    }
    server->metrics_http_ = *std::move(http);
    server->metrics_port_ = server->metrics_http_->port();
    server->metrics_address_ = WithPort(metrics_address, server->metrics_port_);
  }

  grpc::HealthCheckServiceInterface* health = server->server_->GetHealthCheckService();
  health->SetServingStatus("", true);
  health->SetServingStatus(HealthServiceName(), true);
  spdlog::info("cloudcast-server listening on {} ({} workers, metrics {}; {}, {}, reflection {})",
               server->address_, server->service_->worker_threads(),
               server->metrics_port_ > 0 ? "http://" + server->metrics_address_ + "/metrics"
                                         : std::string("off"),
               server->tls_ == nullptr  ? "plaintext"
               : server->tls_->mutual() ? "mutual TLS"
                                        : "TLS",
               tenants == nullptr
                   ? std::string("no authentication")
                   : absl::StrCat("bearer tokens of ", tenants->tenants(), " tenants"),
               options.reflection ? "on" : "off");
  return server;
}

absl::Status Server::ReloadSecurity() {
  absl::Status result;
  if (tls_ != nullptr) {
    if (absl::Status s = tls_->Reload(); s.ok()) {
      spdlog::info("TLS: reloaded {} (new connections get it within {} s)", options_.tls_cert_file,
                   ServerTls::kRefreshSeconds);
    } else {
      spdlog::error("TLS: reload failed, keeping the previous certificate: {}",
                    std::string(s.message()));
      result = s;
    }
  }
  if (!options_.tokens_file.empty()) {
    auto tenants = TenantDirectory::Load(options_.tokens_file, options_.limits.max_pixels);
    if (tenants.ok()) {
      spdlog::info("tokens: reloaded {} ({} tenants); open calls keep their tenant",
                   options_.tokens_file, (*tenants)->tenants());
      service_->SetTenants(*std::move(tenants));
    } else {
      spdlog::error("tokens: reload failed, keeping the previous tokens: {}",
                    std::string(tenants.status().message()));
      if (result.ok()) result = tenants.status();
    }
  }
  return result;
}

Server::~Server() {
  Shutdown();
  // A Shutdown that did not wait for gRPC to finish: it must before the service goes.
  std::lock_guard<std::mutex> lock(shutdown_mu_);
  if (!grpc_finished_ && grpc_shutdown_.valid()) {
    grpc_shutdown_.wait();
    StopAfterGrpc();
  }
}

std::uint32_t Server::queued_frames_high_water() const {
  return service_->queued_frames_high_water();
}

void Server::Abandon() {
  if (server_ != nullptr) server_->Shutdown(std::chrono::system_clock::now());
  service_->StopWorkers();
  std::lock_guard<std::mutex> lock(shutdown_mu_);
  shut_down_ = true;
}

void Server::StartDraining() { Drain(DrainReadWait(options_.shutdown_grace)); }

void Server::Drain(std::chrono::milliseconds read_wait) {
  if (service_->draining()) return;
  // NOT_SERVING first, so that load balancers stop sending before calls are refused.
  grpc::HealthCheckServiceInterface* health = server_->GetHealthCheckService();
  health->SetServingStatus("", false);
  health->SetServingStatus(HealthServiceName(), false);
  service_->StartDraining(read_wait);
}

bool Server::Shutdown(std::chrono::milliseconds grace) {
  std::unique_lock<std::mutex> lock(shutdown_mu_);
  if (shut_down_) return grpc_finished_;
  const auto start = std::chrono::steady_clock::now();
  const auto deadline = start + grace;
  spdlog::info("shutting down (grace {} ms)", grace.count());
  Drain(DrainReadWait(grace));
  // gRPC's part of the drain, at once: a GOAWAY on every connection, no new connection, and the
  // calls it has made but not handed to the service yet fail. A client that opens and resets
  // calls as fast as it can (rapid reset) makes no more of them once its GOAWAY is final, so the
  // backlog it left gRPC stops growing while the calls open are drained. Those go on.
  shutdown_cq_ = grpc_completion_queue_create_for_next(nullptr);
  grpc_server_shutdown_and_notify(server_->c_server(), shutdown_cq_, this);
  // Our calls: streams answer what they hold and end, Process calls finish their frame. Calls
  // their clients cancelled are not waited for: nothing more can reach those clients.
  const bool drained = service_->WaitForCalls(deadline);
  if (drained) {
    spdlog::info("every call answered in {} ms",
                 std::chrono::duration_cast<std::chrono::milliseconds>(
                     std::chrono::steady_clock::now() - start)
                     .count());
  } else {
    const auto [streams, process] = service_->CallsInFlight();
    spdlog::warn(
        "grace period over: cancelling the calls still in flight ({} streams, {} "
        "Process calls)",
        streams, process);
  }
  // Then gRPC's Shutdown with no further wait: it cancels the calls left and closes every
  // connection left (idle ones: a client that keeps a connection open, or one that never
  // finished its handshake, would otherwise hold the shutdown for the whole grace period), then
  // waits until gRPC has finished every call it made. That has no bound: a rapid reset leaves
  // gRPC thousands of calls to finish, seconds of work on 2 busy cores (9.1 s in all against a
  // 5 s grace, issue 30). So it runs on a thread of its own, waited for until the grace period
  // plus kShutdownOverrun.
  grpc_shutdown_ = std::async(std::launch::async,
                              [this] { server_->Shutdown(std::chrono::system_clock::now()); });
  grpc_finished_ =
      grpc_shutdown_.wait_until(deadline + kShutdownOverrun) == std::future_status::ready;
  if (grpc_finished_) {
    StopAfterGrpc();
  } else {
    // Every reply and status the service wrote went out before (the calls that still had
    // something to deliver at the deadline were cancelled; their clients see UNAVAILABLE).
    spdlog::warn(
        "gRPC has not finished the calls its clients abandoned {} ms after the grace "
        "period: not waiting for it",
        kShutdownOverrun.count());
  }
  shut_down_ = true;
  spdlog::info("shut down in {} ms", std::chrono::duration_cast<std::chrono::milliseconds>(
                                         std::chrono::steady_clock::now() - start)
                                         .count());
  shutdown_cv_.notify_all();
  return grpc_finished_;
}

void Server::StopAfterGrpc() {
  grpc_shutdown_.get();
  // gRPC's shutdown notification is in the queue once its Shutdown has returned.
  grpc_completion_queue_shutdown(shutdown_cq_);
  while (
      grpc_completion_queue_next(shutdown_cq_, gpr_inf_future(GPR_CLOCK_MONOTONIC), nullptr).type !=
      GRPC_QUEUE_SHUTDOWN) {
  }
  grpc_completion_queue_destroy(shutdown_cq_);
  shutdown_cq_ = nullptr;
  // gRPC has seen every OnDone by now; a frame still in work holds its reactor until its
  // worker is done, which StopWorkers waits for.
  service_->WaitForCalls(std::chrono::steady_clock::now() + std::chrono::seconds(1));
  service_->StopWorkers();
  metrics_http_.reset();
}

void Server::Wait() {
  std::unique_lock<std::mutex> lock(shutdown_mu_);
  shutdown_cv_.wait(lock, [this] { return shut_down_; });
}

}  // namespace cloudcast::server
