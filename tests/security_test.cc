// Security: TLS and mutual TLS on the gRPC port, certificate reload on SIGHUP, bearer tokens and
// tenants, health without a token, reflection switched off, and the connecting programs' flags.
// Every certificate is made here, at test time, by the openssl tool (tests/support/test_pki.h):
// two unrelated CAs, "ca" and "other".
#include "cloudcast/client/security.h"

#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "cloudcast/client/client.h"
#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/load/probe.h"
#include "cloudcast/proto/convert.h"
#include "cloudcast/server/server.h"
#include "cloudcast/testing/metrics_scrape.h"
#include "cloudcast/v1/cloudcast.grpc.pb.h"
#include "nlohmann/json.hpp"
#include "support/replica_support.h"
#include "support/test_pki.h"
#include "support/waiting.h"
#include "tenants.h"

namespace cloudcast {
namespace {

namespace cc = client;
using std::chrono::milliseconds;
using std::chrono::seconds;
using testing::TestPki;

// Tokens long enough for the tokens file (16 characters at least); never in a log or a metric.
constexpr char kFleetToken[] = "fleet-token-3f9c2a7d51e84b06";
constexpr char kSmallToken[] = "small-token-8e1b4c9f02d7a635";
constexpr char kLabToken[] = "lab-token-5d20c7e9b3a14f68";
constexpr char kWrongToken[] = "wrong-token-000000000000000000";

const SyntheticFrame& Frame() {
  static const SyntheticFrame frame = [] {
    SyntheticOptions o;
    o.width = 160;
    o.height = 120;
    return *SyntheticScene::Default().Render(o);
  }();
  return frame;
}

std::string ReadAll(const std::string& path) { return testing::ReadText(path); }

void WriteFile(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
}

// Replaces `to` by `from` in one step, as an operator's deploy tool would.
void ReplaceFile(const std::string& from, const std::string& to) {
  std::filesystem::copy_file(from, to + ".new", std::filesystem::copy_options::overwrite_existing);
  std::filesystem::rename(to + ".new", to);
}

class SecurityTest : public testing::ScratchDirTest {
 protected:
  void SetUp() override {
    ScratchDirTest::SetUp();
    pki_ = std::make_unique<TestPki>(dir_.string());
    ASSERT_TRUE(pki_->MakeCa("ca"));
    ASSERT_TRUE(pki_->MakeCa("other"));
    ASSERT_TRUE(pki_->MakeLeaf("ca", "server", TestPki::kServer));
    ASSERT_TRUE(pki_->MakeLeaf("ca", "client", TestPki::kClient, 2));
    ASSERT_TRUE(pki_->MakeLeaf("other", "stranger", TestPki::kClient, 3));
  }

  server::ServerOptions TlsOptions(bool mutual) const {
    server::ServerOptions o;
    EXPECT_TRUE(ApplyPreset("new_tsukuba", &o.defaults.frame).ok());  // frames sent camera-less
    o.listen = "127.0.0.1:0";
    o.metrics_listen = "127.0.0.1:0";
    o.tls_cert_file = pki_->Cert("server");
    o.tls_key_file = pki_->Key("server");
    if (mutual) o.tls_client_ca_file = pki_->Cert("ca");
    return o;
  }

  void Start(const server::ServerOptions& options) {
    server_.reset();
    auto s = server::Server::Start(options);
    ASSERT_TRUE(s.ok()) << s.status();
    server_ = *std::move(s);
  }

  // Client options trusting CA `ca` (empty: plaintext), with client certificate `cert` (empty:
  // none) and a bearer token. Connect does not wait: the first call tells whether it connects.
  cc::ClientOptions Options(const std::string& ca, const std::string& cert = "",
                            const std::string& token = "") const {
    cc::ClientOptions o;
    o.connect_timeout = milliseconds(0);
    o.call_timeout = seconds(30);  // only a hang guard: a refused handshake fails at once
    if (!ca.empty()) {
      cc::TlsFiles files;
      files.ca_file = pki_->Cert(ca);
      if (!cert.empty()) {
        files.cert_file = pki_->Cert(cert);
        files.key_file = pki_->Key(cert);
      }
      auto tls = cc::LoadTlsFiles(files);
      EXPECT_TRUE(tls.ok()) << tls.status();
      if (tls.ok()) o.security.tls = *tls;
    }
    o.security.bearer_token = token;
    return o;
  }

