// Bearer tokens and the tenants they stand for (--tokens-file). A call carries
// "authorization: Bearer <token>"; the token names a tenant, and the tenant's limits replace the
// per-client shares: its streams, its Process calls in flight and its largest frame.
//
// The file is JSON (see README, "Security"):
//
//   {"tenants": [
//     {"name": "warehouse-robots", "tokens": ["<token>", "<next token, while rotating>"],
//      "max_streams": 8, "max_process_in_flight": 2, "max_pixels": 307200}
//   ]}
//
// Only SHA-256 digests of the tokens are kept, and no message, log line or metric ever holds a
// token.
#pragma once

#include <grpcpp/grpcpp.h>

#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <unordered_map>

#include "absl/status/statusor.h"

namespace cloudcast::server {

struct Tenant {
  std::string name;
  // 0: the server's per-client share (--max-streams-per-client, --max-process-per-client) and
  // its --max-pixels.
  std::uint32_t max_streams = 0;
  std::uint32_t max_process_in_flight = 0;
  std::uint64_t max_pixels = 0;
};

class TenantDirectory {
 public:
  // Parses the file's text. `max_pixels` is the server's --max-pixels, which no tenant may
  // exceed. Errors (INVALID_ARGUMENT) start with `source` (the file name) and name the tenant and
  // key: unknown keys, missing names or tokens, tokens shorter than 16 characters or used twice.
  static absl::StatusOr<std::shared_ptr<const TenantDirectory>> Parse(std::string_view text,
                                                                      const std::string& source,
                                                                      std::uint64_t max_pixels);
  // Reads and parses `path`; errors name --tokens-file and the path.
  static absl::StatusOr<std::shared_ptr<const TenantDirectory>> Load(const std::string& path,
                                                                     std::uint64_t max_pixels);

  // The tenant whose token the call's "authorization: Bearer <token>" metadata carries, or
  // UNAUTHENTICATED (missing or malformed header, unknown token). The message never holds the
  // token.
  absl::StatusOr<std::shared_ptr<const Tenant>> Authenticate(
      const std::multimap<grpc::string_ref, grpc::string_ref>& metadata) const;
  absl::StatusOr<std::shared_ptr<const Tenant>> AuthenticateToken(std::string_view token) const;

  std::size_t tenants() const { return tenants_; }

 private:
  using Digest = std::array<unsigned char, 32>;
  struct DigestHash {
    std::size_t operator()(const Digest& d) const;
  };
  static Digest Sha256(std::string_view text);

  std::unordered_map<Digest, std::shared_ptr<const Tenant>, DigestHash> by_token_;
  std::size_t tenants_ = 0;
};

}  // namespace cloudcast::server
