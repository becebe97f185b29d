// Who makes a call: the client it counts against (its peer host, the address a trusted proxy
// names, or with bearer tokens its tenant), and the tenant's limits. Stream, Process and GetInfo
// all identify their caller here (through CallAdmitter for the first two).
#pragma once

#include <grpcpp/grpcpp.h>

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "admission.h"
#include "cloudcast/server/options.h"
#include "cloudcast/v1/cloudcast.pb.h"
#include "metrics.h"
#include "tenants.h"

namespace cloudcast::server {

// Its admission key and shares, its tenant (null without tokens) and the stream defaults with
// the tenant's pixel limit.
struct Caller {
  Admission::Client client;
  std::shared_ptr<const Tenant> tenant;
  std::shared_ptr<const StreamSettings> defaults;
  // "ipv4:10.0.0.1:40123" or "ipv4:10.0.0.1:40123 (tenant fleet-a)", for logs.
  std::string label;
  // The worker pool's key of the client (its admission key): fairness is per client, however
  // many connections it spreads its calls over.
  std::uint64_t fair_key = 0;

  // RESOURCE_EXHAUSTED naming the tenant's limit when the frame has more pixels than it allows.
  absl::Status CheckTenantPixels(const v1::Frame& frame) const;
};

class CallerIdentifier {
 public:
  // `defaults`: the server's stream settings; `metrics` counts the calls refused for their token.
  CallerIdentifier(const ServerOptions& options, std::shared_ptr<const StreamSettings> defaults,
                   Metrics* metrics);

  // The bearer tokens new calls must carry (null: none needed). Calls already open keep the
  // tenant they were identified as. Thread-safe.
  void SetTenants(std::shared_ptr<const TenantDirectory> tenants);

  // UNAUTHENTICATED when tokens are required and the call has no valid one (counted, logged at
  // debug level only: a stranger must not be able to flood the log).
  absl::StatusOr<Caller> Identify(grpc::CallbackServerContext* context);

 private:
  // The client a trusted proxy's x-forwarded-for names (its last entry), as an admission key
  // ("ipv4:10.1.2.3"); empty when the call is not from a trusted proxy or names no address.
  std::string ForwardedClient(grpc::CallbackServerContext* context,
                              const std::string& peer_host) const;

  const std::uint64_t max_pixels_;  // the server's --max-pixels
  const std::shared_ptr<const StreamSettings> defaults_;
  Metrics* const metrics_;
  std::vector<std::string> trusted_proxies_;  // as PeerHost gives them ("ipv4:127.0.0.1")
  std::mutex mu_;
  std::shared_ptr<const TenantDirectory> tenants_;  // under mu_
};

}  // namespace cloudcast::server