  absl::StatusOr<v1::ServerInfo> GetInfo(const std::string& address,
                                         const cc::ClientOptions& options) {
    auto client = cc::Client::Connect(address, options);
    if (!client.ok()) return client.status();
    return (*client)->GetInfo();
  }

  // Streams one frame; the cloud's point count, or the error.
  absl::StatusOr<std::size_t> StreamOneFrame(const std::string& address,
                                             const cc::ClientOptions& options) {
    auto client = cc::Client::Connect(address, options);
    if (!client.ok()) return client.status();
    auto stream = (*client)->OpenStream(cc::StreamConfig());
    if (!stream.ok()) return stream.status();
    if (auto s = (*stream)->Send(Frame().disparity_view(), Frame().colour_view()); !s.ok()) {
      // The call ended: how it ended is the answer.
      const absl::Status finished = (*stream)->Finish();
      return finished.ok() ? s : finished;
    }
    cc::Result r;
    const bool got = (*stream)->Read(&r);
    (*stream)->CloseSend().IgnoreError();
    const absl::Status finished = (*stream)->Finish();
    if (!got) return finished.ok() ? absl::InternalError("no reply") : finished;
    if (!r.ok()) return r.status;
    return r.cloud.size();
  }

  std::unique_ptr<TestPki> pki_;
  std::unique_ptr<server::Server> server_;
};

// ---------------------------------------------------------------------------------------------
// TLS and mutual TLS

TEST_F(SecurityTest, TlsClientStreamsAFrameAndGetsACloud) {
  Start(TlsOptions(/*mutual=*/false));
  auto points = StreamOneFrame(server_->address(), Options("ca"));
  ASSERT_TRUE(points.ok()) << points.status();
  EXPECT_GT(*points, 0u);
  // The server name override: "localhost" is what the certificate names besides 127.0.0.1.
  cc::ClientOptions named = Options("ca");
  named.security.tls->server_name = "localhost";
  EXPECT_TRUE(GetInfo(server_->address(), named).ok());
}

TEST_F(SecurityTest, PlaintextClientIsRefusedByATlsServer) {
  Start(TlsOptions(/*mutual=*/false));
  auto info = GetInfo(server_->address(), Options(""));
  ASSERT_FALSE(info.ok());
  EXPECT_EQ(info.status().code(), absl::StatusCode::kUnavailable) << info.status();
}

TEST_F(SecurityTest, ClientThatTrustsAnotherCaRefusesTheServer) {
  Start(TlsOptions(/*mutual=*/false));
  auto info = GetInfo(server_->address(), Options("other"));
  ASSERT_FALSE(info.ok());
  EXPECT_EQ(info.status().code(), absl::StatusCode::kUnavailable) << info.status();
}

TEST_F(SecurityTest, MutualTlsAcceptsAClientCertificateOfItsCa) {
  Start(TlsOptions(/*mutual=*/true));
  auto points = StreamOneFrame(server_->address(), Options("ca", "client"));
  ASSERT_TRUE(points.ok()) << points.status();
  EXPECT_GT(*points, 0u);
}

TEST_F(SecurityTest, MutualTlsRefusesAClientWithoutCertificate) {
  Start(TlsOptions(/*mutual=*/true));
  auto info = GetInfo(server_->address(), Options("ca"));
  ASSERT_FALSE(info.ok());
  EXPECT_EQ(info.status().code(), absl::StatusCode::kUnavailable) << info.status();
}

TEST_F(SecurityTest, MutualTlsRefusesACertificateFromAnotherCa) {
  Start(TlsOptions(/*mutual=*/true));
  auto info = GetInfo(server_->address(), Options("ca", "stranger"));
  ASSERT_FALSE(info.ok());
  EXPECT_EQ(info.status().code(), absl::StatusCode::kUnavailable) << info.status();
}

// A missing, unreadable or wrong file is a usage error at startup (exit 2) naming the flag.
TEST_F(SecurityTest, BadTlsFilesStopTheServerNamingTheFlag) {
  WriteFile(Path("garbage.pem"), "not a certificate\n");
  const std::string server = testing::BinDir() + "/cloudcast-server";
  struct Case {
    std::vector<std::string> args;
    std::string flag, says;
  };
  const std::vector<Case> cases = {
      {{"--tls-cert", Path("missing.pem"), "--tls-key", pki_->Key("server")},
       "--tls-cert",
       "cannot read"},
      {{"--tls-cert", Path("garbage.pem"), "--tls-key", pki_->Key("server")},
       "--tls-cert",
       "no PEM certificate"},
      {{"--tls-cert", pki_->Cert("server"), "--tls-key", Path("garbage.pem")},
       "--tls-key",
       "no PEM private key"},
      {{"--tls-cert", pki_->Cert("server"), "--tls-key", pki_->Key("client")},
       "--tls-key",
       "does not belong"},
      {{"--tls-cert", pki_->Cert("server"), "--tls-key", pki_->Key("server"), "--tls-client-ca",
        Path("missing-ca.pem")},
       "--tls-client-ca",
       "cannot read"},
      {{"--tls-cert", pki_->Cert("server")}, "--tls-key", "needs"},
      {{"--tls-client-ca", pki_->Cert("ca")}, "--tls-client-ca", "needs --tls-cert"},
  };
  for (const Case& c : cases) {
    std::vector<std::string> args = {"--listen", "127.0.0.1:0", "--metrics-listen", ""};
    args.insert(args.end(), c.args.begin(), c.args.end());
    const testing::RunResult r = testing::RunProgram(server, args, dir_.string());
    EXPECT_EQ(r.code, 2) << r;
    EXPECT_NE(r.err.find(c.flag), std::string::npos) << r;
    EXPECT_NE(r.err.find(c.says), std::string::npos) << r;
  }
}

// SIGHUP: new connections get the new certificate (here from a new CA), connections already open
// keep theirs, and a reload that fails keeps the certificate in use.
TEST_F(SecurityTest, SighupReloadsTheCertificate) {
  ASSERT_TRUE(pki_->MakeLeaf("other", "server2", TestPki::kServer, 7));
  // The files the server is started with, which the test then replaces.
  const std::string cert = Path("live.pem"), key = Path("live.key");
  std::filesystem::copy_file(pki_->Cert("server"), cert);
  std::filesystem::copy_file(pki_->Key("server"), key);
  testing::ServerProcess process("127.0.0.1:0", "reload", {"--tls-cert", cert, "--tls-key", key},
                                 Path("server.log"));
  ASSERT_TRUE(process.WaitUntilBound()) << process.log();
  const std::string address = process.address();
  // Connect waits for the server (a TLS handshake that succeeds), up to its timeout.
  cc::ClientOptions old_ca = Options("ca");
  old_ca.connect_timeout = seconds(30);
  auto early = cc::Client::Connect(address, old_ca);
  ASSERT_TRUE(early.ok()) << early.status() << "\n" << process.log();
  auto open = (*early)->OpenStream(cc::StreamConfig());
  ASSERT_TRUE(open.ok()) << open.status();
  cc::Stream& stream = **open;
  ASSERT_TRUE(stream.Send(Frame().disparity_view(), Frame().colour_view()).ok());
  cc::Result r;
  ASSERT_TRUE(stream.Read(&r));
  ASSERT_TRUE(r.ok()) << r.status;
  EXPECT_FALSE(GetInfo(address, Options("other")).ok());

  ReplaceFile(pki_->Cert("server2"), cert);
  ReplaceFile(pki_->Key("server2"), key);
  process.Signal(SIGHUP);
  // gRPC's certificate watcher takes the new copy at its next look (about a second): nothing
  // announces it, so the test asks until a client of the new CA gets in.
  EXPECT_TRUE(testing::Eventually([&] { return GetInfo(address, Options("other")).ok(); }))
      << process.log();
  auto refused = GetInfo(address, Options("ca"));
  EXPECT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kUnavailable) << refused.status();
  // The stream opened before the reload goes on, on its connection.
  ASSERT_TRUE(stream.Send(Frame().disparity_view(), Frame().colour_view()).ok());
  ASSERT_TRUE(stream.Read(&r));
  EXPECT_TRUE(r.ok()) << r.status;
  ASSERT_TRUE(stream.CloseSend().ok());
  EXPECT_TRUE(stream.Finish().ok());

