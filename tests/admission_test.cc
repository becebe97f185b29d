// Admission: the server-wide limits and each client's share of them.
#include "admission.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace cloudcast::server {
namespace {

TEST(AdmissionTest, OneClientCannotTakeEverySlot) {
  Admission admission({/*max_streams=*/4, /*per_client=*/2, /*max_process=*/4, /*per_client=*/1});
  std::vector<Admission::Ticket> held;
  for (int i = 0; i < 2; ++i) {
    auto t = admission.Admit(Admission::Kind::kStream, "ipv4:127.0.0.1");
    ASSERT_TRUE(t.ok());
    held.push_back(*std::move(t));
  }
  auto third = admission.Admit(Admission::Kind::kStream, "ipv4:127.0.0.1");
  ASSERT_FALSE(third.ok());
  EXPECT_EQ(third.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_NE(std::string(third.status().message()).find("--max-streams-per-client"),
            std::string::npos)
      << third.status();
  // Another client still gets in, up to the server's limit.
  for (int i = 0; i < 2; ++i) {
    auto t = admission.Admit(Admission::Kind::kStream, "ipv4:127.0.0.2");
    ASSERT_TRUE(t.ok());
    held.push_back(*std::move(t));
  }
  auto over = admission.Admit(Admission::Kind::kStream, "ipv4:127.0.0.3");
  ASSERT_FALSE(over.ok());
  EXPECT_NE(std::string(over.status().message()).find("--max-streams"), std::string::npos);
  // Process calls are counted apart.
  auto p = admission.Admit(Admission::Kind::kProcess, "ipv4:127.0.0.1");
  ASSERT_TRUE(p.ok());
  EXPECT_FALSE(admission.Admit(Admission::Kind::kProcess, "ipv4:127.0.0.1").ok());
  // A ticket given back frees its place.
  held.front().Release();
  EXPECT_TRUE(admission.Admit(Admission::Kind::kStream, "ipv4:127.0.0.1").ok());
  EXPECT_EQ(admission.open(Admission::Kind::kStream), 3u);  // the temporary one was given back
}

// With bearer tokens a client is its tenant, whose own limits replace the per-client share.
TEST(AdmissionTest, TenantLimitsReplaceTheShare) {
  Admission admission({/*max_streams=*/8, /*per_client=*/4, /*max_process=*/8, /*per_client=*/4});
  const Admission::Client fleet{"tenant:fleet", "fleet", /*max_streams=*/1, /*max_process=*/0};
  auto first = admission.Admit(Admission::Kind::kStream, fleet);
  ASSERT_TRUE(first.ok());
  auto second = admission.Admit(Admission::Kind::kStream, fleet);
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_NE(std::string(second.status().message())
                .find("tenant 'fleet': its limit is 1 (max_streams in --tokens-file)"),
            std::string::npos)
      << second.status();
  // Without a limit of its own, the tenant has the per-client share, named as such.
  std::vector<Admission::Ticket> held;
  for (int i = 0; i < 4; ++i) {
    auto t = admission.Admit(Admission::Kind::kProcess, fleet);
    ASSERT_TRUE(t.ok());
    held.push_back(*std::move(t));
  }
  auto over = admission.Admit(Admission::Kind::kProcess, fleet);
  ASSERT_FALSE(over.ok());
  EXPECT_NE(std::string(over.status().message()).find("tenant 'fleet'"), std::string::npos);
  EXPECT_NE(std::string(over.status().message()).find("--max-process-per-client"),
            std::string::npos);
}

TEST(AdmissionTest, PeerHostDropsThePort) {
  EXPECT_EQ(PeerHost("ipv4:127.0.0.1:40123"), "ipv4:127.0.0.1");
  EXPECT_EQ(PeerHost("ipv6:[::1]:40123"), "ipv6:[::1]");
  EXPECT_EQ(PeerHost("unix:/run/cloudcast.sock"), "unix:/run/cloudcast.sock");
}

}  // namespace
}  // namespace cloudcast::server
