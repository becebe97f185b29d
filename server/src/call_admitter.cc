#include "call_admitter.h"

#include <algorithm>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "frame_input.h"

namespace cloudcast::server {

FrameCharge& FrameCharge::operator=(FrameCharge&& other) noexcept {
  if (this != &other) {
    Release();
    budget_ = std::exchange(other.budget_, nullptr);
    bytes_ = std::exchange(other.bytes_, 0);
    pixels_ = other.pixels_;
    work_bytes_ = other.work_bytes_;
  }
  return *this;
}

void FrameCharge::Release() {
  if (budget_ != nullptr) std::exchange(budget_, nullptr)->Give(std::exchange(bytes_, 0));
}

CallAdmitter::CallAdmitter(const ServerOptions& options,
                           std::shared_ptr<const StreamSettings> defaults, Metrics* metrics,
                           CallLog* log)
    : options_(options),
      metrics_(metrics),
      log_(log),
      callers_(options, std::move(defaults), metrics),
      admission_(Admission::Limits{options.max_streams, options.ResolvedMaxStreamsPerClient(),
                                   options.max_streams, options.ResolvedMaxProcessPerClient()}),
      memory_(options.memory_budget_bytes) {}

absl::StatusOr<AdmittedCall> CallAdmitter::AdmitCall(Admission::Kind kind,
                                                     grpc::CallbackServerContext* context,
                                                     const MakeRoom& make_room) {
  const bool stream = kind == Admission::Kind::kStream;
  if (draining_.load()) {
    (stream ? metrics_->streams_rejected_shutdown : metrics_->process_rejected_shutdown)
        .Increment();
    return absl::UnavailableError("the server is shutting down");
  }
  // Before anything is parsed or held: a caller without a valid token costs nothing more.
  auto caller = callers_.Identify(context);
  if (!caller.ok()) return caller.status();
  Admission::Refusal refusal;
  auto ticket = admission_.Admit(kind, caller->client, &refusal);
  // A full server makes room for a new client by ending a stream that sends nothing.
  if (!ticket.ok() && refusal == Admission::Refusal::kServerFull && make_room &&
      make_room(*caller)) {
    ticket = admission_.Admit(kind, caller->client, &refusal);
  }
  if (!ticket.ok()) {
    (stream ? metrics_->streams_rejected_limit : metrics_->process_rejected_limit).Increment();
    log_->Log(spdlog::level::warn, "{} from {} refused: {}", stream ? "stream" : "Process call",
              caller->label, std::string(ticket.status().message()));
    return ticket.status();
  }
  return AdmittedCall{*std::move(caller), *std::move(ticket), next_call_key_.fetch_add(1)};
}

absl::StatusOr<FrameCharge> CallAdmitter::AdmitFrame(const Caller& caller, const v1::Frame& frame,
                                                     std::size_t request_bytes,
                                                     const StereoParams& stereo,
                                                     bool* for_memory) {
  bool ignored;
  if (for_memory == nullptr) for_memory = &ignored;
  *for_memory = false;
  if (absl::Status s = caller.CheckTenantPixels(frame); !s.ok()) return s;
  FrameMemoryCost cost = EstimateFrameMemory(frame, stereo);
  const Limits& limits = options_.limits;
  if (cost.pixels > limits.max_pixels || cost.max_side > limits.max_side) {
    cost.decoded_bytes = cost.work_bytes = 0;
  }
  *for_memory = true;
  if (cost.work_bytes > options_.work_memory_bytes) {
    metrics_->frames_refused_work_memory.Increment();
    return absl::ResourceExhaustedError(absl::StrCat(
        "frame: ", cost.pixels, " pixels need about ", cost.work_bytes >> 20,
        " MB to process (the decoded images and the pipeline's working memory, estimated from "
        "the frame's header before decoding), more than the server's work memory of ",
        options_.work_memory_bytes >> 20, " MB (--work-memory-mb); send smaller frames"));
  }
  // Held until a worker is done with it: the request as received, and what it decodes to.
  const std::uint64_t bytes = request_bytes + cost.decoded_bytes;
  if (!memory_.TryTake(bytes)) {
    metrics_->frames_refused_memory_budget.Increment();
    return MemoryExhausted(bytes);
  }
  *for_memory = false;
  FrameCharge charge;
  charge.budget_ = &memory_;
  charge.bytes_ = bytes;
  charge.pixels_ = std::max<std::uint64_t>(cost.pixels, 1);
  charge.work_bytes_ = cost.work_bytes;
  return charge;
}

absl::Status CallAdmitter::ChargeVideoDecoder(std::uint64_t bytes) {
  if (memory_.TryTake(bytes)) return absl::OkStatus();
  metrics_->frames_refused_memory_budget.Increment();
  return absl::ResourceExhaustedError(absl::StrCat(
      "the server's memory budget (", memory_.held() >> 20, " of ", memory_.limit() >> 20,
      " MB in use, --memory-budget-mb) cannot hold this video bitstream's decoder: ", bytes,
      " bytes for the picture size its sequence header states; not decoded, send an IDR later"));
}

absl::Status CallAdmitter::MemoryExhausted(std::uint64_t bytes) const {
  return absl::ResourceExhaustedError(absl::StrCat(
      "the server's memory budget for frames in flight is in use (", memory_.held() >> 20, " of ",
      memory_.limit() >> 20, " MB, --memory-budget-mb): this frame of ", bytes,
      " bytes was not processed; send it again later"));
}

}  // namespace cloudcast::server
