#include "process_call.h"

#include <utility>

#include "call_helpers.h"

namespace cloudcast::server {
namespace {

constexpr char kProcessMethod[] = "/cloudcast.v1.CloudCast/Process";

// Ends a call at once.
class EndedCall final : public grpc::ServerGenericBidiReactor {
 public:
  explicit EndedCall(grpc::Status status) { Finish(std::move(status)); }
  void OnDone() override { delete this; }
};

}  // namespace

ProcessCall::ProcessCall(const ProcessCallServices& services, grpc::CallbackServerContext* context)
    : services_(services) {
  // Every member is written and read under mu_ (the destructor runs after OnDone takes it): gRPC
  // orders the reactions through its own uninstrumented locks, which TSan cannot see.
  std::unique_lock<std::mutex> lock(mu_);
  auto admitted = services_.admitter->AdmitCall(Admission::Kind::kProcess, context);
  if (!admitted.ok()) {
    lock.unlock();
    Finish(ToGrpc(admitted.status()));
    return;
  }
  admitted_ = *std::move(admitted);
  client_ = admitted_.caller.fair_key;
  // Held while reserving: a grant arriving from another thread waits until the state is set.
  waiter_ = services_.reads->Reserve(client_, services_.read_reservation,
                                     [this] { StartReading(); });
  const bool granted = waiter_ == ReadBudget::kGranted;
  state_ = granted ? State::kReading : State::kWaitingForBudget;
  lock.unlock();
  if (granted) StartRead(&request_);
}

void ProcessCall::StartReading() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (state_ != State::kWaitingForBudget) return;
    state_ = State::kReading;
  }
  StartRead(&request_);
}

void ProcessCall::OnReadDone(bool ok) {
  AdmittedCall admitted;
  std::uint64_t client = 0;
  {
    std::lock_guard<std::mutex> lock(mu_);
    state_ = State::kRead;
    admitted = std::move(admitted_);
    client = client_;
  }
  // The message is whole (or will never be): its bytes are now the frame's, charged by the
  // frame admission like any frame's.
  services_.reads->Release(client, services_.read_reservation);
  if (!ok) {
    // Cancelled, or the client half-closed without a request.
    admitted.ticket.Release();
    // The whole request is what is missing: the empty field path, as for one that does not parse.
    Finish(RequestError(absl::InvalidArgumentError(
                            "the Process call ended before its ProcessRequest arrived"),
                        ""));
    return;
  }
  const Arrival arrival{Clock::now(), UnixNanos()};
  services_.serve(this, std::move(admitted), request_, arrival);
}

void ProcessCall::OnCancel() {
  bool withdrawn = false;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (state_ == State::kWaitingForBudget) {
      // Not granted yet: it never will be. Granted meanwhile: its read starts and fails.
      withdrawn = services_.reads->Cancel(client_, waiter_);
      if (withdrawn) {
        state_ = State::kEnded;
        admitted_.ticket.Release();
      }
    }
  }
  if (withdrawn) Finish(grpc::Status(grpc::StatusCode::CANCELLED, "cancelled"));
}

void ProcessCall::OnDone() {
  { std::lock_guard<std::mutex> lock(mu_); }  // after every reaction's writes (see the constructor)
  delete this;
}

std::size_t ProcessCall::Reply(const google::protobuf::Message& reply) {
  Serialize(reply, &reply_);
  const std::size_t bytes = reply_.Length();
  StartWriteAndFinish(&reply_, grpc::WriteOptions(), grpc::Status::OK);
  return bytes;
}

grpc::ServerGenericBidiReactor* ProcessService::CreateReactor(
    grpc::GenericCallbackServerContext* context) {
  if (context->method() != kProcessMethod) {
    return new EndedCall(grpc::Status(grpc::StatusCode::UNIMPLEMENTED, ""));
  }
  return new ProcessCall(services_, context);
}

}  // namespace cloudcast::server
