#include "cloudcast/server/cli.h"

#include <chrono>
#include <cmath>

#include "absl/strings/str_cat.h"

namespace cloudcast::server {
namespace {

std::chrono::milliseconds ToMillis(double seconds) {
  return std::chrono::milliseconds(static_cast<std::int64_t>(std::llround(seconds * 1000.0)));
}

}  // namespace

ServerFlags::ServerFlags(CLI::App& app)
    : idle_timeout_seconds_(std::chrono::duration<double>(options_.idle_timeout).count()),
      first_message_timeout_seconds_(
          std::chrono::duration<double>(options_.first_message_timeout).count()),
      memory_budget_mb_(options_.memory_budget_bytes >> 20),
      work_memory_mb_(options_.work_memory_bytes >> 20),
      shed_quiet_after_seconds_(std::chrono::duration<double>(options_.shed_quiet_after).count()),
      refusal_delay_seconds_(std::chrono::duration<double>(options_.refusal_delay).count()),
      shutdown_grace_seconds_(std::chrono::duration<double>(options_.shutdown_grace).count()),
      delivery_(convert::Name(options_.defaults.delivery)) {
  app.option_defaults()->always_capture_default();
  app.set_config("--config", "",
                 "Read flags from this TOML or INI file: one `name = value` per flag, the name "
                 "without its dashes (e.g. max-streams = 8); the command line wins; an unknown "
                 "name is an error");
  // A misspelt key (max-stream = 8) must not be ignored silently: CLI11's default drops it.
  app.allow_config_extras(false);

  ServerOptions& o = options_;
  app.add_option("--listen", o.listen, "gRPC address, host:port; port 0 picks a free one")
      ->group("Service");
  app.add_option("--threads", o.threads, "Worker threads that process frames; 0 = one per core")
      ->check(CLI::Range(0, 1024))
      ->group("Service");
  app.add_option("--metrics-listen", o.metrics_listen,
                 "Prometheus /metrics address, host:port; ':port' uses the host of --listen "
                 "(metrics are reachable where the service is); empty switches it off")
      ->group("Service");
  app.add_option("--instance", o.instance,
                 "This replica's name, sent in every reply and in GetInfo; default: the host name")
      ->group("Service");
  app.add_option("--log-level", log_level_, "trace, debug, info, warn, error, critical or off")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "critical", "off"}))
      ->group("Service");
  app.add_option("--ready-file", ready_file_,
                 "Once serving, write the bound addresses to this file (lines `grpc=host:port` and "
                 "`metrics=host:port`, empty when off), replacing it whole: how a script or test "
                 "that asked for port 0 learns the port without racing for a free one")
      ->group("Service");
  app.add_option("--shutdown-grace", shutdown_grace_seconds_,
                 "Seconds frames in flight get to finish on SIGINT / SIGTERM before their calls "
                 "are cancelled")
      ->check(CLI::Range(0.0, 3600.0))
      ->group("Service");

  app.add_option("--max-connection-age", max_connection_age_seconds_,
                 "Seconds after which a connection is told to go away (GOAWAY), so long-lived "
                 "clients rebalance onto new replicas; 0 = never")
      ->check(CLI::Range(0.0, 2.0e6))
      ->group("Service");
  app.add_option("--max-connection-age-grace", max_connection_age_grace_seconds_,
                 "Seconds the streams of such a connection get to finish before they are "
                 "cancelled; 0 = no limit")
      ->check(CLI::Range(0.0, 2.0e6))
      ->group("Service");
  app.add_option("--ping-after", ping_after_seconds_,
                 "Seconds a peer may send nothing before it gets an HTTP/2 PING, which it must "
                 "answer within --ping-timeout or its connection is closed with its calls (a "
                 "proxy that stopped reading one client's connection); -1 = 0.5 with "
                 "--trusted-proxy, off without; 0 = off")
      ->check(CLI::Range(-1.0, 2.0e6))
      ->group("Service");
  app.add_option("--ping-timeout", ping_timeout_seconds_,
                 "Seconds a PING of --ping-after may go unanswered")
      ->check(CLI::Range(0.001, 2.0e6))
      ->group("Service");

  const std::string security = "Security (README, Security)";
  app.add_option("--tls-cert", o.tls_cert_file,
                 "Serve TLS with this PEM certificate chain (leaf first); with --tls-key. "
                 "Re-read on SIGHUP. Default: plaintext")
      ->group(security);
  app.add_option("--tls-key", o.tls_key_file,
                 "The PEM private key of --tls-cert (unencrypted). Re-read on SIGHUP")
      ->group(security);
  app.add_option("--tls-client-ca", o.tls_client_ca_file,
                 "Mutual TLS: require a client certificate that chains to these PEM CAs; clients "
                 "without one are refused. Re-read on SIGHUP")
      ->group(security);
  app.add_option("--tokens-file", o.tokens_file,
                 "Require a bearer token (metadata 'authorization: Bearer <token>') on every "
                 "CloudCast call: a JSON file of tenants, their tokens and limits (README, "
                 "Security). Health checks stay open. Re-read on SIGHUP. Default: no "
                 "authentication")
      ->group(security);
  app.add_flag("--no-reflection", no_reflection_,
               "Do not serve gRPC server reflection (which lets anyone list the API)")
      ->group(security);

  app.add_option("--max-message-bytes", o.max_message_bytes,
                 "Largest request message; a larger one ends its call with RESOURCE_EXHAUSTED")
      ->group("Limits");
  app.add_option("--max-side", o.limits.max_side, "Largest image width or height, pixels")
      ->group("Limits");
  app.add_option("--max-pixels", o.limits.max_pixels,
                 "Largest width x height, pixels (at most 2^24)")
      ->group("Limits");
  app.add_option("--max-stereo-volume", o.limits.max_stereo_volume,
                 "Largest width x height x num_disparities of a stereo pair matched (the matcher's "
                 "cost volume, a byte each); a larger pair gets RESOURCE_EXHAUSTED")
      ->group("Limits");
  app.add_option("--max-streams", o.max_streams,
                 "Concurrent Stream calls (and, separately, Process calls in flight); more get "
                 "RESOURCE_EXHAUSTED")
      ->group("Limits");
  app.add_option("--idle-timeout", idle_timeout_seconds_,
                 "Seconds a stream may sit with nothing moving before it is ended with "
                 "DEADLINE_EXCEEDED")
      ->check(CLI::Range(0.001, 86400.0))
      ->group("Limits");
  app.add_option("--memory-budget-mb", memory_budget_mb_,
                 "Megabytes of frames the server may hold at once (read, not yet processed), "
                 "each counted at its decoded size (a compressed or encoded frame is charged "
                 "what it decodes to, before it is decoded); past it new frames get "
                 "RESOURCE_EXHAUSTED")
      ->check(CLI::Range(1, 1 << 24))
      ->group("Limits");
  app.add_option("--work-memory-mb", work_memory_mb_,
                 "Megabytes frames in work may use (decoded images and the pipeline's working "
                 "memory, estimated from each frame's header before decoding: up to 128 bytes a "
                 "pixel); a frame waits for a worker until it fits, one that never fits gets "
                 "RESOURCE_EXHAUSTED")
      ->check(CLI::Range(16, 1 << 24))
      ->group("Limits");
  app.add_option("--large-frame-pixels", o.large_frame_pixels,
                 "Frames of more pixels are large: they run on all workers but one at most, and "
                 "give their scratch memory back afterwards")
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1} << 24))
      ->group("Limits");
  app.add_option("--refusal-delay", refusal_delay_seconds_,
                 "Seconds before a Process call refused for memory is answered (it holds one of "
                 "its client's Process places meanwhile), so such refusals cannot flood the "
                 "server; 0 = at once")
      ->check(CLI::Range(0.0, 60.0))
      ->group("Limits");
  app.add_option("--shed-quiet-after", shed_quiet_after_seconds_,
                 "When --max-streams is reached, a stream that has sent no frame for this many "
                 "seconds is ended (UNAVAILABLE) to make room for a new client; 0 = never")
      ->check(CLI::Range(0.0, 86400.0))
      ->group("Limits");
  app.add_option("--stream-window-bytes", o.stream_window_bytes,
                 "gRPC receive window per stream: what the transport buffers beyond the frames "
                 "a stream holds (fixed; no BDP growth)")
      ->group("Limits");
  app.add_option("--first-message-timeout", first_message_timeout_seconds_,
                 "Seconds a new stream may take to send its first message before it is ended "
                 "with DEADLINE_EXCEEDED")
      ->check(CLI::Range(0.001, 86400.0))
      ->group("Limits");
  app.add_option("--max-streams-per-client", o.max_streams_per_client,
                 "One client's share of --max-streams (a client is its peer address); 0 = half "
                 "of --max-streams. Behind an L7 balancer every call comes from it: raise this")
      ->group("Limits");
  app.add_option("--max-process-per-client", o.max_process_per_client,
                 "One client's share of the Process calls in flight; 0 = half of --max-streams")
      ->group("Limits");
  app.add_option("--max-reading-mb-per-client", reading_mb_per_client_,
                 "MB of Process requests one client may have arriving at once: each read "
                 "reserves --max-message-bytes (gRPC holds a message whole before it is checked), "
                 "the client's other Process calls wait to read; 0 = twice --max-message-bytes")
      ->group("Limits");
  app.add_option("--trusted-proxy", o.trusted_proxies,
                 "A proxy in front (its IP address; repeat for several) whose x-forwarded-for "
                 "header names the client: its calls count against that address. Others' "
                 "headers are ignored")
      ->group("Limits");
  const std::string transport = "HTTP/2 transport (docs/http2-hardening.md)";
  app.add_option("--http2-max-concurrent-streams", o.http2_max_concurrent_streams,
                 "Streams open at once on one connection (SETTINGS_MAX_CONCURRENT_STREAMS)")
      ->check(CLI::Range(1u, 0x7fffffffu))
      ->group(transport);
  app.add_option("--http2-max-metadata-bytes", o.http2_max_metadata_bytes,
                 "Largest header block of a call; 0 = gRPC's default (8 KB)")
      ->group(transport);
  app.add_option("--transport-memory-mb", transport_memory_mb_,
                 "gRPC's resource quota: memory its transport may use; 0 = no quota")
      ->check(CLI::Range(0, 1 << 24))
      ->group(transport);
  app.add_option("--log-calls-per-second", o.log_calls_per_second,
                 "Per-call log lines (stream opened, done, refused) written per second at most; "
                 "the rest are counted, not written")
      ->check(CLI::Range(1u, 1000000u))
      ->group("Service");
  app.add_option("--max-queued-frames", o.max_queued_frames,
                 "Frames held per stream in delivery 'all' (waiting + in work + replies not yet "
                 "written); when full the stream is not read")
      ->group("Limits");

  const std::string defaults = "Stream defaults (a client's StreamConfig overrides them)";
  stages_ = std::make_unique<cli::StageFlags>(
      app, cli::StageFlags::Groups{defaults, defaults, defaults}, o.defaults.frame);
  app.add_option("--delivery", delivery_,
                 "Default delivery: 'latest' (real time, drops stale frames) or 'all' "
                 "(lossless, flow-controlled)")
      ->check(CLI::IsMember({"latest", "all"}))
      ->group(defaults);
}

