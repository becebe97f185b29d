// Admission: the server-wide limits and each client's share of them.
#include "admission.h"
#include "read_budget.h"

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

// The Process reads of one client: each reserves a whole message; past the client's share the
// next waits, in the order they came, and starts when an earlier read gives its share back.
TEST(ReadBudgetTest, AClientsReadsBeyondItsShareWaitInTurn) {
  ReadBudget budget(/*per_client_bytes=*/200);
  std::vector<int> started;
  EXPECT_EQ(budget.Reserve(1, 100, [] {}), ReadBudget::kGranted);
  EXPECT_EQ(budget.Reserve(1, 100, [] {}), ReadBudget::kGranted);
  const std::uint64_t third = budget.Reserve(1, 100, [&] { started.push_back(3); });
  const std::uint64_t fourth = budget.Reserve(1, 100, [&] { started.push_back(4); });
  EXPECT_NE(third, ReadBudget::kGranted);
  EXPECT_NE(fourth, ReadBudget::kGranted);
  EXPECT_EQ(budget.waiting(1), 2u);
  // Another client is not held back by the first one's.
  EXPECT_EQ(budget.Reserve(2, 100, [] {}), ReadBudget::kGranted);
  budget.Release(1, 100);
  EXPECT_EQ(started, std::vector<int>{3});
  budget.Release(1, 100);
  EXPECT_EQ(started, (std::vector<int>{3, 4}));
  EXPECT_EQ(budget.reserved(1), 200u);
  budget.Release(1, 100);
  budget.Release(1, 100);
  EXPECT_EQ(budget.reserved(1), 0u);
}

// A call that leaves while it waits is withdrawn; one granted meanwhile is not (its read runs).
// Withdrawing the head of the line lets the next one in when it fits.
TEST(ReadBudgetTest, AWithdrawnWaiterLetsTheNextOneIn) {
  ReadBudget budget(/*per_client_bytes=*/100);
  std::vector<int> started;
  ASSERT_EQ(budget.Reserve(7, 60, [] {}), ReadBudget::kGranted);
  const std::uint64_t big = budget.Reserve(7, 100, [&] { started.push_back(1); });
  const std::uint64_t small = budget.Reserve(7, 40, [&] { started.push_back(2); });
  ASSERT_NE(big, ReadBudget::kGranted);
  EXPECT_TRUE(started.empty());  // the small one waits behind the big one: first come, first read
  EXPECT_TRUE(budget.Cancel(7, big));
  EXPECT_EQ(started, std::vector<int>{2});
  EXPECT_FALSE(budget.Cancel(7, small));  // granted already
  EXPECT_FALSE(budget.Cancel(7, 12345));
  budget.Release(7, 60);
  budget.Release(7, 40);
  EXPECT_EQ(budget.reserved(7), 0u);
  EXPECT_EQ(budget.waiting(7), 0u);
}

// A message larger than the share is still read when the client has nothing else reserved:
// every client can always send one message of --max-message-bytes.
TEST(ReadBudgetTest, AReadLargerThanTheShareIsGrantedAlone) {
  ReadBudget budget(/*per_client_bytes=*/50);
  EXPECT_EQ(budget.Reserve(3, 80, [] {}), ReadBudget::kGranted);
  bool second = false;
  ASSERT_NE(budget.Reserve(3, 10, [&] { second = true; }), ReadBudget::kGranted);
  budget.Release(3, 80);
  EXPECT_TRUE(second);
}

}  // namespace
}  // namespace cloudcast::server
