#include "cloudcast/load/probe.h"

#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <spdlog/fmt/fmt.h>

#include <vector>

namespace cloudcast::load {

absl::Status ProbeHealth(const std::string& target, const std::string& service,
                         std::chrono::milliseconds timeout,
                         const client::ChannelSecurity& security) {
  auto created = client::CreateChannel(target, security, grpc::ChannelArguments());
  if (!created.ok()) return created.status();
  std::shared_ptr<grpc::Channel> channel = *std::move(created);
  // HealthCheckRequest { string service = 1; }
  std::string request(1, static_cast<char>((1 << 3) | 2));
  request += static_cast<char>(service.size());  // service names are short (< 128 bytes)
  request += service;
  grpc::Slice slice(request.data(), request.size());
  grpc::ByteBuffer in(&slice, 1), out;
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + timeout);
  context.set_wait_for_ready(true);  // a replica still starting is waited for, up to the deadline
  // A generic call on a completion queue of this function's own, waited for here: everything
  // the call touches (context, buffers, queue) outlives it, and no gRPC thread is involved.
  grpc::CompletionQueue cq;
  grpc::GenericStub stub(channel);
  std::unique_ptr<grpc::GenericClientAsyncResponseReader> call =
      stub.PrepareUnaryCall(&context, "/grpc.health.v1.Health/Check", in, &cq);
  grpc::Status status;
  call->StartCall();
  int tag = 1;
  call->Finish(&out, &status, &tag);
  void* got = nullptr;
  bool ok = false;
  if (!cq.Next(&got, &ok) || got != &tag || !ok) {
    status = grpc::Status(grpc::StatusCode::INTERNAL, "the health check did not complete");
  }
  cq.Shutdown();
  while (cq.Next(&got, &ok)) {
  }
  if (!status.ok()) {
    return absl::UnavailableError(fmt::format("{}: health check of '{}' failed: {} {}", target,
                                              service, static_cast<int>(status.error_code()),
                                              status.error_message()));
  }
  // HealthCheckResponse { ServingStatus status = 1; } with SERVING = 1; an absent field is 0.
  std::vector<grpc::Slice> slices;
  if (!out.Dump(&slices).ok()) slices.clear();
  std::string bytes;
  for (const auto& s : slices) bytes.append(reinterpret_cast<const char*>(s.begin()), s.size());
  int serving = 0;
  if (bytes.size() >= 2 && bytes[0] == static_cast<char>(1 << 3)) serving = bytes[1];
  if (serving != 1) {
    static const char* const kNames[] = {"UNKNOWN", "SERVING", "NOT_SERVING", "SERVICE_UNKNOWN"};
    return absl::UnavailableError(
        fmt::format("{}: '{}' is {}", target, service,
                    serving >= 0 && serving <= 3 ? kNames[serving] : "UNKNOWN"));
  }
  return absl::OkStatus();
}

}  // namespace cloudcast::load
