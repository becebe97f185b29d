// The CloudCast gRPC service on the callback API.
//
// Threading: gRPC's threads only move messages: they run the reactions (OnReadDone, OnWriteDone,
// ...), which check configs, queue frames and start reads and writes. Frames are processed on a
// WorkerPool of `threads` workers, each with its own FrameProcessor (a core Pipeline is not
// thread-safe). A housekeeping thread ends idle streams.
//
// One StreamReactor per Stream call: a thin shell that sequences gRPC's reads, writes and Finish
// around the stream's StreamQueue, which holds the delivery policy (see stream_queue.h).
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "admission.h"
#include "cloudcast/server/options.h"
#include "cloudcast/v1/cloudcast.grpc.pb.h"
#include "delayed_actions.h"
#include "frame_processor.h"
#include "log_limiter.h"
#include "metrics.h"
#include "spdlog/spdlog.h"
#include "tenants.h"
#include "worker_pool.h"

namespace cloudcast::server {

// Stream and Process take raw bytes and parse them here, so that bytes which are not a valid
// message get a status that says so (gRPC's own parsing reports a half-close, or UNIMPLEMENTED).
using CallbackBase =
    v1::CloudCast::WithRawCallbackMethod_Stream<v1::CloudCast::WithRawCallbackMethod_Process<
        v1::CloudCast::WithCallbackMethod_GetInfo<v1::CloudCast::Service>>>;

class CloudCastService final : public CallbackBase {
 public:
  // `options` must be valid (ServerOptions::Validate); `metrics` must outlive the service.
  CloudCastService(const ServerOptions& options, Metrics* metrics);
  ~CloudCastService() override;  // StopWorkers()
  CloudCastService(const CloudCastService&) = delete;
  CloudCastService& operator=(const CloudCastService&) = delete;

  grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* Stream(
      grpc::CallbackServerContext* context) override;
  grpc::ServerUnaryReactor* Process(grpc::CallbackServerContext* context,
                                    const grpc::ByteBuffer* request,
                                    grpc::ByteBuffer* reply) override;
  grpc::ServerUnaryReactor* GetInfo(grpc::CallbackServerContext* context,
                                    const v1::GetInfoRequest* request,
                                    v1::ServerInfo* info) override;

  // The bearer tokens new calls must carry (null: none needed). Calls already open keep the
  // tenant they were admitted as. Thread-safe.
  void SetTenants(std::shared_ptr<const TenantDirectory> tenants);

  // Shutdown, step 1: new Stream and Process calls get UNAVAILABLE; every open stream stops
  // reading, answers the frames it already holds and ends with UNAVAILABLE.
  void StartDraining();
  bool draining() const { return draining_.load(); }
  // Waits until every Stream call is done (OnDone) and every Process call has finished, or
  // `deadline` passes; true if none is left.
  bool WaitForCalls(std::chrono::steady_clock::time_point deadline);
  // Runs the frames still queued, then joins the workers and the housekeeping thread. Call once
  // the gRPC server has shut down. Idempotent.
  void StopWorkers();

  int active_streams() const { return static_cast<int>(admission_.open(Admission::Kind::kStream)); }
  int worker_threads() const { return static_cast<int>(pool_.size()); }
  // The most frames one stream held at once (waiting + in work + replies not yet written), over
  // all streams since the start or the last reset. Tests check it against max_queued_frames.
  std::uint32_t queued_frames_high_water() const { return queued_high_water_.load(); }
  void ResetQueuedFramesHighWater() { queued_high_water_.store(0); }

 private:
  class StreamReactor;

  // Who makes a call: its admission key and shares, its tenant (null without tokens) and the
  // stream defaults with the tenant's pixel limit.
  struct Caller {
    Admission::Client client;
    std::shared_ptr<const Tenant> tenant;
    std::shared_ptr<const StreamSettings> defaults;
    // "ipv4:10.0.0.1:40123" or "ipv4:10.0.0.1:40123 (tenant fleet-a)", for logs.
    std::string label;
    // The worker pool's key of the client (its admission key): fairness is per client, however
    // many connections it spreads its calls over.
    std::uint64_t fair_key = 0;
  };
  // UNAUTHENTICATED when tokens are required and the call has no valid one (counted).
  absl::StatusOr<Caller> Identify(grpc::CallbackServerContext* context);
  // RESOURCE_EXHAUSTED naming the tenant's limit when the frame has more pixels than it allows.
  static absl::Status CheckTenantPixels(const Caller& caller, const v1::Frame& frame);

  // The client a trusted proxy's x-forwarded-for names (its last entry), as an admission key
  // ("ipv4:10.1.2.3"); empty when the call is not from a trusted proxy or names no address.
  std::string ForwardedClient(grpc::CallbackServerContext* context,
                              const std::string& peer_host) const;
  // A frame's memory, checked and charged before anything is decoded: RESOURCE_EXHAUSTED naming
  // --work-memory-mb when it can never be processed, or --memory-budget-mb when the frames held
  // fill the budget; otherwise `charged` gets what was taken from the budget (the request's bytes
  // and the frame's decoded images). A frame over the image limits (--max-side, --max-pixels),
  // which the worker refuses naming the field before it decodes anything, is charged its bytes
  // only and its `cost` zeroed.
  absl::Status ChargeFrame(std::size_t request_bytes, FrameMemoryCost* cost,
                           std::uint64_t* charged);
  // When the server is full: ends the stream that has been quiet longest (no frame for
  // --shed-quiet-after or more) of the client holding the most streams, not `newcomer`'s; true
  // if one was ended (its place is free).
  bool ShedQuietStream(const Caller& newcomer);
  // Finishes a Process call refused for memory after --refusal-delay, holding one of the client's
  // Process places meanwhile (at once when it has none left, or the server drains).
  void RefuseLater(grpc::ServerUnaryReactor* reactor, const Admission::Client& client,
                   grpc::Status status);
  // A per-call log line, within --log-calls-per-second (says how many were left out before it).
  template <typename... Args>
  void LogCall(spdlog::level::level_enum level, spdlog::format_string_t<Args...> format,
               Args&&... args);

  void NoteQueued(std::uint32_t held);
  void ProcessCallDone();
  absl::Status MemoryExhausted(std::size_t bytes) const;
  void Register(StreamReactor* stream);
  void Unregister(StreamReactor* stream);
  void Housekeeping();

  const ServerOptions options_;
  MemoryBudget memory_;
  Admission admission_;
  const std::shared_ptr<const StreamSettings> default_settings_;
  Metrics* const metrics_;
  // Before pool_: the workers use it until the pool is stopped.
  FrameRunner runner_;
  WorkerPool pool_;

  std::vector<std::string> trusted_proxies_;  // as PeerHost gives them ("ipv4:127.0.0.1")
  LogLimiter call_log_;
  // After admission_ and metrics_, which its actions use: it is destroyed (and runs what is left)
  // before them.
  DelayedActions delayed_;

  std::mutex tenants_mu_;
  std::shared_ptr<const TenantDirectory> tenants_;  // under tenants_mu_

  std::atomic<bool> draining_{false};
  std::atomic<int> active_process_calls_{0};
  std::atomic<std::uint64_t> next_call_key_{1};  // the worker pool's key of each call
  std::atomic<std::uint32_t> queued_high_water_{0};

  // Open streams, for the idle check and draining. Lock order: streams_mu_, then a stream's own.
  std::mutex streams_mu_;
  std::condition_variable streams_cv_;
  std::set<StreamReactor*> streams_;
  bool stop_housekeeping_ = false;
  std::thread housekeeping_;
  std::once_flag stop_once_;
};

}  // namespace cloudcast::server