  // A broken file: the reload fails, is logged, and the certificate in use stays.
  WriteFile(cert, "-----BEGIN CERTIFICATE-----\ntruncated\n");
  process.Signal(SIGHUP);
  // The log line is the event; the log file is all there is to watch.
  EXPECT_TRUE(testing::Eventually([&] {
    return process.log().find("reload failed, keeping the previous certificate") !=
           std::string::npos;
  })) << process.log();
  EXPECT_NE(process.log().find("--tls-cert"), std::string::npos) << process.log();
  EXPECT_TRUE(GetInfo(address, Options("other")).ok());

  process.Signal(SIGTERM);
  EXPECT_EQ(process.Wait(), std::optional<int>(0)) << process.log();
}

// ---------------------------------------------------------------------------------------------
// Bearer tokens and tenants

class TokensTest : public SecurityTest {
 protected:
  void SetUp() override {
    SecurityTest::SetUp();
    WriteFile(Path("tokens.json"), std::string(R"({"tenants": [
      {"name": "fleet", "tokens": [")") +
                                       kFleetToken + R"("],
       "max_streams": 1, "max_process_in_flight": 1},
      {"name": "small-camera", "tokens": [")" +
                                       kSmallToken + R"("], "max_pixels": 10000},
      {"name": "lab", "tokens": [")" + kLabToken +
                                       R"("]}
    ]})");
  }

  server::ServerOptions TokenOptions() const {
    server::ServerOptions o = TlsOptions(/*mutual=*/false);
    o.tokens_file = Path("tokens.json");
    return o;
  }

  // A raw GetInfo with exactly this authorization metadata ("" for none).
  grpc::Status RawGetInfo(const std::string& authorization) {
    cc::ChannelSecurity security;
    security.tls = Options("ca").security.tls;
    auto channel = cc::CreateChannel(server_->address(), security, grpc::ChannelArguments());
    EXPECT_TRUE(channel.ok());
    auto stub = v1::CloudCast::NewStub(*channel);
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + seconds(30));
    if (!authorization.empty()) context.AddMetadata("authorization", authorization);
    v1::ServerInfo info;
    return stub->GetInfo(&context, v1::GetInfoRequest(), &info);
  }
};

