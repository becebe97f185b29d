#include "cloudcast/cli/connection_flags.h"

#include "absl/strings/str_cat.h"

namespace cloudcast::cli {

ConnectionFlags::ConnectionFlags(CLI::App& app, const std::string& group) {
  app.add_flag("--tls", tls_,
               "Connect with TLS, trusting the system's CAs (implied by every --tls-* flag). "
               "Default: plaintext")
      ->group(group);
  app.add_option("--tls-ca", ca_file_,
                 "TLS: trust only the CA certificates in this PEM file for the server's "
                 "certificate")
      ->group(group);
  app.add_option("--tls-cert", cert_file_,
                 "Mutual TLS: this client's PEM certificate chain, sent to a server that "
                 "requires one (with --tls-key)")
      ->group(group);
  app.add_option("--tls-key", key_file_, "Mutual TLS: the PEM private key of --tls-cert")
      ->group(group);
  app.add_option("--tls-server-name", server_name_,
                 "TLS: the name the server's certificate must carry, when --server is an "
                 "address or a name the certificate does not list")
      ->group(group);
  app.add_option("--token-file", token_file_,
                 "Send the bearer token in this file ('authorization: Bearer <token>') with "
                 "every call; a file, so that the token does not show in ps or shell history")
      ->check(CLI::ExistingFile)
      ->group(group);
}

absl::StatusOr<client::ChannelSecurity> ConnectionFlags::Security() const {
  using client::PemKind;
  client::ChannelSecurity security;
  const auto read = [](const std::string& path, PemKind kind, const char* flag,
                       std::string* out) -> absl::Status {
    if (path.empty()) return absl::OkStatus();
    auto pem = client::ReadPemFile(path, kind);
    if (!pem.ok())
      return absl::InvalidArgumentError(absl::StrCat(flag, ": ", pem.status().message()));
    *out = *std::move(pem);
    return absl::OkStatus();
  };
  if (tls_ || !ca_file_.empty() || !cert_file_.empty() || !key_file_.empty() ||
      !server_name_.empty()) {
    if (cert_file_.empty() != key_file_.empty()) {
      return absl::InvalidArgumentError(
          cert_file_.empty() ? "--tls-key needs --tls-cert (the certificate it belongs to)"
                             : "--tls-cert needs --tls-key (its private key)");
    }
    client::TlsOptions tls;
    tls.server_name = server_name_;
    if (auto s = read(ca_file_, PemKind::kCertificate, "--tls-ca", &tls.root_ca_pem); !s.ok()) {
      return s;
    }
    if (auto s = read(cert_file_, PemKind::kCertificate, "--tls-cert", &tls.cert_chain_pem);
        !s.ok()) {
      return s;
    }
    if (auto s = read(key_file_, PemKind::kPrivateKey, "--tls-key", &tls.private_key_pem);
        !s.ok()) {
      return s;
    }
    security.tls = std::move(tls);
  }
  if (!token_file_.empty()) {
    auto token = client::ReadTokenFile(token_file_);
    if (!token.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("--token-file: ", token.status().message()));
    }
    security.bearer_token = *std::move(token);
  }
  return security;
}

}  // namespace cloudcast::cli
