// The connection flags of every program that connects to a cloudcast server (cloudcast-client,
// cloudcast-load): TLS, a client certificate for mutual TLS, and the bearer token, defined once.
//
//   CLI::App app;
//   cloudcast::cli::ConnectionFlags connection(app);
//   app.parse(argc, argv);
//   auto security = connection.Security();  // reads the files; errors name the flag
//   if (!security.ok()) return Usage(security.status());
//   options.security = *security;           // client::ClientOptions, or load::FleetOptions
#pragma once

#include <CLI/CLI.hpp>
#include <string>

#include "absl/status/statusor.h"
#include "cloudcast/client/security.h"

namespace cloudcast::cli {

class ConnectionFlags {
 public:
  // Registers --tls, --tls-ca, --tls-cert, --tls-key, --tls-server-name and --token-file on
  // `app` (which must outlive this object), in the --help group `group`.
  explicit ConnectionFlags(CLI::App& app, const std::string& group = "Connection security");
  ConnectionFlags(const ConnectionFlags&) = delete;
  ConnectionFlags& operator=(const ConnectionFlags&) = delete;

  // After parsing: the files read into a ChannelSecurity (TLS when any TLS flag was given).
  // Errors (INVALID_ARGUMENT) name the flag and the file.
  absl::StatusOr<client::ChannelSecurity> Security() const;

 private:
  bool tls_ = false;
  std::string ca_file_;
  std::string cert_file_;
  std::string key_file_;
  std::string server_name_;
  std::string token_file_;
};

}  // namespace cloudcast::cli
