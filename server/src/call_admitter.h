// One admission path for Stream and Process, in one order:
//
//   call   the server drains?  -> UNAVAILABLE            (counted: _rejected_shutdown_total)
//          identify the caller -> UNAUTHENTICATED        (calls_unauthenticated_total)
//          take a place        -> RESOURCE_EXHAUSTED     (_rejected_limit_total; a stream first
//                                                          makes room by shedding a quiet one)
//   frame  (each frame of a stream, the frame of a Process call, once parsed)
//          the tenant's pixels -> RESOURCE_EXHAUSTED naming the tenant's limit
//          work memory, budget -> RESOURCE_EXHAUSTED naming the flag (frames_refused_total),
//                                 weighed from the frame's header before anything is decoded
//
// A call refused at a step has cost nothing of the later ones: no memory is charged for a call
// the server would not take, and a caller without a valid token has no place. Thread-safe.
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>

#include "absl/status/statusor.h"
#include "admission.h"
#include "call_log.h"
#include "caller.h"
#include "cloudcast/core/stereo.h"
#include "cloudcast/server/options.h"
#include "cloudcast/v1/cloudcast.pb.h"
#include "metrics.h"

namespace cloudcast::server {

// A frame's memory, held in the server's budget until the worker is done with it (Release, or
// destruction), and what the worker pool weighs the frame by.
class FrameCharge {
 public:
  FrameCharge() = default;
  FrameCharge(FrameCharge&& other) noexcept { *this = std::move(other); }
  FrameCharge& operator=(FrameCharge&& other) noexcept;
  ~FrameCharge() { Release(); }
  void Release();  // atomic: safe on a worker without the call's lock

  std::uint64_t pixels() const { return pixels_; }          // >= 1
  std::uint64_t work_bytes() const { return work_bytes_; }  // its work memory while it runs

 private:
  friend class CallAdmitter;
  MemoryBudget* budget_ = nullptr;
  std::uint64_t bytes_ = 0;
  std::uint64_t pixels_ = 1;
  std::uint64_t work_bytes_ = 0;
};

// A call that has its place.
struct AdmittedCall {
  Caller caller;
  Admission::Ticket ticket;  // the call's place among the server's and its client's
  std::uint64_t call_key = 0;  // the worker pool's key of the call
};

class CallAdmitter {
 public:
  // `metrics` and `log` must outlive the admitter.
  CallAdmitter(const ServerOptions& options, std::shared_ptr<const StreamSettings> defaults,
               Metrics* metrics, CallLog* log);

  // Called when the server is full: may end another client's stream to free a place; true if
  // it did.
  using MakeRoom = std::function<bool(const Caller& newcomer)>;
  // The call's steps (above); every refusal is counted in `kind`'s metric and (at a limit)
  // logged within the per-call log limit.
  absl::StatusOr<AdmittedCall> AdmitCall(Admission::Kind kind,
                                         grpc::CallbackServerContext* context,
                                         const MakeRoom& make_room = nullptr);

  // The frame's steps (above), for a frame of `request_bytes` as received, to be processed with
  // `stereo` (a stereo pair's matcher memory depends on them). A frame over the image limits
  // (--max-side, --max-pixels), which the worker refuses naming the field before it decodes
  // anything, is charged its bytes only. `for_memory`, when given, says whether a refusal was for
  // memory (a Process call answers those after --refusal-delay).
  absl::StatusOr<FrameCharge> AdmitFrame(const Caller& caller, const v1::Frame& frame,
                                         std::size_t request_bytes, const StereoParams& stereo,
                                         bool* for_memory = nullptr);

  // A video decoder's memory (video_input.h), charged from its sequence header before it is
  // opened and held while its stream lives, in the same budget as the frames in flight:
  // RESOURCE_EXHAUSTED naming the budget when it does not fit. Release gives it back.
  absl::Status ChargeVideoDecoder(std::uint64_t bytes);
  void ReleaseVideoDecoder(std::uint64_t bytes) { memory_.Give(bytes); }

  // Identification alone, for calls that hold no place (GetInfo).
  absl::StatusOr<Caller> Identify(grpc::CallbackServerContext* context) {
    return callers_.Identify(context);
  }
  void SetTenants(std::shared_ptr<const TenantDirectory> tenants) {
    callers_.SetTenants(std::move(tenants));
  }

  // From now on every call is refused UNAVAILABLE.
  void StartDraining() { draining_.store(true); }
  bool draining() const { return draining_.load(); }

  std::uint32_t open(Admission::Kind kind) const { return admission_.open(kind); }

 private:
  absl::Status MemoryExhausted(std::uint64_t bytes) const;

  const ServerOptions& options_;
  Metrics* const metrics_;
  CallLog* const log_;
  CallerIdentifier callers_;
  Admission admission_;
  MemoryBudget memory_;
  std::atomic<bool> draining_{false};
  std::atomic<std::uint64_t> next_call_key_{1};
};

}  // namespace cloudcast::server