TEST_F(TokensTest, MissingOrWrongTokenIsUnauthenticated) {
  Start(TokenOptions());
  for (const std::string& authorization :
       {std::string(), std::string("Bearer ") + kWrongToken, std::string("Basic ") + kFleetToken,
        std::string(kFleetToken)}) {
    const grpc::Status s = RawGetInfo(authorization);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAUTHENTICATED) << authorization;
    for (const char* token : {kFleetToken, kWrongToken}) {
      EXPECT_EQ(s.error_message().find(token), std::string::npos) << s.error_message();
    }
  }
  EXPECT_TRUE(RawGetInfo(std::string("Bearer ") + kFleetToken).ok());
  EXPECT_TRUE(RawGetInfo(std::string("bearer ") + kFleetToken).ok());  // the scheme's case

  // Stream and Process, through the client library.
  for (const std::string& token : {std::string(), std::string(kWrongToken)}) {
    auto streamed = StreamOneFrame(server_->address(), Options("ca", "", token));
    ASSERT_FALSE(streamed.ok());
    EXPECT_EQ(streamed.status().code(), absl::StatusCode::kUnauthenticated) << streamed.status();
    EXPECT_EQ(std::string(streamed.status().message()).find(kWrongToken), std::string::npos);
    auto client = cc::Client::Connect(server_->address(), Options("ca", "", token));
    ASSERT_TRUE(client.ok());
    auto processed = (*client)->Process(Frame().disparity_view(), Frame().colour_view());
    ASSERT_FALSE(processed.ok());
    EXPECT_EQ(processed.status().code(), absl::StatusCode::kUnauthenticated);
  }
  // 4 GetInfo, then a Stream and a Process call with each of the 2 tokens.
  const std::string metrics = server::ScrapeMetrics(server_->metrics_port());
  EXPECT_EQ(server::MetricValue(metrics, "cloudcast_calls_unauthenticated_total"), 8) << metrics;
}

TEST_F(TokensTest, RightTokenStreamsAndProcesses) {
  Start(TokenOptions());
  auto points = StreamOneFrame(server_->address(), Options("ca", "", kFleetToken));
  ASSERT_TRUE(points.ok()) << points.status();
  EXPECT_GT(*points, 0u);
  auto client = cc::Client::Connect(server_->address(), Options("ca", "", kFleetToken));
  ASSERT_TRUE(client.ok());
  auto processed = (*client)->Process(Frame().disparity_view(), Frame().colour_view());
  EXPECT_TRUE(processed.ok()) << processed.status();
}

// Tokens over plaintext work too (behind a TLS-terminating proxy on the same host).
TEST_F(TokensTest, TokensWorkWithoutTls) {
  server::ServerOptions o = TokenOptions();
  o.tls_cert_file.clear();
  o.tls_key_file.clear();
  Start(o);
  EXPECT_TRUE(GetInfo(server_->address(), Options("", "", kFleetToken)).ok());
  auto refused = GetInfo(server_->address(), Options("", "", kWrongToken));
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kUnauthenticated);
}

