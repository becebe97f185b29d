// The in-process cloudcast server of every test that talks to one (server, client library,
// cloudcast-client): cloudcast::server::Server on 127.0.0.1 and a free port, channels and stubs to
// it, and a fixture that shares one server across a test suite.
//
//   auto server = testing::StartTestServer(options);    // options from TestServerOptions()
//   ASSERT_NE(server, nullptr);
//   auto stub = testing::NewStub(*server);              // generated gRPC stub, own connection
//   auto client = client::Client::Connect(server->address());
//
// The server shuts down when the unique_ptr goes (its destructor drains with the default grace).
#pragma once

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <memory>
#include <string>

#include "cloudcast/server/options.h"
#include "cloudcast/server/server.h"
#include "cloudcast/v1/cloudcast.grpc.pb.h"

namespace cloudcast::testing {

// 127.0.0.1 on a free port, no metrics exporter, two workers (the cores of these machines; the
// GetInfo test checks the number), everything else at its default, but for the stream defaults:
// the paper's setting (preset new_tsukuba), stated as an operator would (cloudcast-server
// --camera-preset new_tsukuba), since most tests send New Tsukuba frames (or the synthetic
// scene's, with the same camera at 640x480) and leave the camera and passthrough to the server.
// The contract's own defaults (no camera, no passthrough): ContractServerOptions().
inline server::ServerOptions ContractServerOptions() {
  server::ServerOptions options;
  options.listen = "127.0.0.1:0";
  options.metrics_listen = "";
  options.threads = 2;
  return options;
}

inline server::ServerOptions TestServerOptions() {
  server::ServerOptions options = ContractServerOptions();
  EXPECT_TRUE(ApplyPreset("new_tsukuba", &options.defaults.frame).ok());
  return options;
}

// Starts a server; when it cannot start, a test failure and nullptr.
inline std::unique_ptr<server::Server> StartTestServer(
    const server::ServerOptions& options = TestServerOptions()) {
  absl::StatusOr<std::unique_ptr<server::Server>> server = server::Server::Start(options);
  EXPECT_TRUE(server.ok()) << "the in-process server did not start: " << server.status();
  return server.ok() ? *std::move(server) : nullptr;
}

struct ChannelOptions {
  // Keeps the HTTP/2 receive window at its initial 64 KB (no BDP probing, which would grow it):
  // a client that stops reading then stops the server's writes after the first 64 KB of
  // replies, whatever the machine's speed. For the tests of slow readers and stuck streams.
  bool fixed_receive_window = false;
};

// A channel to `server` with a connection of its own (a local subchannel pool: two channels
// are two clients, not two streams on one connection), no send size limit.
inline std::shared_ptr<grpc::Channel> NewChannel(const server::Server& server,
                                                 const ChannelOptions& options = {}) {
  grpc::ChannelArguments args;
  args.SetMaxSendMessageSize(-1);
  args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  if (options.fixed_receive_window) args.SetInt(GRPC_ARG_HTTP2_BDP_PROBE, 0);
  return grpc::CreateCustomChannel(server.address(), grpc::InsecureChannelCredentials(), args);
}

inline std::unique_ptr<v1::CloudCast::Stub> NewStub(const server::Server& server,
                                                    const ChannelOptions& options = {}) {
  return v1::CloudCast::NewStub(NewChannel(server, options));
}

// One server for every test of a suite (starting one per test would dominate the time): started
// before the suite's first test with TestServerOptions(), shut down after its last. `Base` is the
// fixture it extends (e.g. ScratchDirTest).
template <typename Base = ::testing::Test>
class SharedServer : public Base {
 protected:
  static void SetUpTestSuite() { shared_server_ = StartTestServer().release(); }
  static void TearDownTestSuite() {
    delete shared_server_;
    shared_server_ = nullptr;
  }
  void SetUp() override {
    Base::SetUp();
    ASSERT_NE(shared_server_, nullptr) << "no in-process server";
  }

  static server::Server& shared_server() { return *shared_server_; }
  // "127.0.0.1:<port>", for Client::Connect and --server.
  static const std::string& shared_target() { return shared_server_->address(); }

 private:
  inline static server::Server* shared_server_ = nullptr;
};

using SharedServerTest = SharedServer<>;

}  // namespace cloudcast::testing
