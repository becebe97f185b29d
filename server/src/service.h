// The CloudCast gRPC service on the callback API.
//
// Threading: gRPC's threads only move messages: they run the reactions (OnReadDone, OnWriteDone,
// ...), which check configs, queue frames and start reads and writes. Frames are processed on a
// WorkerPool of `threads` workers, each with its own FrameProcessor (a core Pipeline is not
// thread-safe). A housekeeping thread ends idle streams.
//
// Both RPCs that carry frames are admitted by one CallAdmitter (call_admitter.h: draining,
// caller, place; then per frame the tenant's pixels and memory). One StreamReactor per Stream
// call (stream_reactor.h) sequences gRPC's reads, writes and Finish around the stream's
// StreamQueue (the delivery policy) and StreamLifecycle (its one state). OpenStreams holds the
// calls open, for housekeeping, draining, shedding and shutdown.
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "admission.h"
#include "call_admitter.h"
#include "call_log.h"
#include "cloudcast/server/options.h"
#include "cloudcast/v1/cloudcast.grpc.pb.h"
#include "delayed_actions.h"
#include "frame_processor.h"
#include "metrics.h"
#include "open_streams.h"
#include "process_call.h"
#include "read_budget.h"
#include "stream_reactor.h"
#include "tenants.h"
#include "worker_pool.h"

namespace cloudcast::server {

// Stream and Process take raw bytes and parse them here, so that bytes which are not a valid
// message get a status that says so (gRPC's own parsing reports a half-close, or UNIMPLEMENTED).
// Process is a generic method, served by process_service() (ProcessCall: its read waits for the
// client's read budget).
using CallbackBase =
    v1::CloudCast::WithRawCallbackMethod_Stream<v1::CloudCast::WithGenericMethod_Process<
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
  grpc::ServerUnaryReactor* GetInfo(grpc::CallbackServerContext* context,
                                    const v1::GetInfoRequest* request,
                                    v1::ServerInfo* info) override;

  // Serves the Process method: register it with the server beside this service.
  grpc::CallbackGenericService* process_service() { return &process_service_; }

  // The bearer tokens new calls must carry (null: none needed). Calls already open keep the
  // tenant they were admitted as. Thread-safe.
  void SetTenants(std::shared_ptr<const TenantDirectory> tenants);

  // Shutdown, step 1: new Stream and Process calls get UNAVAILABLE; every open stream stops
  // reading, answers the frames it already holds and ends with UNAVAILABLE. A message a stream
  // was reading when the drain began (its client sent it before it could know) is answered too;
  // the stream waits for it at most `read_wait`.
  void StartDraining(std::chrono::milliseconds read_wait);
  bool draining() const { return admitter_.draining(); }
  // Waits until every call that can still deliver something is done, or `deadline` passes; true
  // if none is left. A Stream call is done at OnDone, or once it is settled
  // (StreamReactor::Settled: cancelled by its client, or ended having read nothing): gRPC may
  // take long to finish such calls (a rapid reset leaves thousands), and nobody waits for their
  // status. A Process call is done once it has finished.
  bool WaitForCalls(std::chrono::steady_clock::time_point deadline);
  // The calls WaitForCalls still waits for: streams, Process calls.
  std::pair<int, int> CallsInFlight();
  // Runs the frames still queued, then joins the workers and the housekeeping thread. Call once
  // the gRPC server has shut down. Idempotent.
  void StopWorkers();

  int active_streams() const {
    return static_cast<int>(admitter_.open(Admission::Kind::kStream));
  }
  int worker_threads() const { return static_cast<int>(pool_.size()); }
  // The most frames one stream held at once (waiting + in work + replies not yet written), over
  // all streams since the start or the last reset. Tests check it against max_queued_frames.
  std::uint32_t queued_frames_high_water() const { return streams_.queued_high_water(); }
  void ResetQueuedFramesHighWater() { streams_.ResetQueuedHighWater(); }

 private:
  // A Process call whose request has arrived: parsed, weighed and queued for a worker.
  void ServeProcess(ProcessCall* call, AdmittedCall admitted, const grpc::ByteBuffer& request,
                    Arrival arrival);
  // Finishes a Process call refused for memory after --refusal-delay, holding the call's place
  // meanwhile (at once while the server drains).
  void RefuseLater(ProcessCall* call, std::shared_ptr<Admission::Ticket> ticket,
                   grpc::Status status);
  void Housekeeping();
  // A Process call (or a refusal held back) begins and ends: counted for WaitForCalls.
  void ProcessStarted();
  void ProcessDone();

  const ServerOptions options_;
  const std::shared_ptr<const StreamSettings> default_settings_;
  Metrics* const metrics_;
  CallLog call_log_;
  CallAdmitter admitter_;
  // Before pool_: the workers use it until the pool is stopped.
  FrameRunner runner_;
  WorkerPool pool_;
  OpenStreams streams_;
  std::atomic<int> process_calls_{0};  // Process calls open, and refusals held back
  CallsChanged calls_changed_;
  const StreamServices stream_services_;
  ReadBudget process_reads_;
  ProcessService process_service_;
  // After admitter_ and metrics_, which its actions use: it is destroyed (and runs what is left)
  // before them.
  DelayedActions delayed_;

  // The housekeeping thread: ends idle streams, gives memory back (MemoryHousekeeping).
  std::mutex housekeeping_mu_;
  std::condition_variable housekeeping_cv_;
  bool stop_housekeeping_ = false;  // under housekeeping_mu_
  // When the drain stops waiting for the reads its streams had started (under housekeeping_mu_).
  std::optional<std::chrono::steady_clock::time_point> drain_reads_until_;
  std::thread housekeeping_;
  std::once_flag stop_once_;
};

}  // namespace cloudcast::server