TEST_F(TokensTest, TenantOverItsStreamLimitIsResourceExhaustedNamingTheLimit) {
  Start(TokenOptions());
  auto client = cc::Client::Connect(server_->address(), Options("ca", "", kFleetToken));
  ASSERT_TRUE(client.ok());
  // The first stream is admitted (its frame is answered), and stays open.
  auto first = (*client)->OpenStream(cc::StreamConfig());
  ASSERT_TRUE(first.ok());
  ASSERT_TRUE((*first)->Send(Frame().disparity_view(), Frame().colour_view()).ok());
  cc::Result r;
  ASSERT_TRUE((*first)->Read(&r));
  ASSERT_TRUE(r.ok()) << r.status;
  // The tenant's second is refused, whatever connection it comes on.
  auto second = StreamOneFrame(server_->address(), Options("ca", "", kFleetToken));
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.status().code(), absl::StatusCode::kResourceExhausted) << second.status();
  const std::string message(second.status().message());
  EXPECT_NE(message.find("tenant 'fleet'"), std::string::npos) << message;
  EXPECT_NE(message.find("its limit is 1 (max_streams in --tokens-file)"), std::string::npos)
      << message;
  // Another tenant still gets in (the server-wide limit is far away).
  EXPECT_TRUE(StreamOneFrame(server_->address(), Options("ca", "", kLabToken)).ok());
  ASSERT_TRUE((*first)->CloseSend().ok());
  EXPECT_TRUE((*first)->Finish().ok());
  // Its place is free again.
  EXPECT_TRUE(StreamOneFrame(server_->address(), Options("ca", "", kFleetToken)).ok());
}