absl::StatusOr<ServerOptions> ServerFlags::Options() const {
  ServerOptions o = options_;
  o.idle_timeout = ToMillis(idle_timeout_seconds_);
  o.first_message_timeout = ToMillis(first_message_timeout_seconds_);
  o.memory_budget_bytes = memory_budget_mb_ << 20;
  o.work_memory_bytes = work_memory_mb_ << 20;
  o.shed_quiet_after = ToMillis(shed_quiet_after_seconds_);
  o.refusal_delay = ToMillis(refusal_delay_seconds_);
  o.transport_memory_bytes = transport_memory_mb_ << 20;
  o.reading_bytes_per_client = reading_mb_per_client_ << 20;
  o.shutdown_grace = ToMillis(shutdown_grace_seconds_);
  o.reflection = !no_reflection_;
  o.max_connection_age = ToMillis(max_connection_age_seconds_);
  o.max_connection_age_grace = ToMillis(max_connection_age_grace_seconds_);
  o.ping_after =
      ping_after_seconds_ < 0 ? std::chrono::milliseconds(-1) : ToMillis(ping_after_seconds_);
  o.ping_timeout = ToMillis(ping_timeout_seconds_);
  auto frame = stages_->Apply(o.defaults.frame);
  if (!frame.ok()) return frame.status();
  o.defaults.frame = *std::move(frame);
  if (!convert::ParseDelivery(delivery_, &o.defaults.delivery)) {
    return absl::InvalidArgumentError(
        absl::StrCat("--delivery must be latest or all, got ", delivery_));
  }
  if (absl::Status s = o.Validate(); !s.ok()) return s;
  return o;
}

}  // namespace cloudcast::server
