// The server's TLS material (--tls-cert, --tls-key, --tls-client-ca), reloadable while serving.
//
// gRPC 1.51 offers two certificate providers: static data (never changes) and a file watcher
// (re-reads files on a timer, and serves no certificate at all while a file is unreadable). So
// the files are read and checked here (OpenSSL: PEM parses, the key belongs to the certificate),
// and gRPC's file watcher reads our own copy of them: a memfd, reached as /proc/self/fd/N, which
// only this process can see and which vanishes with it (no key written to disk). Reload() checks
// the new files and, only if they are good, swaps the copy in one dup2; the watcher hands it to
// new handshakes within its refresh interval (1 s). Established connections keep their session.
#pragma once

#include <grpcpp/security/server_credentials.h>
#include <grpcpp/security/tls_certificate_provider.h>

#include <ctime>
#include <memory>
#include <mutex>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace cloudcast::server {

struct TlsFiles {
  std::string cert_file;       // PEM certificate chain, leaf first (--tls-cert)
  std::string key_file;        // PEM private key of the leaf, unencrypted (--tls-key)
  std::string client_ca_file;  // PEM CAs client certificates must chain to; "" = no mTLS
};

class ServerTls {
 public:
  // Reads and checks the files. Errors (INVALID_ARGUMENT) name the flag and the file: missing,
  // unreadable, no PEM certificate or key, a key that does not belong to the certificate.
  static absl::StatusOr<std::unique_ptr<ServerTls>> Load(const TlsFiles& files);
  ~ServerTls();
  ServerTls(const ServerTls&) = delete;
  ServerTls& operator=(const ServerTls&) = delete;

  // Credentials for AddListeningPort: TLS 1.2+, and with a client CA, client certificates
  // required and verified.
  std::shared_ptr<grpc::ServerCredentials> Credentials() const { return credentials_; }
  bool mutual() const { return !files_.client_ca_file.empty(); }

  // Reads the same files again. On success new handshakes use them within about a second; on
  // error nothing changes (the old certificate stays) and the status says what was wrong.
  absl::Status Reload();

  // How often gRPC's watcher looks at our copy.
  static constexpr unsigned kRefreshSeconds = 1;

 private:
  // One memfd at a fixed descriptor number, replaced whole.
  class PemCopy {
   public:
    ~PemCopy();
    absl::Status Replace(const std::string& text);
    std::string path() const;

   private:
    int fd_ = -1;
    std::time_t mtime_ = 0;
  };

  explicit ServerTls(const TlsFiles& files) : files_(files) {}

  const TlsFiles files_;
  std::mutex mu_;  // one Reload at a time
  PemCopy identity_;
  PemCopy client_ca_;
  std::shared_ptr<grpc::experimental::FileWatcherCertificateProvider> provider_;
  std::shared_ptr<grpc::ServerCredentials> credentials_;
};

}  // namespace cloudcast::server