TEST_F(TokensTest, TenantOverItsMaxPixelsIsRefusedNamingTheLimit) {
  Start(TokenOptions());
  // 160 x 120 = 19200 pixels; "small-camera" may send 10000.
  auto streamed = StreamOneFrame(server_->address(), Options("ca", "", kSmallToken));
  ASSERT_FALSE(streamed.ok());
  EXPECT_EQ(streamed.status().code(), absl::StatusCode::kResourceExhausted) << streamed.status();
  std::string message(streamed.status().message());
  EXPECT_NE(message.find("tenant 'small-camera'"), std::string::npos) << message;
  EXPECT_NE(message.find("10000 pixels per frame (max_pixels in --tokens-file)"), std::string::npos)
      << message;
  auto client = cc::Client::Connect(server_->address(), Options("ca", "", kSmallToken));
  ASSERT_TRUE(client.ok());
  auto processed = (*client)->Process(Frame().disparity_view(), Frame().colour_view());
  ASSERT_FALSE(processed.ok());
  EXPECT_EQ(processed.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_NE(std::string(processed.status().message()).find("max_pixels"), std::string::npos);
  // A frame within the limit is processed.
  SyntheticOptions o;
  o.width = 80;
  o.height = 60;  // 4800 pixels: allowed
  const SyntheticFrame small = *SyntheticScene::Default().Render(o);
  auto fits = (*client)->Process(small.disparity_view(), small.colour_view());
  EXPECT_TRUE(fits.ok()) << fits.status();
  // The fleet tenant has no pixel limit of its own: the server's applies.
  EXPECT_TRUE(StreamOneFrame(server_->address(), Options("ca", "", kFleetToken)).ok());
}

TEST_F(TokensTest, HealthCheckNeedsNoToken) {
  Start(TokenOptions());
  cc::ChannelSecurity security;
  security.tls = Options("ca").security.tls;
  for (const char* service : {"", "cloudcast.v1.CloudCast"}) {
    EXPECT_TRUE(load::ProbeHealth(server_->address(), service, seconds(30), security).ok())
        << service;
  }
}

// The tokens in use, a wrong one, and the log (at debug level) and /metrics of a real process.
TEST_F(TokensTest, TokensNeverAppearInTheLogOrTheMetrics) {
  testing::ServerProcess process("127.0.0.1:0", "tokens",
                                 {"--tls-cert", pki_->Cert("server"), "--tls-key",
                                  pki_->Key("server"), "--tokens-file", Path("tokens.json")},
                                 Path("server.log"), "debug", "127.0.0.1:0");
  ASSERT_TRUE(process.WaitUntilBound()) << process.log();
  const std::string address = process.address();
  const int metrics_port = process.metrics_port();
  cc::ClientOptions fleet = Options("ca", "", kFleetToken);
  fleet.connect_timeout = seconds(30);  // waits for the process to listen
  auto client = cc::Client::Connect(address, fleet);
  ASSERT_TRUE(client.ok()) << client.status() << "\n" << process.log();
  EXPECT_TRUE(StreamOneFrame(address, Options("ca", "", kFleetToken)).ok());
  EXPECT_FALSE(StreamOneFrame(address, Options("ca", "", kWrongToken)).ok());
  EXPECT_FALSE(StreamOneFrame(address, Options("ca", "", kSmallToken)).ok());  // max_pixels
  EXPECT_FALSE(GetInfo(address, Options("ca")).ok());
  const std::string metrics = server::ScrapeMetrics(metrics_port);
  ASSERT_NE(metrics.find("cloudcast_calls_unauthenticated_total"), std::string::npos) << metrics;
  process.Signal(SIGTERM);
  EXPECT_EQ(process.Wait(), std::optional<int>(0));
  const std::string log = process.log();
  ASSERT_NE(log.find("tenant fleet"), std::string::npos) << log;  // the log says who, not how
  for (const char* token : {kFleetToken, kSmallToken, kLabToken, kWrongToken}) {
    EXPECT_EQ(log.find(token), std::string::npos) << token << "\n" << log;
    EXPECT_EQ(metrics.find(token), std::string::npos) << token;
    // Not even a part of one.
    EXPECT_EQ(log.find(std::string(token).substr(6, 10)), std::string::npos) << token;
  }
}

// SIGHUP re-reads the tokens file: a rotated token gets in, the retired one no longer; a broken
// file keeps the tokens in use.
TEST_F(TokensTest, SighupReloadsTheTokensFile) {
  constexpr char kRotated[] = "rotated-token-a41c9e03d7b2f586";
  testing::ServerProcess process("127.0.0.1:0", "tokens", {"--tokens-file", Path("tokens.json")},
                                 Path("server.log"));
  ASSERT_TRUE(process.WaitUntilBound()) << process.log();
  const std::string address = process.address();
  cc::ClientOptions fleet = Options("", "", kFleetToken);
  fleet.connect_timeout = seconds(30);  // waits for the process to listen
  auto client = cc::Client::Connect(address, fleet);
  ASSERT_TRUE(client.ok()) << client.status() << "\n" << process.log();
  ASSERT_TRUE((*client)->GetInfo().ok());

  WriteFile(Path("tokens.new"),
            std::string(R"({"tenants": [{"name": "fleet", "tokens": [")") + kRotated + R"("]}]})");
  std::filesystem::rename(Path("tokens.new"), Path("tokens.json"));
  process.Signal(SIGHUP);
  // The reload runs on the server's signal thread; nothing tells the test when it is done.
  EXPECT_TRUE(testing::Eventually([&] { return GetInfo(address, Options("", "", kRotated)).ok(); }))
      << process.log();
  auto retired = GetInfo(address, Options("", "", kFleetToken));
  EXPECT_EQ(retired.status().code(), absl::StatusCode::kUnauthenticated) << retired.status();

  WriteFile(Path("tokens.json"), "{ broken");
  process.Signal(SIGHUP);
  EXPECT_TRUE(testing::Eventually([&] {
    return process.log().find("reload failed, keeping the previous tokens") != std::string::npos;
  })) << process.log();
  EXPECT_TRUE(GetInfo(address, Options("", "", kRotated)).ok());
  process.Signal(SIGTERM);
  EXPECT_EQ(process.Wait(), std::optional<int>(0)) << process.log();
}

// A tokens file is checked whole at startup; every error names the tenant and the key, and
// never quotes a token.
TEST(TokensFileTest, ErrorsNameTheTenantAndTheKey) {
  const std::uint64_t max_pixels = 1 << 24;
  struct Case {
    std::string json, says;
  };
  const std::string t = R"("tokens": ["abcdefghijklmnop-1"])";
  const std::vector<Case> cases = {
      {"{", "not valid JSON"},
      {R"({"tenant": []})", "unknown key \"tenant\""},
      {R"({"tenants": []})", "no tenant"},
      {R"({"tenants": [{"tokens": ["abcdefghijklmnop-1"]}]})", "\"name\""},
      {R"({"tenants": [{"name": "a b", )" + t + "}]}", "a name holds only"},
      {R"({"tenants": [{"name": "a"}]})", "tenant 'a': \"tokens\""},
      {R"({"tenants": [{"name": "a", "tokens": ["short"]}]})", "at least 16 characters"},
      {R"({"tenants": [{"name": "a", "tokens": ["abcdefghijklmnop 1"]}]})", "no spaces"},
      {R"({"tenants": [{"name": "a", )" + t + R"(, "max_stream": 2}]})",
       "tenant 'a': unknown key \"max_stream\""},
      {R"({"tenants": [{"name": "a", )" + t + R"(, "max_streams": -1}]})",
       "\"max_streams\" must be a non-negative integer"},
      {R"({"tenants": [{"name": "a", )" + t + R"(, "max_pixels": 16777217}]})", "--max-pixels"},
      {R"({"tenants": [{"name": "a", )" + t + R"(}, {"name": "b", )" + t + "}]}",
       "tenant 'b', token #0: the same token is listed twice"},
      {R"({"tenants": [{"name": "a", )" + t +
           R"(}, {"name": "a", "tokens": ["zzzzzzzzzzzzzzzz"]}]})",
       "tenant 'a' is listed twice"},
  };
  for (const Case& c : cases) {
    auto d = server::TenantDirectory::Parse(c.json, "tokens.json", max_pixels);
    ASSERT_FALSE(d.ok()) << c.json;
    EXPECT_EQ(d.status().code(), absl::StatusCode::kInvalidArgument);
    const std::string message(d.status().message());
    EXPECT_NE(message.find("tokens.json: "), std::string::npos) << message;
    EXPECT_NE(message.find(c.says), std::string::npos) << message;
    EXPECT_EQ(message.find("abcdefghijklmnop"), std::string::npos) << message;
  }
  auto good = server::TenantDirectory::Parse(
      R"({"tenants": [{"name": "a", "tokens": ["abcdefghijklmnop-1", "abcdefghijklmnop-2"],
          "max_streams": 3, "max_process_in_flight": 2, "max_pixels": 307200}]})",
      "tokens.json", max_pixels);
  ASSERT_TRUE(good.ok()) << good.status();
  for (const char* token : {"abcdefghijklmnop-1", "abcdefghijklmnop-2"}) {
    auto tenant = (*good)->AuthenticateToken(token);
    ASSERT_TRUE(tenant.ok());
    EXPECT_EQ((*tenant)->name, "a");
    EXPECT_EQ((*tenant)->max_streams, 3u);
    EXPECT_EQ((*tenant)->max_process_in_flight, 2u);
    EXPECT_EQ((*tenant)->max_pixels, 307200u);
  }
  EXPECT_EQ((*good)->AuthenticateToken("abcdefghijklmnop-3").status().code(),
            absl::StatusCode::kUnauthenticated);
}

