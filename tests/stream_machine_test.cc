// The client stream core's state machine (cloudcast/client/stream_machine.h) on its own, with a
// clock the test drives: one write at a time, config first, DELIVERY_LATEST replacement,
// DELIVERY_ALL back-pressure, replies and skipped frames, lost calls with resends and drops,
// backoff and give-up, cancel, and a random schedule checked against the rule that every frame
// submitted is settled exactly once.
#include "cloudcast/client/stream_machine.h"

#include <gtest/gtest.h>

#include <map>
#include <random>
#include <string>
#include <vector>

namespace cloudcast::client {
namespace {

using Machine = StreamMachine<std::string, std::string>;
using Clock = Machine::Clock;
using Submitted = Machine::Submitted;
using std::chrono::milliseconds;

const Clock::time_point kT0 = Clock::time_point(std::chrono::seconds(1000));

StreamMachineOptions Latest() {
  StreamMachineOptions o;
  o.latest = true;
  return o;
}

StreamMachineOptions All(std::size_t max_queued = 1, bool resilient = false) {
  StreamMachineOptions o;
  o.max_queued = max_queued;
  o.resilient = resilient;
  o.reconnect_timeout = std::chrono::seconds(5);
  return o;
}

ReplyInfo Answer(std::uint64_t sequence) {
  ReplyInfo r;
  r.sequence = sequence;
  return r;
}

std::vector<std::uint64_t> Sequences(const std::vector<Machine::Settled>& s, FrameFate fate) {
  std::vector<std::uint64_t> out;
  for (const auto& e : s) {
    if (e.fate == fate) out.push_back(e.sequence);
  }
  return out;
}

TEST(StreamMachineTest, TheConfigGoesFirstAndOneWriteAtATime) {
  Machine m(All(/*max_queued=*/0), std::string("config"));
  m.Start(kT0);
  Machine::Effects e = m.TakeEffects();
  EXPECT_TRUE(e.open_call);
  EXPECT_FALSE(e.after_failure);
  ASSERT_TRUE(e.write);
  EXPECT_FALSE(e.write->is_frame);
  EXPECT_EQ(e.write->payload, "config");

  EXPECT_EQ(m.Submit(1, "f1", "r1", kT0), Submitted::kQueued);  // the config is still writing
  EXPECT_EQ(m.Submit(2, "f2", "r2", kT0), Submitted::kQueued);
  EXPECT_FALSE(m.TakeEffects().write);
  m.WriteDone(true, kT0);
  e = m.TakeEffects();
  ASSERT_TRUE(e.write);
  EXPECT_EQ(e.write->payload, "f1");
  EXPECT_EQ(e.write->sequence, 1u);
  EXPECT_TRUE(e.queue_freed);
  ASSERT_TRUE(m.Reconfigure("config2", kT0).ok());
  m.WriteDone(true, kT0);
  EXPECT_EQ(m.TakeEffects().write->payload, "f2");
  m.WriteDone(true, kT0);
  EXPECT_EQ(m.TakeEffects().write->payload, "config2");
  m.WriteDone(true, kT0);
  EXPECT_FALSE(m.TakeEffects().write);
  // An idle call writes a new frame at once.
  EXPECT_EQ(m.Submit(3, "f3", "r3", kT0), Submitted::kWriting);
  EXPECT_EQ(m.TakeEffects().write->payload, "f3");
}

TEST(StreamMachineTest, LatestReplacesTheWaitingFrameAndNeverRefuses) {
  Machine m(Latest(), std::string("config"));
  m.Start(kT0);
  m.TakeEffects();
  m.WriteDone(true, kT0);
  m.TakeEffects();
  EXPECT_EQ(m.Submit(0, "f0", "r0", kT0), Submitted::kWriting);
  m.TakeEffects();
  // The write slot is busy (the network is slow): each new frame replaces the waiting one.
  for (std::uint64_t s = 1; s <= 50; ++s) {
    EXPECT_EQ(m.Submit(s, "f" + std::to_string(s), "r" + std::to_string(s), kT0),
              Submitted::kQueued);
  }
  Machine::Effects e = m.TakeEffects();
  EXPECT_EQ(Sequences(e.settled, FrameFate::kReplaced).size(), 49u);
  EXPECT_EQ(e.settled.front().frame.record, "r1");  // the record comes back with its fate
  EXPECT_EQ(e.settled.front().sends, 0);
  EXPECT_EQ(m.replaced(), 49u);
  EXPECT_EQ(m.queued_frames(), 1u);
  m.WriteDone(true, kT0);
  e = m.TakeEffects();
  ASSERT_TRUE(e.write);
  EXPECT_EQ(e.write->sequence, 50u);  // the newest goes next
}

TEST(StreamMachineTest, AllHoldsTheSenderBackInsteadOfReplacing) {
  Machine m(All(/*max_queued=*/2), std::nullopt);  // no config: frames go first
  m.Start(kT0);
  EXPECT_TRUE(m.TakeEffects().open_call);
  EXPECT_EQ(m.Submit(1, "f1", "", kT0), Submitted::kWriting);
  EXPECT_EQ(m.Submit(2, "f2", "", kT0), Submitted::kQueued);
  EXPECT_EQ(m.Submit(3, "f3", "", kT0), Submitted::kQueued);
  EXPECT_EQ(m.Submit(4, "f4", "", kT0), Submitted::kFull);  // nothing changed
  EXPECT_EQ(m.submitted(), 3u);
  EXPECT_TRUE(m.TakeEffects().settled.empty());
  m.WriteDone(true, kT0);
  EXPECT_TRUE(m.TakeEffects().queue_freed);
  EXPECT_EQ(m.Submit(4, "f4", "", kT0), Submitted::kQueued);
  EXPECT_EQ(m.replaced(), 0u);
}

TEST(StreamMachineTest, RepliesSettleTheirFrameAndTheSkippedOnesBeforeIt) {
  Machine m(Latest(), std::nullopt);
  m.Start(kT0);
  for (std::uint64_t s = 1; s <= 4; ++s) {
    m.Submit(s, "f", "r" + std::to_string(s), kT0);
    m.WriteDone(true, kT0);
  }
  m.TakeEffects();
  Machine::Answer a = m.Reply(Answer(3));
  ASSERT_EQ(a.kind, Machine::Answer::kFrame);
  EXPECT_EQ(a.frame->frame.record, "r3");
  EXPECT_EQ(a.frame->fate, FrameFate::kAnswered);
  EXPECT_EQ(Sequences(m.TakeEffects().settled, FrameFate::kDropped),
            (std::vector<std::uint64_t>{1, 2}));
  EXPECT_EQ(m.Reply(Answer(2)).kind, Machine::Answer::kDuplicate);
  ReplyInfo config_error;
  config_error.answers_frame = false;
  EXPECT_EQ(m.Reply(config_error).kind, Machine::Answer::kNotAFrame);
  // A clean end of a DELIVERY_LATEST stream: what is unanswered was skipped by the server.
  m.CloseSend(false, kT0);
  Machine::Effects e = m.TakeEffects();
  EXPECT_TRUE(e.writes_done);
  EXPECT_TRUE(e.release_writes);
  m.CallDone(absl::OkStatus(), kT0);
  e = m.TakeEffects();
  EXPECT_TRUE(e.ended);
  EXPECT_EQ(Sequences(e.settled, FrameFate::kDropped), (std::vector<std::uint64_t>{4}));
  EXPECT_TRUE(m.status().ok());
}

TEST(StreamMachineTest, WithoutResilienceALostCallEndsTheStreamAndSettlesEverything) {
  Machine m(All(/*max_queued=*/0), std::string("config"));
  m.Start(kT0);
  m.Submit(1, "f1", "", kT0);
  m.Submit(2, "f2", "", kT0);
  m.WriteDone(true, kT0);  // config
  m.WriteDone(true, kT0);  // 1; 2 is writing
  m.TakeEffects();
  m.WriteDone(false, kT0);  // the call broke
  EXPECT_TRUE(m.TakeEffects().release_writes);
  m.Submit(3, "f3", "", kT0);
  EXPECT_FALSE(m.TakeEffects().write);  // nothing more on a broken call
  m.CallDone(absl::UnavailableError("connection reset"), kT0);
  Machine::Effects e = m.TakeEffects();
  EXPECT_TRUE(e.ended);
  EXPECT_FALSE(e.open_call);
  EXPECT_EQ(Sequences(e.settled, FrameFate::kLost), (std::vector<std::uint64_t>{1, 2}));
  EXPECT_EQ(Sequences(e.settled, FrameFate::kUnsent), (std::vector<std::uint64_t>{3}));
  EXPECT_NE(e.settled[0].why.message().find("connection reset"), std::string::npos);
  EXPECT_EQ(m.Submit(4, "f4", "", kT0), Submitted::kEnded);
  EXPECT_EQ(m.status().code(), absl::StatusCode::kUnavailable);
}

TEST(StreamMachineTest, AResilientStreamResendsInOrderOnANewCallAndReportsTheReconnect) {
  Machine m(All(/*max_queued=*/0, /*resilient=*/true), std::string("config"));
  m.Start(kT0);
  for (std::uint64_t s = 1; s <= 3; ++s) m.Submit(s, "f" + std::to_string(s), "", kT0);
  for (int w = 0; w < 4; ++w) m.WriteDone(true, kT0);
  ASSERT_EQ(m.Reply(Answer(1)).kind, Machine::Answer::kFrame);
  m.TakeEffects();
  ReplyInfo from_a;
  from_a.sequence = 0;
  from_a.answers_frame = false;
  from_a.instance = "replica-a";
  m.Reply(from_a);
  m.CallDone(absl::UnavailableError("GOAWAY"), kT0 + milliseconds(10));
  Machine::Effects e = m.TakeEffects();
  ASSERT_TRUE(e.open_call);
  EXPECT_TRUE(e.after_failure);
  EXPECT_TRUE(e.settled.empty());  // 2 and 3 wait to be sent again
  std::vector<std::string> writes;
  writes.push_back(e.write->payload);
  for (int w = 0; w < 3; ++w) {
    m.WriteDone(true, kT0 + milliseconds(20));
    e = m.TakeEffects();
    if (e.write) writes.push_back(e.write->payload);
    if (e.reconnected) {
      EXPECT_EQ(e.reconnected->attempt, 1);
      EXPECT_EQ(e.reconnected->frames_resent, 2u);
      EXPECT_EQ(e.reconnected->old_instance, "replica-a");
      EXPECT_EQ(e.reconnected->took, milliseconds(10));
    }
  }
  EXPECT_EQ(writes, (std::vector<std::string>{"config", "f2", "f3"}));
  EXPECT_EQ(m.reconnects(), 1);
  EXPECT_EQ(m.resent(), 2u);
  // Each frame once: an answer to 2, then a second answer to it from a resend is a duplicate.
  EXPECT_EQ(m.Reply(Answer(2)).kind, Machine::Answer::kFrame);
  EXPECT_EQ(m.Reply(Answer(2)).kind, Machine::Answer::kDuplicate);
}

TEST(StreamMachineTest, LatestDropsWhatALostCallLeftUnanswered) {
  StreamMachineOptions o = Latest();
  o.resilient = true;
  Machine m(o, std::nullopt);
  m.Start(kT0);
  m.Submit(1, "f1", "", kT0);
  m.WriteDone(true, kT0);
  m.Submit(2, "f2", "", kT0);
  m.WriteDone(true, kT0);
  m.TakeEffects();
  m.CallDone(absl::UnavailableError("killed"), kT0);
  Machine::Effects e = m.TakeEffects();
  EXPECT_TRUE(e.open_call);
  EXPECT_EQ(Sequences(e.settled, FrameFate::kDropped), (std::vector<std::uint64_t>{1, 2}));
  EXPECT_EQ(m.frames_dropped_reported(), 2u);
}

TEST(StreamMachineTest, FailedReplacementsBackOffAndTheStreamGivesUpAtTheTimeout) {
  Machine m(All(/*max_queued=*/0, /*resilient=*/true), std::string("config"));
  m.Start(kT0);
  m.Submit(1, "f1", "", kT0);
  m.WriteDone(true, kT0);
  m.WriteDone(true, kT0);
  m.TakeEffects();
  m.CallDone(absl::UnavailableError("down"), kT0);
  EXPECT_TRUE(m.TakeEffects().open_call);  // the first attempt goes at once
  m.CallDone(absl::UnavailableError("still down"), kT0 + milliseconds(1));
  Machine::Effects e = m.TakeEffects();
  EXPECT_FALSE(e.open_call);  // the next after a backoff
  ASSERT_TRUE(e.wake_at);
  EXPECT_EQ(*e.wake_at, kT0 + milliseconds(21));
  m.Timer(kT0 + milliseconds(21));
  e = m.TakeEffects();
  EXPECT_TRUE(e.open_call);
  // This one waits for a replica that never comes: at the deadline it is cancelled, and its end
  // ends the stream.
  m.Timer(kT0 + std::chrono::seconds(5));
  EXPECT_TRUE(m.TakeEffects().cancel_call);
  m.CallDone(absl::CancelledError("cancelled"), kT0 + std::chrono::seconds(5));
  e = m.TakeEffects();
  EXPECT_TRUE(e.ended);
  EXPECT_TRUE(m.gave_up());
  EXPECT_EQ(m.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(m.status().message().find("reconnect_timeout"), std::string::npos) << m.status();
  EXPECT_EQ(Sequences(e.settled, FrameFate::kLost), (std::vector<std::uint64_t>{1}));
}

TEST(StreamMachineTest, CancelBetweenCallsEndsAtOnceAndCancelOnACallWaitsForItsEnd) {
  Machine m(All(0, true), std::nullopt);
  m.Start(kT0);
  m.Submit(1, "f1", "", kT0);
  m.TakeEffects();
  m.Cancel();
  EXPECT_TRUE(m.TakeEffects().cancel_call);
  EXPECT_FALSE(m.ended());
  // The cancelled call's end does not reconnect, even as CANCELLED.
  m.CallDone(absl::CancelledError("cancelled"), kT0);
  Machine::Effects e = m.TakeEffects();
  EXPECT_TRUE(e.ended);
  EXPECT_FALSE(e.open_call);
  EXPECT_EQ(m.status().code(), absl::StatusCode::kCancelled);

  Machine between(All(0, true), std::nullopt);
  between.Start(kT0);
  between.CallDone(absl::UnavailableError("a"), kT0);
  between.CallDone(absl::UnavailableError("b"), kT0);  // now waiting for the backoff
  between.TakeEffects();
  between.Cancel();
  EXPECT_TRUE(between.TakeEffects().ended);
}

// A random life: frames submitted, writes completing, in-order replies skipping some frames,
// calls lost and replaced, a final end. Every frame is settled exactly once, whatever happens.
TEST(StreamMachineTest, EveryFrameIsSettledExactlyOnceInARandomLife) {
  for (int seed = 1; seed <= 200; ++seed) {
    SCOPED_TRACE(seed);
    std::mt19937 rng(seed);
    StreamMachineOptions o;
    o.latest = seed % 2 == 0;
    o.resilient = seed % 3 != 0;
    o.max_queued = 3;
    o.reconnect_timeout = std::chrono::seconds(2);
    Machine m(o, std::string("config"));
    Clock::time_point now = kT0;
    m.Start(now);
    std::map<std::uint64_t, int> settled;  // sequence -> times settled
    std::uint64_t next = 1, accepted = 0;
    bool call_open = true, writing = true;  // the config
    std::vector<std::uint64_t> on_call;     // frames written on this call, unanswered
    auto drain = [&] {
      Machine::Effects e = m.TakeEffects();
      if (e.open_call) {
        call_open = true;
        on_call.clear();
      }
      if (e.write) {
        writing = true;
        if (e.write->is_frame) on_call.push_back(e.write->sequence);
      }
      for (const auto& s : e.settled) ++settled[s.sequence];
    };
    drain();
    for (int step = 0; step < 300 && !m.ended(); ++step) {
      now += milliseconds(std::uniform_int_distribution<int>(0, 30)(rng));
      const int what = std::uniform_int_distribution<int>(0, 9)(rng);
      if (what <= 3) {
        const Submitted s = m.Submit(next, "f", "", now);
        if (s == Submitted::kWriting || s == Submitted::kQueued) {
          ++accepted;
          ++next;
        }
      } else if (what <= 5 && call_open && writing) {
        writing = false;
        m.WriteDone(std::uniform_int_distribution<int>(0, 30)(rng) != 0, now);
      } else if (what <= 7 && call_open && !on_call.empty()) {
        // The server answers a frame on this call, perhaps skipping earlier ones.
        const std::size_t k = std::uniform_int_distribution<std::size_t>(
            0, o.latest ? on_call.size() - 1 : 0)(rng);
        const Machine::Answer a = m.Reply(Answer(on_call[k]));
        if (a.frame) ++settled[a.frame->sequence];
        on_call.erase(on_call.begin(), on_call.begin() + static_cast<long>(k) + 1);
      } else if (what == 8 && call_open) {
        call_open = false;
        writing = false;
        m.CallDone(absl::UnavailableError("lost"), now);
      } else if (what == 9) {
        m.Timer(now);
      }
      drain();
    }
    if (!m.ended()) {
      m.Cancel();
      drain();
      if (call_open) {
        m.CallDone(absl::CancelledError("cancelled"), now);
        drain();
      }
    }
    ASSERT_TRUE(m.ended());
    EXPECT_EQ(settled.size(), accepted);
    for (const auto& [sequence, times] : settled) {
      EXPECT_EQ(times, 1) << "frame " << sequence;
      EXPECT_LT(sequence, next);
    }
  }
}

// A rate controller's window: past it a frame waits in the queue (and DELIVERY_LATEST replaces
// it there), a reply that opens the window lets the newest one out, configs are never held.
TEST(StreamMachineTest, FramesPastTheWindowWaitInTheQueue) {
  Machine m(Latest(), std::string("config"));
  m.SetMaxUnanswered(2, kT0);
  m.Start(kT0);
  m.TakeEffects();
  m.WriteDone(true, kT0);  // the config
  EXPECT_EQ(m.Submit(1, "f1", "", kT0), Submitted::kWriting);
  m.TakeEffects();
  m.WriteDone(true, kT0);
  EXPECT_EQ(m.Submit(2, "f2", "", kT0), Submitted::kWriting);
  m.TakeEffects();
  m.WriteDone(true, kT0);
  // Two unanswered: the window is full although the write slot is free.
  EXPECT_EQ(m.Submit(3, "f3", "", kT0), Submitted::kQueued);
  EXPECT_FALSE(m.TakeEffects().write);
  EXPECT_EQ(m.Submit(4, "f4", "", kT0), Submitted::kQueued);
  Machine::Effects e = m.TakeEffects();
  EXPECT_FALSE(e.write);
  EXPECT_EQ(Sequences(e.settled, FrameFate::kReplaced), std::vector<std::uint64_t>{3});
  ASSERT_TRUE(m.Reply(Answer(1)).frame);
  m.SetMaxUnanswered(2, kT0);
  e = m.TakeEffects();
  ASSERT_TRUE(e.write);
  EXPECT_EQ(e.write->sequence, 4u);
  m.WriteDone(true, kT0);
  // A smaller window holds the next frame until two replies came.
  m.SetMaxUnanswered(1, kT0);
  EXPECT_EQ(m.Submit(5, "f5", "", kT0), Submitted::kQueued);
  ASSERT_TRUE(m.Reply(Answer(2)).frame);
  m.SetMaxUnanswered(1, kT0);
  EXPECT_FALSE(m.TakeEffects().write);
  ASSERT_TRUE(m.Reply(Answer(4)).frame);
  m.SetMaxUnanswered(1, kT0);
  e = m.TakeEffects();
  ASSERT_TRUE(e.write);
  EXPECT_EQ(e.write->sequence, 5u);
  // 0: no limit.
  m.WriteDone(true, kT0);
  m.SetMaxUnanswered(0, kT0);
  EXPECT_EQ(m.Submit(6, "f6", "", kT0), Submitted::kWriting);
}

// Frames made at dispatch (video): the owner asks for room before it encodes, the machine never
// replaces what is queued, and the owner's own replacements of raw frames count as replaced.
StreamMachineOptions MadeAtDispatch() {
  StreamMachineOptions o = Latest();
  o.replace_queued = false;
  o.max_queued = 3;  // bounds the queue as with DELIVERY_ALL
  return o;
}

TEST(StreamMachineTest, RoomIsOfferedOnceWhenTheWindowOpensAndUnmadeFramesCountAsReplaced) {
  Machine m(MadeAtDispatch(), std::string("config"));
  m.SetMaxUnanswered(1, kT0);
  m.Start(kT0);
  m.TakeEffects();  // the config's write
  // Room while the config is written: a frame queued now goes right after it.
  EXPECT_TRUE(m.WantRoom());
  EXPECT_EQ(m.Submit(1, "f1", "r1", kT0), Submitted::kQueued);
  EXPECT_FALSE(m.WantRoom());  // f1 waits for the write slot
  // The owner replaces the raw frame it kept meanwhile: settled and counted, never queued.
  m.Unmade(FrameFate::kReplaced, 2, "r2", kT0);
  Machine::Effects e = m.TakeEffects();
  EXPECT_FALSE(e.room);
  EXPECT_EQ(Sequences(e.settled, FrameFate::kReplaced), std::vector<std::uint64_t>{2});
  EXPECT_EQ(m.submitted(), 2u);
  EXPECT_EQ(m.replaced(), 1u);
  m.WriteDone(true, kT0);  // the config
  e = m.TakeEffects();
  ASSERT_TRUE(e.write);
  EXPECT_EQ(e.write->sequence, 1u);
  EXPECT_FALSE(e.room);  // f1 fills the window of one
  m.WriteDone(true, kT0);
  EXPECT_FALSE(m.TakeEffects().room);
  EXPECT_FALSE(m.WantRoom());
  ASSERT_TRUE(m.Reply(Answer(1)).frame);
  m.SetMaxUnanswered(1, kT0);
  EXPECT_TRUE(m.TakeEffects().room);  // once
  EXPECT_FALSE(m.TakeEffects().room);
  EXPECT_TRUE(m.WantRoom());
  EXPECT_EQ(m.Submit(3, "f3", "r3", kT0), Submitted::kWriting);
  // A smaller window after a reply: no room until enough replies came.
  m.WriteDone(true, kT0);
  EXPECT_FALSE(m.WantRoom());
  m.SetMaxUnanswered(1, kT0);
  EXPECT_FALSE(m.TakeEffects().room);
  ASSERT_TRUE(m.Reply(Answer(3)).frame);
  EXPECT_TRUE(m.TakeEffects().room);
}

TEST(StreamMachineTest, MadeAtDispatchAQueuedFrameIsNeverReplaced) {
  Machine m(MadeAtDispatch(), std::string("config"));
  m.Start(kT0);
  m.TakeEffects();
  // Frames submitted while the config is written (an owner that did not ask for room): every
  // one is written, in order; none is replaced.
  EXPECT_EQ(m.Submit(1, "f1", "", kT0), Submitted::kQueued);
  EXPECT_EQ(m.Submit(2, "f2", "", kT0), Submitted::kQueued);
  EXPECT_EQ(m.Submit(3, "f3", "", kT0), Submitted::kQueued);
  EXPECT_EQ(m.Submit(4, "f4", "", kT0), Submitted::kFull);
  EXPECT_TRUE(m.TakeEffects().settled.empty());
  std::vector<std::uint64_t> written;
  for (int i = 0; i < 4; ++i) {
    m.WriteDone(true, kT0);
    Machine::Effects e = m.TakeEffects();
    if (e.write) written.push_back(e.write->sequence);
  }
  EXPECT_EQ(written, (std::vector<std::uint64_t>{1, 2, 3}));
  EXPECT_EQ(m.replaced(), 0u);
  // Still DELIVERY_LATEST on the wire: frames the server skipped are dropped, not lost.
  ASSERT_TRUE(m.Reply(Answer(3)).frame);
  EXPECT_EQ(m.TakeEffects().settled.size(), 2u);
}

TEST(StreamMachineTest, NoRoomAfterCloseSendOrTheEnd) {
  Machine m(MadeAtDispatch(), std::string("config"));
  m.Start(kT0);
  m.TakeEffects();
  m.CloseSend(/*discard_queued=*/false, kT0);
  EXPECT_FALSE(m.WantRoom());
  m.WriteDone(true, kT0);
  EXPECT_FALSE(m.TakeEffects().room);
  m.CallDone(absl::OkStatus(), kT0);
  Machine::Effects e = m.TakeEffects();
  EXPECT_TRUE(e.ended);
  EXPECT_FALSE(e.room);
  EXPECT_FALSE(m.WantRoom());
}

}  // namespace
}  // namespace cloudcast::client
