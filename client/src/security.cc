#include "cloudcast/client/security.h"

#include <grpcpp/support/client_interceptor.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>
#include <utility>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"

namespace cloudcast::client {
namespace {

absl::StatusOr<std::string> ReadFile(const std::string& path, const char* what) {
  std::ifstream file(path, std::ios::binary);
  if (!file) {
    return absl::InvalidArgumentError(
        absl::StrCat("cannot read the ", what, " file ", path, ": ", std::strerror(errno)));
  }
  std::stringstream ss;
  ss << file.rdbuf();
  return ss.str();
}

// Adds the bearer token to every call of the channel: one place, whatever stub makes the call
// (generated, generic, sync or callback).
class BearerTokenInterceptor final : public grpc::experimental::Interceptor {
 public:
  explicit BearerTokenInterceptor(const std::string* header) : header_(header) {}
  void Intercept(grpc::experimental::InterceptorBatchMethods* methods) override {
    if (methods->QueryInterceptionHookPoint(
            grpc::experimental::InterceptionHookPoints::PRE_SEND_INITIAL_METADATA)) {
      methods->GetSendInitialMetadata()->emplace("authorization", *header_);
    }
    methods->Proceed();
  }

 private:
  const std::string* header_;
};

class BearerTokenInterceptorFactory final
    : public grpc::experimental::ClientInterceptorFactoryInterface {
 public:
  explicit BearerTokenInterceptorFactory(const std::string& token)
      : header_(absl::StrCat("Bearer ", token)) {}
  grpc::experimental::Interceptor* CreateClientInterceptor(
      grpc::experimental::ClientRpcInfo* /*info*/) override {
    return new BearerTokenInterceptor(&header_);
  }

 private:
  const std::string header_;  // lives as long as the channel
};

}  // namespace

absl::StatusOr<std::string> ReadPemFile(const std::string& path, PemKind kind) {
  const bool cert = kind == PemKind::kCertificate;
  auto pem = ReadFile(path, cert ? "certificate" : "private key");
  if (!pem.ok()) return pem.status();
  if (!absl::StrContains(*pem, cert ? "-----BEGIN CERTIFICATE-----" : "PRIVATE KEY-----")) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, " holds no PEM ", cert ? "certificate" : "private key"));
  }
  return pem;
}

absl::StatusOr<TlsOptions> LoadTlsFiles(const TlsFiles& files) {
  TlsOptions tls;
  tls.server_name = files.server_name;
  if (files.cert_file.empty() != files.key_file.empty()) {
    return absl::InvalidArgumentError(
        "a client certificate needs its private key, and a key its certificate: give both");
  }
  if (!files.ca_file.empty()) {
    auto ca = ReadPemFile(files.ca_file, PemKind::kCertificate);
    if (!ca.ok()) return ca.status();
    tls.root_ca_pem = *std::move(ca);
  }
  if (!files.cert_file.empty()) {
    auto cert = ReadPemFile(files.cert_file, PemKind::kCertificate);
    if (!cert.ok()) return cert.status();
    auto key = ReadPemFile(files.key_file, PemKind::kPrivateKey);
    if (!key.ok()) return key.status();
    tls.cert_chain_pem = *std::move(cert);
    tls.private_key_pem = *std::move(key);
  }
  return tls;
}

absl::StatusOr<std::string> ReadTokenFile(const std::string& path) {
  auto text = ReadFile(path, "token");
  if (!text.ok()) return text.status();
  const std::string token(absl::StripAsciiWhitespace(*text));
  // The token itself is never part of a message.
  if (token.empty())
    return absl::InvalidArgumentError(absl::StrCat("the token file ", path, " is empty"));
  for (char c : token) {
    if (static_cast<unsigned char>(c) <= ' ' || c == 0x7f) {
      return absl::InvalidArgumentError(absl::StrCat(
          "the token file ", path,
          " holds whitespace or control characters inside the token; it must hold one token"));
    }
  }
  return token;
}

absl::StatusOr<std::shared_ptr<grpc::Channel>> CreateChannel(
    const std::string& target, const ChannelSecurity& security, grpc::ChannelArguments args,
    std::shared_ptr<grpc::ChannelCredentials> credentials) {
  if (credentials != nullptr && security.tls.has_value()) {
    return absl::InvalidArgumentError(
        "give either ready-made channel credentials or TLS options, not both");
  }
  if (credentials == nullptr) {
    if (security.tls.has_value()) {
      const TlsOptions& tls = *security.tls;
      if (tls.cert_chain_pem.empty() != tls.private_key_pem.empty()) {
        return absl::InvalidArgumentError(
            "TlsOptions: cert_chain_pem and private_key_pem go together: set both or neither");
      }
      grpc::SslCredentialsOptions ssl;
      ssl.pem_root_certs = tls.root_ca_pem;
      ssl.pem_cert_chain = tls.cert_chain_pem;
      ssl.pem_private_key = tls.private_key_pem;
      credentials = grpc::SslCredentials(ssl);
      if (!tls.server_name.empty()) args.SetSslTargetNameOverride(tls.server_name);
    } else {
      credentials = grpc::InsecureChannelCredentials();
    }
  }
  // Every channel is a connection of its own. gRPC's process-wide subchannel pool would otherwise
  // put every channel to one target with the same arguments on one TCP connection: two robots
  // (Clients, or the load generator's channels) in one process would be one client to the
  // server's fair queue, and all their frames would go through one transport's reads (on 2
  // cores, 4 raw streams on one connection got a fifth fewer frames/s than on four).
  args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  std::shared_ptr<grpc::Channel> channel;
  if (security.bearer_token.empty()) {
    channel = grpc::CreateCustomChannel(target, credentials, args);
  } else {
    std::vector<std::unique_ptr<grpc::experimental::ClientInterceptorFactoryInterface>> factories;
    factories.push_back(std::make_unique<BearerTokenInterceptorFactory>(security.bearer_token));
    channel = grpc::experimental::CreateCustomChannelWithInterceptors(target, credentials, args,
                                                                      std::move(factories));
  }
  if (channel == nullptr) {
    return absl::InternalError(absl::StrCat("cannot create a gRPC channel to ", target));
  }
  return channel;
}

}  // namespace cloudcast::client
