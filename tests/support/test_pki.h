// Certificates for the security tests, made at test time with the openssl command-line tool into
// the test's own folder: certificate authorities, and server or client certificates they sign.
// EC P-256 keys (fast to make), valid for two days; server certificates name localhost and
// 127.0.0.1.
//
//   TestPki pki(dir);
//   ASSERT_TRUE(pki.MakeCa("ca"));
//   ASSERT_TRUE(pki.MakeLeaf("ca", "server", TestPki::kServer));
//   options.tls_cert_file = pki.Cert("server");  // dir/server.pem, dir/server.key
#pragma once

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <string>

namespace cloudcast::testing {

class TestPki {
 public:
  enum Usage { kServer, kClient };

  explicit TestPki(std::string dir) : dir_(std::move(dir)) {}

  std::string Cert(const std::string& name) const { return dir_ + "/" + name + ".pem"; }
  std::string Key(const std::string& name) const { return dir_ + "/" + name + ".key"; }

  // A self-signed CA: Cert(name), Key(name).
  bool MakeCa(const std::string& name) {
    return Run(
        "req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 2"
        " -subj /CN=cloudcast-test-" +
        name + " -keyout " + Key(name) + " -out " + Cert(name) +
        " -addext basicConstraints=critical,CA:TRUE"
        " -addext keyUsage=critical,keyCertSign,cRLSign");
  }

  // A certificate for `name` signed by CA `ca`, with serial `serial`.
  bool MakeLeaf(const std::string& ca, const std::string& name, Usage usage, int serial = 1) {
    const std::string ext = dir_ + "/" + name + ".ext", csr = dir_ + "/" + name + ".csr";
    {
      std::ofstream out(ext);
      out << "basicConstraints=CA:FALSE\n";
      if (usage == kServer) {
        out << "subjectAltName=DNS:localhost,IP:127.0.0.1\nextendedKeyUsage=serverAuth\n";
      } else {
        out << "extendedKeyUsage=clientAuth\n";
      }
    }
    return Run("req -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -subj /CN=" + name +
               " -keyout " + Key(name) + " -out " + csr) &&
           Run("x509 -req -in " + csr + " -CA " + Cert(ca) + " -CAkey " + Key(ca) +
               " -set_serial " + std::to_string(serial) + " -days 2 -extfile " + ext + " -out " +
               Cert(name));
  }

 private:
  bool Run(const std::string& args) {
    const std::string command = "openssl " + args + " >>" + dir_ + "/openssl.log 2>&1";
    const bool ok = std::system(command.c_str()) == 0;
    EXPECT_TRUE(ok) << command << " (see " << dir_ << "/openssl.log)";
    return ok;
  }

  const std::string dir_;
};

}  // namespace cloudcast::testing
