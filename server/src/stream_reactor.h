// One Stream call: gRPC's op sequencing around the stream's StreamQueue (the delivery policy,
// stream_queue.h) and its StreamLifecycle (the one state it is in, stream_lifecycle.h). The call
// was admitted before the reactor exists (CallAdmitter::AdmitCall); each frame it reads is
// admitted by CallAdmitter::AdmitFrame and then runs on the worker pool.
//
// Lifetime: the reactor counts references: one for gRPC (dropped in OnDone), one per frame in
// the worker pool, one per OpenStreams snapshot that holds it. The last Unref deletes it, so a
// worker can still touch its stream after gRPC is done with the call.
//
// Locking: mu_ guards the state. Every decision to call StartRead / StartWrite / Finish /
// TryCancel is taken under mu_; the calls themselves are made after mu_ is released, under
// ops_mu_, which is taken before mu_ is let go. So the calls reach gRPC in the order they were
// decided and none comes after Finish. (Reactions are not run inline by gRPC for non-inlineable
// reactors, so holding ops_mu_ across the calls cannot deadlock.)
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "call_admitter.h"
#include "call_log.h"
#include "cloudcast/server/options.h"
#include "frame_processor.h"
#include "metrics.h"
#include "open_streams.h"
#include "stream_lifecycle.h"
#include "stream_queue.h"
#include "video_input.h"
#include "worker_pool.h"

namespace cloudcast::server {

// Wakes whoever waits for the calls to settle (CloudCastService::WaitForCalls, at shutdown): a
// call state it checks changed. Notify after the change; WaitUntil checks `settled` under the
// lock Notify takes, so no change is missed. Thread-safe.
class CallsChanged {
 public:
  void Notify() {
    { std::lock_guard<std::mutex> lock(mu_); }
    cv_.notify_all();
  }
  template <typename Settled>
  bool WaitUntil(std::chrono::steady_clock::time_point deadline, Settled settled) {
    std::unique_lock<std::mutex> lock(mu_);
    return cv_.wait_until(lock, deadline, settled);
  }

 private:
  std::mutex mu_;
  std::condition_variable cv_;
};

// What a stream uses of the service; all of it outlives every stream.
struct StreamServices {
  const ServerOptions* options;
  Metrics* metrics;
  CallAdmitter* admitter;
  FrameRunner* runner;
  WorkerPool* pool;
  OpenStreams* streams;
  CallLog* log;
  CallsChanged* calls_changed;  // told when a stream is abandoned or done
};

class StreamReactor final : public grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer> {
 public:
  StreamReactor(const StreamServices& services, grpc::CallbackServerContext* context,
                AdmittedCall call);

  void OnReadDone(bool ok) override;
  void OnWriteDone(bool ok) override;
  void OnCancel() override;
  void OnDone() override;

  void Ref() { refs_.fetch_add(1, std::memory_order_relaxed); }
  void Unref() {
    if (refs_.fetch_sub(1, std::memory_order_acq_rel) == 1) delete this;
  }

  // Ends the stream if nothing moved on it for the idle timeout (housekeeping).
  void CheckIdle(std::chrono::steady_clock::time_point now);
  // Stops reading; the frames already held are answered, then the stream ends (UNAVAILABLE). A
  // read already started is answered too, and waited for until StopAwaitingRead: its client sent
  // that message before it could know of the drain.
  void BeginDrain();
  void StopAwaitingRead();
  // How long the stream has sent no frame, when it holds none either and is neither ending nor
  // closing: a stream the server may shed to make room for a new client.
  std::optional<std::chrono::steady_clock::duration> QuietFor(
      std::chrono::steady_clock::time_point now);
  // Ends the stream with `status` to free its place; false when it is ending already.
  bool Shed(grpc::Status status);
  const std::string& client() const { return caller_.client.key; }
  // Nothing more can reach the client: it cancelled the call, or a write failed.
  bool abandoned() const { return abandoned_.load(std::memory_order_acquire); }
  // Whether shutdown may stop waiting for this stream before gRPC has finished it (OnDone): it
  // is abandoned, or it has ended (its status handed to gRPC) having read nothing, so its status
  // answers nothing. A rapid reset leaves gRPC thousands of such calls to finish, seconds of
  // work on a busy machine. A stream that read messages is waited for until its status is out.
  // Takes the stream's lock; told through StreamServices::calls_changed.
  bool Settled();

 private:
  struct Job;
  struct Ops;

  ~StreamReactor() override;

  void Pump(std::unique_lock<std::mutex>& lock, bool cancel = false);
  void Break();
  void Abandon();  // without mu_
  Job* Acquire();
  void Release(Job* job);
  void DecodeVideo(Job* job);  // outside mu_
  void Accept(Job* job, std::size_t bytes);
  void AcceptFrame(Job* job, std::size_t bytes);
  void QueueError(Job* job, v1::ErrorKind kind, const absl::Status& status);
  void FillError(const absl::Status& status, v1::ErrorKind kind, std::uint64_t sequence,
                 const std::string& frame_id, v1::FrameError* error);
  void Dispatch();
  void StartWriteIfReady(Ops* ops);
  void Work(Job* job, std::size_t worker);

  const StreamServices services_;
  Admission::Ticket ticket_;  // this stream's place among the server's and its client's
  grpc::CallbackServerContext* const context_;
  const Caller caller_;
  const std::uint64_t call_key_;  // the worker pool's key of the call
  std::atomic<int> refs_{1};
  std::atomic<bool> abandoned_{false};

  std::mutex ops_mu_;  // see the file comment
  std::mutex mu_;
  StreamLifecycle lifecycle_;
  std::vector<std::unique_ptr<Job>> jobs_;  // every slot this stream ever needed
  std::vector<Job*> free_;
  std::shared_ptr<const StreamSettings> settings_;
  StreamQueue queue_;
  Job* reading_ = nullptr;
  Job* writing_ = nullptr;
  std::uint64_t messages_read_ = 0;  // none yet: --first-message-timeout applies
  std::uint64_t bytes_received_ = 0;  // request bytes read (CloudReply.stream_bytes_received)
  std::chrono::steady_clock::time_point last_activity_;
  std::chrono::steady_clock::time_point last_frame_;  // the last frame read, or the opening
  // The stream's video decoders, made at its first video picture; used by the reading path
  // only (OnReadDone, one read at a time), outside mu_.
  std::unique_ptr<VideoDecoders> video_;
};

}  // namespace cloudcast::server
