// How a client proves who it talks to and who it is: TLS (optionally with a client certificate,
// for a server that runs mutual TLS) and a bearer token sent with every call. Every program that
// connects builds its channel through CreateChannel, so the rules live in one place.
//
//   cc::ClientOptions options;
//   cc::TlsFiles files;
//   files.ca_file = "ca.pem";                                   // or fill TlsOptions' PEMs
//   auto tls = cc::LoadTlsFiles(files);
//   if (!tls.ok()) return Fail(tls.status());
//   options.security.tls = *tls;
//   auto token = cc::ReadTokenFile("/run/secrets/cloudcast-token");  // not on the command line
//   if (!token.ok()) return Fail(token.status());
//   options.security.bearer_token = *token;
//   auto client = cc::Client::Connect("robot-offload:50051", options);
#pragma once

#include <grpcpp/grpcpp.h>

#include <memory>
#include <optional>
#include <string>

#include "absl/status/statusor.h"

namespace cloudcast::client {

// TLS towards the server. All PEM text, not file names (LoadTlsFiles reads files).
struct TlsOptions {
  // The CA certificates the server's certificate must chain to. Empty: gRPC's default roots
  // (the system's, or GRPC_DEFAULT_SSL_ROOTS_FILE_PATH).
  std::string root_ca_pem;
  // This client's certificate chain and its private key, for a server that requires client
  // certificates (mutual TLS). Both or neither.
  std::string cert_chain_pem;
  std::string private_key_pem;
  // The name the server's certificate must carry. Empty: the host of the target. Set it when
  // dialing an address (127.0.0.1:50051) that the certificate does not name.
  std::string server_name;
};

// The security of one channel.
struct ChannelSecurity {
  // nullopt (the default): plaintext.
  std::optional<TlsOptions> tls;
  // Sent as "authorization: Bearer <token>" with every call; empty: no token. It is sent over a
  // plaintext channel too (for a TLS-terminating proxy on the same host); anywhere else, use TLS,
  // or anyone on the path can read it.
  std::string bearer_token;
};

// File names for LoadTlsFiles; empty ones are left out.
struct TlsFiles {
  std::string ca_file;
  std::string cert_file;
  std::string key_file;
  std::string server_name;
};

// One PEM file: its text, or INVALID_ARGUMENT naming the file when it cannot be read or holds
// no PEM block of that kind.
enum class PemKind { kCertificate, kPrivateKey };
absl::StatusOr<std::string> ReadPemFile(const std::string& path, PemKind kind);

// Reads the files into TlsOptions. Errors (INVALID_ARGUMENT) name the file and what is wrong: it
// cannot be read, holds no PEM certificate (or key), or a certificate comes without its key.
absl::StatusOr<TlsOptions> LoadTlsFiles(const TlsFiles& files);

// The token in `path`: the file's text without surrounding whitespace. Errors name the file: it
// cannot be read, is empty, or holds whitespace or control characters inside the token.
absl::StatusOr<std::string> ReadTokenFile(const std::string& path);

// A channel to `target` with `security` on top of `args`: TLS credentials (or plaintext), an
// interceptor that adds the bearer token to every call, and a TCP connection of its own (never
// shared with another channel to the same target). `credentials`, when not null, is used
// instead of the TLS ones (it must not be combined with security.tls: INVALID_ARGUMENT).
absl::StatusOr<std::shared_ptr<grpc::Channel>> CreateChannel(
    const std::string& target, const ChannelSecurity& security, grpc::ChannelArguments args,
    std::shared_ptr<grpc::ChannelCredentials> credentials = nullptr);

}  // namespace cloudcast::client
