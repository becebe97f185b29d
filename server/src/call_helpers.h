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
#include "cloudcast/proto/convert.h"

namespace cloudcast::server {

using Clock = std::chrono::steady_clock;

inline std::int64_t UnixNanos() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

inline double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

// A refusal of what the client sent, as a call status: its FieldViolation goes in the status
// details (a google.rpc.BadRequest), so that a client never parses the message. `fallback_field`:
// the field when the message does not start with one (convert::FieldViolationOf).
inline grpc::Status RequestError(const absl::Status& s, std::string_view fallback_field) {
  return grpc::Status(static_cast<grpc::StatusCode>(s.code()), std::string(s.message()),
                      convert::StatusDetails(s, fallback_field));
}

// `what`: the message the bytes should have been ("StreamRequest"). The field at fault is the
// whole request: the empty path.
inline grpc::Status Unparsable(const char* what, std::size_t bytes) {
  return RequestError(absl::InvalidArgumentError(
                          absl::StrCat("the request could not be parsed as a cloudcast.v1.", what,
                                       " (", bytes, " bytes): not a valid protobuf message")),
                      "");
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
