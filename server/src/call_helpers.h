// Small pieces every call uses: the clocks replies are stamped with, the status of bytes that do
// not parse, absl to gRPC statuses, and serializing a reply into gRPC's bytes.
#pragma once

#include <grpcpp/grpcpp.h>
#include <grpcpp/impl/codegen/proto_utils.h>  // SerializationTraits for protobuf messages

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <string>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace cloudcast::server {

using Clock = std::chrono::steady_clock;

inline std::int64_t UnixNanos() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

inline double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

// `what`: the message the bytes should have been ("StreamRequest").
inline grpc::Status Unparsable(const char* what, std::size_t bytes) {
  return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                      absl::StrCat("the request could not be parsed as a cloudcast.v1.", what, " (",
                                   bytes, " bytes): not a valid protobuf message"));
}

inline grpc::Status ToGrpc(const absl::Status& s) {
  // absl and gRPC share the canonical code numbers.
  return grpc::Status(static_cast<grpc::StatusCode>(s.code()), std::string(s.message()));
}

// Serializes a reply for gRPC (the raw methods own their bytes); false only on a message too
// large for protobuf (2 GB).
inline bool Serialize(const google::protobuf::Message& message, grpc::ByteBuffer* bytes) {
  bool own_buffer;
  return grpc::SerializationTraits<google::protobuf::Message>::Serialize(message, bytes,
                                                                         &own_buffer)
      .ok();
}

}  // namespace cloudcast::server
