#include "cloudcast/load/probe.h"

#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <spdlog/fmt/fmt.h>

#include <condition_variable>
#include <mutex>
#include <vector>

namespace cloudcast::load {

absl::Status ProbeHealth(const std::string& target, const std::string& service,
                         std::chrono::milliseconds timeout,
                         const client::ChannelSecurity& security) {
  auto created = client::CreateChannel(target, security, grpc::ChannelArguments());
  if (!created.ok()) return created.status();
  std::shared_ptr<grpc::Channel> channel = *std::move(created);
  grpc::GenericStub stub(channel);
  // HealthCheckRequest { string service = 1; }
  std::string request(1, static_cast<char>((1 << 3) | 2));
  request += static_cast<char>(service.size());  // service names are short (< 128 bytes)
  request += service;
  grpc::Slice slice(request.data(), request.size());
  grpc::ByteBuffer in(&slice, 1), out;
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + timeout);
  context.set_wait_for_ready(true);  // a replica still starting is waited for, up to the deadline
  std::mutex mu;
  std::condition_variable cv;
  bool done = false;
  grpc::Status status;
  stub.UnaryCall(&context, "/grpc.health.v1.Health/Check", grpc::StubOptions(), &in, &out,
                 [&](grpc::Status s) {
                   std::lock_guard<std::mutex> lock(mu);
                   status = std::move(s);
                   done = true;
                   cv.notify_all();
                 });
  {
    std::unique_lock<std::mutex> lock(mu);
    cv.wait(lock, [&] { return done; });
  }
  if (!status.ok()) {
    return absl::UnavailableError(fmt::format("{}: health check of '{}' failed: {} {}", target,
                                              service, static_cast<int>(status.error_code()),
                                              status.error_message()));
  }
  // HealthCheckResponse { ServingStatus status = 1; } with SERVING = 1; an absent field is 0.
  std::vector<grpc::Slice> slices;
  out.Dump(&slices);
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
