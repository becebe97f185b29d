#include "tls.h"

#include <fcntl.h>
#include <openssl/bio.h>
#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/x509.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>
#include <utility>

#include "absl/strings/str_cat.h"

namespace cloudcast::server {
namespace {

struct Pem {
  std::string identity;   // the certificate chain, then the key: one file, so one version
  std::string client_ca;  // "" without mTLS
};

absl::StatusOr<std::string> ReadFile(const std::string& path, const char* flag) {
  std::ifstream file(path, std::ios::binary);
  if (!file) {
    return absl::InvalidArgumentError(
        absl::StrCat(flag, ": cannot read ", path, ": ", std::strerror(errno)));
  }
  std::stringstream ss;
  ss << file.rdbuf();
  if (!file.good() && !file.eof()) {
    return absl::InvalidArgumentError(absl::StrCat(flag, ": cannot read ", path));
  }
  return ss.str();
}

// A passphrase callback that gives none: an encrypted key fails instead of prompting on stdin.
int NoPassphrase(char* /*buf*/, int /*size*/, int /*rwflag*/, void* /*u*/) { return 0; }

using BioPtr = std::unique_ptr<BIO, decltype(&BIO_free)>;
using X509Ptr = std::unique_ptr<X509, decltype(&X509_free)>;
using KeyPtr = std::unique_ptr<EVP_PKEY, decltype(&EVP_PKEY_free)>;

BioPtr MemBio(const std::string& text) {
  return BioPtr(BIO_new_mem_buf(text.data(), static_cast<int>(text.size())), &BIO_free);
}

// The certificates in `pem`, the first one returned; 0 when it holds none.
int CountCertificates(const std::string& pem, X509Ptr* first) {
  BioPtr bio = MemBio(pem);
  int n = 0;
  while (X509* cert = PEM_read_bio_X509(bio.get(), nullptr, NoPassphrase, nullptr)) {
    if (n++ == 0 && first != nullptr) {
      first->reset(cert);
    } else {
      X509_free(cert);
    }
  }
  ERR_clear_error();  // the loop ends on "no start line"
  return n;
}

absl::StatusOr<Pem> ReadAndCheck(const TlsFiles& files) {
  if (files.cert_file.empty() || files.key_file.empty()) {
    return absl::InvalidArgumentError(
        "--tls-cert and --tls-key go together: the certificate and its private key");
  }
  auto cert = ReadFile(files.cert_file, "--tls-cert");
  if (!cert.ok()) return cert.status();
  auto key = ReadFile(files.key_file, "--tls-key");
  if (!key.ok()) return key.status();
  X509Ptr leaf(nullptr, &X509_free);
  if (CountCertificates(*cert, &leaf) == 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("--tls-cert: ", files.cert_file, " holds no PEM certificate"));
  }
  BioPtr key_bio = MemBio(*key);
  KeyPtr private_key(PEM_read_bio_PrivateKey(key_bio.get(), nullptr, NoPassphrase, nullptr),
                     &EVP_PKEY_free);
  ERR_clear_error();
  if (private_key == nullptr) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--tls-key: ", files.key_file,
        " holds no PEM private key, or an encrypted one (the server needs it unencrypted)"));
  }
  if (X509_check_private_key(leaf.get(), private_key.get()) != 1) {
    ERR_clear_error();
    return absl::InvalidArgumentError(absl::StrCat("--tls-key: the key in ", files.key_file,
                                                   " does not belong to the certificate in ",
                                                   files.cert_file, " (--tls-cert)"));
  }
  Pem pem;
  pem.identity = *cert;
  if (!pem.identity.empty() && pem.identity.back() != '\n') pem.identity += '\n';
  pem.identity += *key;
  if (!files.client_ca_file.empty()) {
    auto ca = ReadFile(files.client_ca_file, "--tls-client-ca");
    if (!ca.ok()) return ca.status();
    if (CountCertificates(*ca, nullptr) == 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("--tls-client-ca: ", files.client_ca_file, " holds no PEM certificate"));
    }
    pem.client_ca = *std::move(ca);
  }
  return pem;
}

absl::Status Errno(const char* what) {
  return absl::InternalError(absl::StrCat("TLS: ", what, ": ", std::strerror(errno)));
}

}  // namespace

ServerTls::PemCopy::~PemCopy() {
  if (fd_ >= 0) close(fd_);
}

std::string ServerTls::PemCopy::path() const { return absl::StrCat("/proc/self/fd/", fd_); }

absl::Status ServerTls::PemCopy::Replace(const std::string& text) {
  const int fd = memfd_create("cloudcast-tls", MFD_CLOEXEC);
  if (fd < 0) return Errno("memfd_create");
  for (std::size_t done = 0; done < text.size();) {
    const ssize_t n = write(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      close(fd);
      return Errno("writing the certificate copy");
    }
    done += static_cast<std::size_t>(n);
  }
  // gRPC's watcher reads the key and the certificate in two passes and trusts them only if the
  // file's modification time (in seconds) did not change in between: make every version's time
  // differ from the last one's.
  mtime_ = std::max(std::time(nullptr), mtime_ + 1);
  const timespec times[2] = {{mtime_, 0}, {mtime_, 0}};
  if (futimens(fd, times) != 0) {
    close(fd);
    return Errno("futimens");
  }
  if (fd_ < 0) {
    fd_ = fd;
    return absl::OkStatus();
  }
  // One step: the watcher opens either the old copy or the new one, never a partial one.
  const int rc = dup3(fd, fd_, O_CLOEXEC);
  close(fd);
  if (rc < 0) return Errno("dup3");
  return absl::OkStatus();
}

absl::StatusOr<std::unique_ptr<ServerTls>> ServerTls::Load(const TlsFiles& files) {
  auto pem = ReadAndCheck(files);
  if (!pem.ok()) return pem.status();
  std::unique_ptr<ServerTls> tls(new ServerTls(files));
  if (auto s = tls->identity_.Replace(pem->identity); !s.ok()) return s;
  if (tls->mutual()) {
    if (auto s = tls->client_ca_.Replace(pem->client_ca); !s.ok()) return s;
  }
  const std::string identity = tls->identity_.path();
  tls->provider_ = std::make_shared<grpc::experimental::FileWatcherCertificateProvider>(
      identity, identity, tls->mutual() ? tls->client_ca_.path() : std::string(), kRefreshSeconds);
  grpc::experimental::TlsServerCredentialsOptions options(tls->provider_);
  options.watch_identity_key_cert_pairs();
  if (tls->mutual()) {
    options.watch_root_certs();
    options.set_cert_request_type(GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY);
  } else {
    options.set_cert_request_type(GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE);
  }
  tls->credentials_ = grpc::experimental::TlsServerCredentials(options);
  if (tls->credentials_ == nullptr) {
    return absl::InvalidArgumentError("--tls-cert: gRPC refused the TLS configuration");
  }
  return tls;
}

ServerTls::~ServerTls() {
  // The watcher's thread reads our copies: stop it before they close.
  credentials_.reset();
  provider_.reset();
}

absl::Status ServerTls::Reload() {
  std::lock_guard<std::mutex> lock(mu_);
  auto pem = ReadAndCheck(files_);
  if (!pem.ok()) return pem.status();
  if (mutual()) {
    if (auto s = client_ca_.Replace(pem->client_ca); !s.ok()) return s;
  }
  return identity_.Replace(pem->identity);
}

}  // namespace cloudcast::server