TEST_F(SecurityTest, BadTokensFileStopsTheServerNamingTheFlag) {
  WriteFile(Path("bad.json"), R"({"tenants": [{"name": "a", "tokens": ["short"]}]})");
  const std::string server = testing::BinDir() + "/cloudcast-server";
  for (const std::string& file : {Path("bad.json"), Path("missing.json")}) {
    const testing::RunResult r = testing::RunProgram(
        server, {"--listen", "127.0.0.1:0", "--metrics-listen", "", "--tokens-file", file},
        dir_.string());
    EXPECT_EQ(r.code, 2) << r;
    EXPECT_NE(r.err.find("--tokens-file"), std::string::npos) << r;
  }
}

// ---------------------------------------------------------------------------------------------
// Reflection

// Asks the reflection service to list the services; its status, and the reply's bytes.
grpc::Status ListServices(const std::string& address, std::string* reply_bytes) {
  auto channel = grpc::CreateChannel(address, grpc::InsecureChannelCredentials());
  grpc::GenericStub stub(channel);
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + seconds(30));
  grpc::CompletionQueue cq;
  auto call =
      stub.PrepareCall(&ctx, "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo", &cq);
  void* tag;
  bool ok;
  call->StartCall(reinterpret_cast<void*>(1));
  cq.Next(&tag, &ok);
  // ServerReflectionRequest { string list_services = 7; } with the empty string.
  const std::string request("\x3a\x00", 2);
  grpc::Slice slice(request);
  call->Write(grpc::ByteBuffer(&slice, 1), reinterpret_cast<void*>(2));
  cq.Next(&tag, &ok);
  call->WritesDone(reinterpret_cast<void*>(3));
  cq.Next(&tag, &ok);
  grpc::ByteBuffer in;
  call->Read(&in, reinterpret_cast<void*>(4));
  if (cq.Next(&tag, &ok) && ok) {
    std::vector<grpc::Slice> slices;
    in.Dump(&slices).IgnoreError();
    for (const grpc::Slice& s : slices) {
      reply_bytes->append(reinterpret_cast<const char*>(s.begin()), s.size());
    }
  }
  grpc::Status status;
  call->Finish(&status, reinterpret_cast<void*>(5));
  cq.Next(&tag, &ok);
  return status;
}

