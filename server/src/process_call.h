// A Process call, served as a generic call so that the service sees it at its headers, before
// its message is read (issue 30, defect 4). gRPC reads a unary method's message as soon as the
// call starts, and meanwhile opens the call's window to the length the message announces; here
// the read starts only once the client's ReadBudget has room for a whole message (read_budget.h),
// so a client's incomplete messages hold at most its share, not one message per call.
//
// On the wire nothing changes: one request message, then one reply message and OK, or a status.
#pragma once

#include <grpcpp/generic/async_generic_service.h>
#include <grpcpp/grpcpp.h>

#include <cstdint>
#include <functional>
#include <mutex>

#include "call_admitter.h"
#include "frame_processor.h"
#include "read_budget.h"

namespace cloudcast::server {

class ProcessCall;

// What a ProcessCall needs of the service.
struct ProcessCallServices {
  CallAdmitter* admitter = nullptr;
  ReadBudget* reads = nullptr;
  // What each read reserves of its client's share: --max-message-bytes, the most gRPC buffers.
  std::uint64_t read_reservation = 0;
  // Serves a call whose request has arrived whole: ends it with Reply or Fail, exactly once.
  std::function<void(ProcessCall* call, AdmittedCall admitted, const grpc::ByteBuffer& request,
                     Arrival arrival)>
      serve;
};

class ProcessCall final : public grpc::ServerGenericBidiReactor {
 public:
  // Admits the call and starts its read when its client's share has room (or waits for it).
  ProcessCall(const ProcessCallServices& services, grpc::CallbackServerContext* context);

  // The call's answer, sent with OK: the call ends (and may be gone when this returns). The
  // reply's size in bytes.
  std::size_t Reply(const google::protobuf::Message& reply);
  // The call ends with `status` (not OK).
  void Fail(grpc::Status status) { Finish(std::move(status)); }

  void OnReadDone(bool ok) override;
  void OnCancel() override;
  void OnDone() override;

 private:
  enum class State { kWaitingForBudget, kReading, kRead, kEnded };
  void StartReading();

  const ProcessCallServices& services_;
  std::mutex mu_;
  State state_ = State::kEnded;  // under mu_
  std::uint64_t waiter_ = 0;     // the ReadBudget reservation waited for, under mu_
  std::uint64_t client_ = 0;
  AdmittedCall admitted_;
  grpc::ByteBuffer request_;
  grpc::ByteBuffer reply_;
};

// The generic service that serves the Process method through ProcessCall; any other method it
// is asked for is UNIMPLEMENTED, as gRPC would answer.
class ProcessService final : public grpc::CallbackGenericService {
 public:
  explicit ProcessService(ProcessCallServices services) : services_(std::move(services)) {}
  grpc::ServerGenericBidiReactor* CreateReactor(grpc::GenericCallbackServerContext* context) override;

 private:
  const ProcessCallServices services_;
};

}  // namespace cloudcast::server
