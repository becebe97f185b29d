// A gRPC health check (grpc.health.v1.Health/Check) of one target, for container HEALTHCHECKs and
// scripts waiting for a replica: the request and reply are encoded by hand (two tiny messages),
// so no health proto needs generating.
#pragma once

#include <chrono>
#include <string>

#include "absl/status/status.h"
#include "cloudcast/client/security.h"

namespace cloudcast::load {

// OK when `target` answers SERVING for `service` within `timeout`; otherwise UNAVAILABLE (or the
// call's own error) with a message naming the target and what it answered.
// `security`: TLS as for the streams (the health service needs no token).
absl::Status ProbeHealth(const std::string& target, const std::string& service,
                         std::chrono::milliseconds timeout,
                         const client::ChannelSecurity& security = {});

}  // namespace cloudcast::load
