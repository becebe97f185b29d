// A suite's shared in-process server (server_fixture.h) and, per test, a client library Client
// connected to it: the fixture of the tests that speak to the server through the library.
#pragma once

#include <gtest/gtest.h>

#include <memory>

#include "cloudcast/client/client.h"
#include "support/server_fixture.h"

namespace cloudcast::testing {

class SharedServerClientTest : public SharedServerTest {
 protected:
  void SetUp() override {
    SharedServerTest::SetUp();
    absl::StatusOr<std::unique_ptr<client::Client>> c = client::Client::Connect(shared_target());
    ASSERT_TRUE(c.ok()) << c.status();
    client_ = *std::move(c);
  }

  std::unique_ptr<client::Client> client_;
};

}  // namespace cloudcast::testing
