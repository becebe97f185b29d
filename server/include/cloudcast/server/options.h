// The server's options, with their documented defaults. What a stream gets for the StreamConfig
// fields it leaves unset is `defaults`, whose own defaults are the contract's
// (convert::ContractDefaults: no camera, no passthrough, 3 cm voxels, Draco speed 10 at 10 bits).
#pragma once

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "cloudcast/core/limits.h"
#include "cloudcast/proto/convert.h"

namespace cloudcast::server {

using convert::Delivery;
using convert::StreamSettings;

struct ServerOptions {
  // host:port to serve gRPC on; port 0 picks a free port (Server::port() reports it).
  std::string listen = "0.0.0.0:50051";
  // Worker threads that process frames; 0 means one per core (std::thread::hardware_concurrency).
  int threads = 0;
  // Largest request message gRPC accepts. A raw 640x480 frame (8-bit disparity, RGB colour) is
  // 1.2 MiB; one at the pixel limit (2^24 pixels) is 64 MiB plus a few bytes, so serving frames
  // that large needs this raised.
  std::uint64_t max_message_bytes = std::uint64_t{64} << 20;
  // Largest image side and width x height (the core's limits).
  Limits limits;
  // Concurrent Stream calls, and separately Process calls in flight; the next one gets
  // RESOURCE_EXHAUSTED.
  std::uint32_t max_streams = 64;
  // One client's share of those (a client is its peer address; with tokens, its tenant), so no
  // client can take every slot. 0: half of max_streams. Behind an L7 load balancer every call
  // comes from the balancer's address: raise these there, or give robots tokens.
  std::uint32_t max_streams_per_client = 0;
  std::uint32_t max_process_per_client = 0;
  // Bytes of Process requests one client may have arriving at once. gRPC holds a message until
  // it is whole, as wide as it announces (up to max_message_bytes), so each Process read reserves
  // max_message_bytes of this; the client's other Process calls wait to start reading, holding
  // only the transport's window. 0: twice max_message_bytes (two reads at once).
  std::uint64_t reading_bytes_per_client = 0;
  // A stream on which nothing moved this long is ended with DEADLINE_EXCEEDED.
  std::chrono::milliseconds idle_timeout{60'000};
  // A stream that has sent no message at all this long after opening is ended the same way.
  std::chrono::milliseconds first_message_timeout{10'000};
  // Frames held per stream in DELIVERY_ALL mode (waiting + in work + replies not yet written).
  std::uint32_t max_queued_frames = 4;
  // Bytes of frames the server may hold at once (read, not yet processed), over all calls, each
  // counted at its request's size plus what its images decode to (charged before anything is
  // decoded: a few KB of zstd claiming 4096x4096 count 64 MB); past it new frames get
  // RESOURCE_EXHAUSTED instead of memory growing. The transport adds at most max_streams x
  // stream_window_bytes, and frames in work at most work_memory_bytes.
  std::uint64_t memory_budget_bytes = std::uint64_t{1} << 30;
  // Memory for frames in work: their decoded images and the pipeline's working memory, estimated
  // from each frame's header before anything is decoded (frame_input.h, EstimateFrameMemory: up to
  // 128 bytes a pixel). A frame starts on a worker only while the frames in work plus it fit; one
  // that can never fit gets RESOURCE_EXHAUSTED at once. 320 MB fits one 1920x1080 frame at its
  // worst, or several camera frames.
  std::uint64_t work_memory_bytes = std::uint64_t{320} << 20;
  // A Process call refused for memory (a frame that can never fit the work memory, or a full
  // budget) is answered after this pause, holding one of its client's Process places meanwhile: a
  // client that sends such frames call after call then gets a few refusals a second, not
  // thousands (whose transport work costs everyone). 0: at once.
  std::chrono::milliseconds refusal_delay{1'000};
  // Frames of more pixels than this are large: at most all workers but one run large frames at
  // once (a worker stays free for camera frames), and a worker that ran one gives its scratch back
  // to the allocator afterwards, instead of keeping it for the next frame. 2^21: just over
  // 1920x1080.
  std::uint64_t large_frame_pixels = std::uint64_t{1} << 21;
  // When the server is full (--max-streams), a stream that has sent no frame for this long (only
  // a StreamConfig, or nothing, or its last frame that long ago) is ended with UNAVAILABLE to make
  // room for a new client, the client holding the most streams first; a resilient client reopens
  // it. A camera stream at 1 fps or more is never that quiet. 0: never.
  std::chrono::milliseconds shed_quiet_after{2'000};
  // Peers trusted to name the client in an `x-forwarded-for` header (a proxy in front, e.g. the
  // HAProxy sidecar: option forwardfor): a call from one of these addresses counts against the
  // address the header's last entry names, for the per-client shares and fairness. Others'
  // headers are ignored (anyone could send one). IP addresses, e.g. "127.0.0.1".
  std::vector<std::string> trusted_proxies;
  // HTTP/2 limits of gRPC's transport. Streams open at once on one connection (SETTINGS
  // MAX_CONCURRENT_STREAMS; a client may still open and reset streams faster than that, which
  // only a proxy in front bounds: docs/http2-hardening.md).
  std::uint32_t http2_max_concurrent_streams = 256;
  // Largest header block (metadata) of a call; 0: gRPC's default (8 KB).
  std::uint32_t http2_max_metadata_bytes = 0;
  // gRPC's resource quota: memory its transport may use before it starts to refuse work; 0: no
  // quota (gRPC's default).
  std::uint64_t transport_memory_bytes = 0;
  // Per-call log lines (stream opened, done, refused) written per second at most; the rest are
  // counted (cloudcast_log_lines_suppressed_total) and the next line written says how many.
  std::uint32_t log_calls_per_second = 20;
  // gRPC's receive window per stream: how much of the next frames the transport buffers beyond
  // those the stream holds. Fixed (no BDP probing, which grows windows to tens of megabytes):
  // with it a stream whose frames wait holds about max_queued_frames frames plus this.
  std::uint32_t stream_window_bytes = 1u << 20;
  // On shutdown, how long frames in flight may take before their calls are cancelled.
  std::chrono::milliseconds shutdown_grace{5'000};
  // Connections older than this are told to go away (GOAWAY), so that long-lived clients spread
  // onto replicas added since they connected; 0 keeps connections forever. gRPC adds +-10%
  // jitter. Streams still open on such a connection get `max_connection_age_grace` to finish,
  // then are cancelled (a resilient client then reopens them elsewhere; 0: no limit).
  std::chrono::milliseconds max_connection_age{0};
  std::chrono::milliseconds max_connection_age_grace{0};
  // A connection whose peer has sent nothing for `ping_after` gets an HTTP/2 PING, and is closed,
  // with its calls, when the PING is not answered within `ping_timeout`: its peer has stopped
  // reading it. A gRPC client's transport reads its connection whatever its calls do, so it
  // answers at once; HAProxy 2.6 stops reading a server connection whose stream it cannot pass on
  // (the client's window shut, or the client gone while the proxy never read its FIN or reset:
  // issue 30, defect 7), and that connection's calls stayed open until the proxy's timeouts (5 s to
  // 2 minutes). Negative (the default): 500 ms and 1 s with trusted_proxies (the server behind
  // the shipped proxy), off without (a direct client on a slow link could take longer to answer
  // a PING queued behind its replies). ping_after 0: off.
  std::chrono::milliseconds ping_after{-1};
  std::chrono::milliseconds ping_timeout{1'000};
  // ping_after as it applies: `ping_after` unless negative (then by trusted_proxies); 0: off.
  std::chrono::milliseconds EffectivePingAfter() const {
    if (ping_after.count() >= 0) return ping_after;
    return trusted_proxies.empty() ? std::chrono::milliseconds(0) : std::chrono::milliseconds(500);
  }
  // host:port for Prometheus' /metrics; ":port" takes the host of `listen` (metrics are
  // reachable exactly where the service is); empty switches the exporter off.
  std::string metrics_listen = ":9464";
  // This replica's name, sent in every reply and in GetInfo. Empty: the host name.
  std::string instance;

  // Security (README, "Security"). All off by default: plaintext, no authentication.
  // TLS on the gRPC port: the certificate chain (leaf first) and its unencrypted private key,
  // both PEM files; empty: plaintext. Re-read by Server::ReloadSecurity (SIGHUP).
  std::string tls_cert_file;
  std::string tls_key_file;
  // Mutual TLS: the PEM CAs a client's certificate must chain to; clients without a certificate
  // are refused. Needs tls_cert_file. Empty: no client certificates asked for.
  std::string tls_client_ca_file;
  // The JSON file of bearer tokens and tenants (tenants.h). Empty: no authentication. With it,
  // every CloudCast call needs "authorization: Bearer <token>" (health checks do not), and the
  // per-client shares are per tenant, with the tenant's own limits.
  std::string tokens_file;
  // Server reflection (grpc.reflection.v1alpha), which lets tools like grpcurl list the API.
  bool reflection = true;
  // What a stream gets for every StreamConfig field it leaves unset (GetInfo's `defaults`).
  // Its pipeline limits are ignored: `limits` above apply.
  StreamSettings defaults = convert::ContractDefaults();

  // Everything in range: threads >= 0, positive limits, max_queued_frames >= 1, valid defaults.
  // Errors name the command-line flag.
  absl::Status Validate() const;
  // `threads`, or the number of cores when it is 0 (at least 1).
  int ResolvedThreads() const;
  // The per-client shares with 0 resolved (half of max_streams, at least 1).
  std::uint32_t ResolvedMaxStreamsPerClient() const;
  std::uint32_t ResolvedMaxProcessPerClient() const;
  // reading_bytes_per_client with 0 resolved, and never under one message.
  std::uint64_t ResolvedReadingBytesPerClient() const;
  // `instance`, or the host name when it is empty.
  std::string ResolvedInstance() const;
  // `defaults` with `limits`: what a stream starts from.
  StreamSettings StreamDefaults() const;
};

}  // namespace cloudcast::server