TEST(ReflectionTest, OnByDefaultOffWithNoReflection) {
  server::ServerOptions o;
  o.listen = "127.0.0.1:0";
  o.metrics_listen = "";
  auto with = server::Server::Start(o);
  ASSERT_TRUE(with.ok()) << with.status();
  std::string listed;
  EXPECT_TRUE(ListServices((*with)->address(), &listed).ok());
  EXPECT_NE(listed.find("cloudcast.v1.CloudCast"), std::string::npos);
  // In the same process, after a server with reflection: the switch is per server.
  o.reflection = false;
  auto without = server::Server::Start(o);
  ASSERT_TRUE(without.ok()) << without.status();
  std::string none;
  const grpc::Status s = ListServices((*without)->address(), &none);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::UNIMPLEMENTED) << s.error_message();
  EXPECT_EQ(none.find("cloudcast.v1.CloudCast"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// The programs that connect: the same flags, the same rules.

TEST_F(TokensTest, LoadGeneratorConnectsWithTlsAndAToken) {
  Start(TokenOptions());
  WriteFile(Path("token"), std::string(kFleetToken) + "\n");
  const std::string load = testing::BinDir() + "/cloudcast-load";
  const testing::RunResult r = testing::RunProgram(
      load,
      {"--server", server_->address(), "--synthetic", "64x48", "--frames", "5", "--fps", "0",
       "--tls-ca", pki_->Cert("ca"), "--tls-server-name", "localhost", "--token-file",
       Path("token"), "--json", Path("report.json"), "-q"},
      dir_.string());
  EXPECT_EQ(r.code, 0) << r;
  const nlohmann::json report = nlohmann::json::parse(ReadAll(Path("report.json")), nullptr, false);
  EXPECT_EQ(report["statusCodeDistribution"]["OK"], 5) << report.dump();
  EXPECT_EQ(r.out.find(kFleetToken), std::string::npos);
  // Without the token: the server refuses the streams.
  const testing::RunResult refused =
      testing::RunProgram(load,
                          {"--server", server_->address(), "--synthetic", "64x48", "--frames", "5",
                           "--fps", "0", "--tls-ca", pki_->Cert("ca"), "-q"},
                          dir_.string());
  EXPECT_NE(refused.out.find("UNAUTHENTICATED"), std::string::npos) << refused;
  // A bad file is a usage error naming the flag.
  const testing::RunResult bad = testing::RunProgram(
      load, {"--server", server_->address(), "--tls-ca", Path("token")}, dir_.string());
  EXPECT_EQ(bad.code, 2) << bad;
  EXPECT_NE(bad.err.find("--tls-ca"), std::string::npos) << bad;
  // The flags are in --help.
  const testing::RunResult help = testing::RunProgram(load, {"--help"}, dir_.string());
  for (const char* flag :
       {"--tls", "--tls-ca", "--tls-cert", "--tls-key", "--tls-server-name", "--token-file"}) {
    EXPECT_NE(help.out.find(flag), std::string::npos) << flag;
  }
}

TEST_F(TokensTest, ViewerConnectsWithMutualTlsAndAToken) {
  server::ServerOptions o = TlsOptions(/*mutual=*/true);
  o.tokens_file = Path("tokens.json");
  Start(o);
  WriteFile(Path("token"), kFleetToken);
  const std::string viewer = testing::BinDir() + "/cloudcast-client";
  const testing::RunResult r = testing::RunProgram(
      viewer,
      {"--server", server_->address(), "--synthetic", "64x48", "--frames", "3", "--no-window",
       "--lossless", "--tls-ca", pki_->Cert("ca"), "--tls-cert", pki_->Cert("client"), "--tls-key",
       pki_->Key("client"), "--token-file", Path("token")},
      dir_.string());
  EXPECT_EQ(r.code, 0) << r;
  const testing::RunResult help = testing::RunProgram(viewer, {"--help"}, dir_.string());
  for (const char* flag :
       {"--tls", "--tls-ca", "--tls-cert", "--tls-key", "--tls-server-name", "--token-file"}) {
    EXPECT_NE(help.out.find(flag), std::string::npos) << flag;
  }
}

}  // namespace
}  // namespace cloudcast
