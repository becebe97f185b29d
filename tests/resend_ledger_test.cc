// The resilient streams' book (cloudcast/client/resend_ledger.h) on its own: replies in order,
// frames the server skipped, calls lost with resendable and droppable frames, resends lost again,
// duplicates, a random schedule checked against a model, and giving up.
#include "cloudcast/client/resend_ledger.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <set>
#include <string>
#include <vector>

namespace cloudcast::client {
namespace {

using Ledger = ResendLedger<std::string>;
using Match = Ledger::Match;

std::vector<std::uint64_t> Sequences(const std::vector<Ledger::Entry>& entries) {
  std::vector<std::uint64_t> out;
  for (const auto& e : entries) out.push_back(e.sequence);
  return out;
}

TEST(ResendLedgerTest, RepliesTakeTheirFrameAndTheSkippedOnesBeforeIt) {
  Ledger ledger;
  for (std::uint64_t s = 1; s <= 5; ++s) ledger.Sent(s, "frame " + std::to_string(s), false);
  EXPECT_EQ(ledger.in_flight(), 5u);

  Ledger::Reply first = ledger.Answer(1);
  ASSERT_EQ(first.match, Match::kAnswered);
  EXPECT_EQ(first.entry->record, "frame 1");
  EXPECT_EQ(first.skipped, 0u);

  // DELIVERY_LATEST: the server skipped 2 and 3 for 4.
  Ledger::Reply fourth = ledger.Answer(4);
  ASSERT_EQ(fourth.match, Match::kAnswered);
  EXPECT_EQ(fourth.entry->sequence, 4u);
  EXPECT_EQ(fourth.skipped, 2u);
  EXPECT_EQ(ledger.in_flight(), 1u);

  // Replies to frames already answered or skipped answer nothing new.
  EXPECT_EQ(ledger.Answer(4).match, Match::kDuplicate);
  EXPECT_EQ(ledger.Answer(2).match, Match::kDuplicate);
  // A sequence never sent is unknown, and takes nothing out of the book.
  EXPECT_EQ(ledger.Answer(99).match, Match::kUnknown);
  EXPECT_EQ(ledger.in_flight(), 1u);
  EXPECT_EQ(ledger.Answer(5).match, Match::kAnswered);
  EXPECT_TRUE(ledger.empty());
}

TEST(ResendLedgerTest, ALostCallResendsInOrderAndDropsWhatMayNotBeResent) {
  Ledger ledger;
  // Delivery changed mid-stream (a Reconfigure): 1 and 3 may be resent, 2 may not.
  ledger.Sent(1, "a", true);
  ledger.Sent(2, "b", false);
  ledger.Sent(3, "c", true);
  EXPECT_EQ(ledger.CallLost(), 1u);
  EXPECT_EQ(ledger.in_flight(), 0u);
  EXPECT_EQ(ledger.awaiting_resend(), 2u);

  Ledger::Entry* e = ledger.NextResend();
  ASSERT_NE(e, nullptr);
  EXPECT_EQ(e->sequence, 1u);
  EXPECT_EQ(e->record, "a");
  EXPECT_EQ(e->sends, 2);
  // The replacement call is lost too, after one resend: 1 goes again ahead of 3.
  EXPECT_EQ(ledger.CallLost(), 0u);
  EXPECT_EQ(ledger.awaiting_resend(), 2u);
  e = ledger.NextResend();
  EXPECT_EQ(e->sequence, 1u);
  EXPECT_EQ(e->sends, 3);
  e = ledger.NextResend();
  EXPECT_EQ(e->sequence, 3u);
  EXPECT_EQ(e->sends, 2);
  EXPECT_EQ(ledger.NextResend(), nullptr);
  ledger.Sent(4, "d", true);  // new frames after the resends

  // The resent frames are answered once; a second reply to one is a duplicate.
  EXPECT_EQ(ledger.Answer(1).match, Match::kAnswered);
  EXPECT_EQ(ledger.Answer(1).match, Match::kDuplicate);
  Ledger::Reply third = ledger.Answer(3);
  ASSERT_EQ(third.match, Match::kAnswered);
  EXPECT_EQ(third.entry->sends, 2);
  EXPECT_EQ(third.skipped, 0u);
  EXPECT_EQ(Sequences(ledger.TakeUnanswered()), (std::vector<std::uint64_t>{4}));
  EXPECT_TRUE(ledger.empty());
}

TEST(ResendLedgerTest, GivingUpReportsEveryUnansweredFrameInSendOrder) {
  Ledger ledger;
  for (std::uint64_t s = 1; s <= 4; ++s) ledger.Sent(s, "", true);
  ledger.CallLost();
  ledger.NextResend();  // 1 in flight again, 2..4 waiting
  EXPECT_EQ(ledger.unanswered(), 4u);
  EXPECT_EQ(Sequences(ledger.TakeUnanswered()), (std::vector<std::uint64_t>{1, 2, 3, 4}));
  EXPECT_TRUE(ledger.empty());
  EXPECT_EQ(ledger.NextResend(), nullptr);
}

TEST(ResendLedgerTest, SequencesOfTheCallersOwnInAnyOrderAreMatchedButNeverDuplicates) {
  Ledger ledger;
  ledger.Sent(7, "x", false);
  ledger.Sent(3, "y", false);
  ledger.Sent(3, "z", false);  // repeated: the earliest unanswered one is answered first
  Ledger::Reply r = ledger.Answer(3);
  ASSERT_EQ(r.match, Match::kAnswered);
  EXPECT_EQ(r.entry->record, "y");
  EXPECT_EQ(r.skipped, 1u);  // 7 got no reply before it
  EXPECT_EQ(ledger.Answer(3).entry->record, "z");
  // Not increasing: an unmatched reply cannot be told to be a duplicate.
  EXPECT_EQ(ledger.Answer(3).match, Match::kUnknown);
  EXPECT_EQ(ledger.Answer(1).match, Match::kUnknown);
}

// A random schedule of sends, in-order replies (some frames skipped), lost calls and resends,
// against a model: every frame sent ends exactly once as answered, skipped, dropped or still
// unanswered, resends keep send order, and no reply is counted twice.
TEST(ResendLedgerTest, RandomScheduleAccountsForEveryFrameExactlyOnce) {
  for (std::uint64_t seed = 1; seed <= 200; ++seed) {
    SCOPED_TRACE(seed);
    std::mt19937_64 rng(seed);
    const bool resendable = seed % 2 == 0;  // DELIVERY_ALL or DELIVERY_LATEST
    Ledger ledger;
    std::uint64_t next = 1, answered = 0, skipped = 0, dropped = 0;
    std::set<std::uint64_t> done;     // answered or skipped
    std::vector<std::uint64_t> wire;  // on the current call, in write order
    for (int step = 0; step < 300; ++step) {
      switch (rng() % 6) {
        case 0:
        case 1:
        case 2:  // a write: resends first, then a new frame
          if (Ledger::Entry* e = ledger.NextResend()) {
            wire.push_back(e->sequence);
          } else {
            ledger.Sent(next, "", resendable);
            wire.push_back(next++);
          }
          break;
        case 3:
        case 4: {  // the server answers the oldest frame on the wire, maybe after skipping some
          if (wire.empty()) break;
          std::size_t skip = rng() % 3 == 0 ? std::min<std::size_t>(rng() % 3, wire.size() - 1) : 0;
          const std::uint64_t s = wire[skip];
          Ledger::Reply r = ledger.Answer(s);
          ASSERT_EQ(r.match, Match::kAnswered);
          EXPECT_EQ(done.count(s), 0u);
          EXPECT_EQ(r.skipped, skip);
          for (std::size_t k = 0; k <= skip; ++k) done.insert(wire[k]);
          ++answered;
          skipped += r.skipped;
          wire.erase(wire.begin(), wire.begin() + static_cast<std::ptrdiff_t>(skip) + 1);
          // Another reply to that frame (e.g. to its resend): a duplicate.
          if (rng() % 10 == 0) {
            EXPECT_EQ(ledger.Answer(s).match, Match::kDuplicate);
          }
          break;
        }
        case 5:  // the call is lost
          dropped += ledger.CallLost();
          wire.clear();
          break;
      }
      ASSERT_EQ(answered + skipped + dropped + ledger.unanswered(), next - 1);
    }
    const auto rest = ledger.TakeUnanswered();
    EXPECT_TRUE(std::is_sorted(rest.begin(), rest.end(), [](const auto& a, const auto& b) {
      return a.sequence < b.sequence;
    }));
    for (const auto& e : rest) EXPECT_EQ(done.count(e.sequence), 0u);
  }
}

}  // namespace
}  // namespace cloudcast::client
