// The stream queue without gRPC: delivery policy, reply order, drops and bounds, driven step by
// step as the reactor drives it.
#include "stream_queue.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <deque>
#include <memory>
#include <random>
#include <vector>

namespace cloudcast::server {
namespace {

using convert::Delivery;

// Slots with an id, so a test can say which one came back.
struct Slot : StreamSlot {
  int id = 0;
};

class StreamQueueTest : public ::testing::Test {
 protected:
  Slot* Frame(Delivery d) {
    slots_.push_back(std::make_unique<Slot>());
    Slot* s = slots_.back().get();
    s->id = static_cast<int>(slots_.size());
    s->delivery = d;
    return s;
  }
  static int Id(StreamSlot* s) { return s == nullptr ? 0 : static_cast<Slot*>(s)->id; }

  std::vector<std::unique_ptr<Slot>> slots_;
};

TEST_F(StreamQueueTest, AllModeProcessesEveryFrameAndWritesInArrivalOrder) {
  StreamQueue q(4);
  std::vector<StreamSlot*> dropped;
  Slot* a = Frame(Delivery::kAll);
  Slot* b = Frame(Delivery::kAll);
  Slot* c = Frame(Delivery::kAll);
  for (Slot* s : {a, b, c}) q.PushFrame(s, &dropped);
  EXPECT_TRUE(dropped.empty());
  // All three may be in work at once (several workers).
  EXPECT_EQ(Id(q.NextToProcess()), a->id);
  EXPECT_EQ(Id(q.NextToProcess()), b->id);
  EXPECT_EQ(Id(q.NextToProcess()), c->id);
  EXPECT_EQ(q.NextToProcess(), nullptr);
  EXPECT_EQ(q.in_work(), 3);
  // c and b finish first; nothing is written before a.
  EXPECT_TRUE(q.Processed(c));
  EXPECT_TRUE(q.Processed(b));
  EXPECT_EQ(q.NextToWrite(), nullptr);
  EXPECT_TRUE(q.Processed(a));
  EXPECT_EQ(Id(q.NextToWrite()), a->id);
  EXPECT_EQ(q.NextToWrite(), nullptr);  // one write at a time
  q.Written();
  EXPECT_EQ(Id(q.NextToWrite()), b->id);
  q.Written();
  EXPECT_EQ(Id(q.NextToWrite()), c->id);
  q.Written();
  EXPECT_TRUE(q.Empty());
  EXPECT_EQ(q.written(), 3u);
  EXPECT_EQ(q.dropped(), 0u);
}

TEST_F(StreamQueueTest, AllModeStopsReadingAtItsBound) {
  StreamQueue q(3);
  std::vector<StreamSlot*> dropped;
  for (int i = 0; i < 3; ++i) {
    ASSERT_TRUE(q.CanRead(Delivery::kAll)) << i;
    q.PushFrame(Frame(Delivery::kAll), &dropped);
  }
  EXPECT_FALSE(q.CanRead(Delivery::kAll));
  // Held counts waiting, in work, ready and being written: room comes back only once a reply
  // has been written.
  StreamSlot* s = q.NextToProcess();
  EXPECT_FALSE(q.CanRead(Delivery::kAll));
  q.Processed(s);
  EXPECT_FALSE(q.CanRead(Delivery::kAll));
  ASSERT_EQ(q.NextToWrite(), s);
  EXPECT_FALSE(q.CanRead(Delivery::kAll));
  q.Written();
  EXPECT_TRUE(q.CanRead(Delivery::kAll));
  EXPECT_EQ(q.held(), 2u);
}

TEST_F(StreamQueueTest, LatestModeReplacesTheWaitingFrameAndCountsTheDrop) {
  StreamQueue q(4);
  std::vector<StreamSlot*> dropped;
  Slot* a = Frame(Delivery::kLatest);
  q.PushFrame(a, &dropped);
  StreamSlot* working = q.NextToProcess();
  ASSERT_EQ(working, a);
  // While a is in work, b waits; c replaces it, d replaces c.
  Slot* b = Frame(Delivery::kLatest);
  Slot* c = Frame(Delivery::kLatest);
  Slot* d = Frame(Delivery::kLatest);
  q.PushFrame(b, &dropped);
  EXPECT_EQ(q.NextToProcess(), nullptr);  // one in work at a time
  q.PushFrame(c, &dropped);
  q.PushFrame(d, &dropped);
  ASSERT_EQ(dropped.size(), 2u);
  EXPECT_EQ(Id(dropped[0]), b->id);
  EXPECT_EQ(Id(dropped[1]), c->id);
  EXPECT_EQ(q.dropped(), 2u);
  // Keeps reading: a waiting frame will be replaced, so it does not count against the bound.
  EXPECT_TRUE(q.CanRead(Delivery::kLatest));
  q.Processed(a);
  // No frame starts while a finished reply waits for the writer (a slow reader gets drops).
  EXPECT_EQ(q.NextToProcess(), nullptr);
  ASSERT_EQ(q.NextToWrite(), a);
  EXPECT_EQ(Id(q.NextToProcess()), d->id);  // overlaps the write
  q.Written();
  q.Processed(d);
  EXPECT_EQ(Id(q.NextToWrite()), d->id);
  q.Written();
  EXPECT_TRUE(q.Empty());
}

// Defect 6: a DELIVERY_LATEST client that never takes its replies kept being read, and every
// frame dropped, at full speed. Reading now stops after a few drops during one write.
TEST_F(StreamQueueTest, LatestModeStopsReadingAClientThatDoesNotTakeItsReplies) {
  StreamQueue q(4);
  std::vector<StreamSlot*> dropped;
  Slot* a = Frame(Delivery::kLatest);
  q.PushFrame(a, &dropped);
  ASSERT_EQ(q.NextToProcess(), a);
  q.Processed(a);
  ASSERT_EQ(q.NextToWrite(), a);  // the client never completes this write
  std::uint32_t read = 0;
  while (q.CanRead(Delivery::kLatest) && read < 1000) {
    q.PushFrame(Frame(Delivery::kLatest), &dropped);
    ++read;
  }
  EXPECT_EQ(read, StreamQueue::kMaxDropsPerWrite + 1);  // one waits, the others were dropped
  EXPECT_EQ(q.dropped(), StreamQueue::kMaxDropsPerWrite);
  // Once the client takes the reply, reading goes on.
  q.Written();
  EXPECT_TRUE(q.CanRead(Delivery::kLatest));
}

TEST_F(StreamQueueTest, RepliesWithoutWorkKeepTheirPlaceAmongFrames) {
  StreamQueue q(4);
  std::vector<StreamSlot*> dropped;
  Slot* f1 = Frame(Delivery::kAll);
  Slot* err = Frame(Delivery::kAll);
  Slot* f2 = Frame(Delivery::kAll);
  q.PushFrame(f1, &dropped);
  q.PushReply(err);
  q.PushFrame(f2, &dropped);
  EXPECT_EQ(Id(q.NextToProcess()), f1->id);
  EXPECT_EQ(Id(q.NextToProcess()), f2->id);  // the reply took its place without a worker
  q.Processed(f2);
  q.Processed(f1);
  std::vector<int> order;
  while (StreamSlot* s = q.NextToWrite()) {
    order.push_back(Id(s));
    q.Written();
  }
  EXPECT_EQ(order, (std::vector<int>{f1->id, err->id, f2->id}));
}

TEST_F(StreamQueueTest, LatestModeDoesNotDropRepliesOrAllModeFrames) {
  StreamQueue q(4);
  std::vector<StreamSlot*> dropped;
  Slot* busy = Frame(Delivery::kLatest);
  q.PushFrame(busy, &dropped);
  ASSERT_EQ(q.NextToProcess(), busy);
  q.PushReply(Frame(Delivery::kLatest));         // a config error: never dropped
  q.PushFrame(Frame(Delivery::kAll), &dropped);  // sent under an earlier DELIVERY_ALL config
  q.PushFrame(Frame(Delivery::kLatest), &dropped);
  EXPECT_TRUE(dropped.empty());
}

TEST_F(StreamQueueTest, ABoundedLatestStreamStopsReadingWhenRepliesPileUp) {
  // Error replies and unwritten clouds count against the bound (max(bound, 3)) in DELIVERY_LATEST,
  // so a client that sends bad configs and reads nothing cannot grow the queue.
  StreamQueue q(2);
  for (int i = 0; i < 3; ++i) {
    ASSERT_TRUE(q.CanRead(Delivery::kLatest));
    q.PushReply(Frame(Delivery::kLatest));
  }
  EXPECT_FALSE(q.CanRead(Delivery::kLatest));
}

TEST_F(StreamQueueTest, AbandonReleasesEverySlotExactlyOnce) {
  StreamQueue q(8);
  std::vector<StreamSlot*> dropped;
  std::vector<Slot*> pushed;
  for (int i = 0; i < 5; ++i) {
    pushed.push_back(Frame(Delivery::kAll));
    q.PushFrame(pushed.back(), &dropped);
  }
  StreamSlot* w1 = q.NextToProcess();
  StreamSlot* w2 = q.NextToProcess();
  StreamSlot* w3 = q.NextToProcess();
  q.Processed(w1);
  ASSERT_EQ(q.NextToWrite(), w1);  // being written
  q.Processed(w3);                 // done, waiting behind w2
  std::vector<StreamSlot*> released;
  q.Abandon(&released);
  EXPECT_TRUE(q.abandoned());
  EXPECT_FALSE(q.CanRead(Delivery::kAll));
  EXPECT_EQ(q.NextToProcess(), nullptr);
  // w2 is still in work: it comes back through Processed, which says "release it".
  EXPECT_FALSE(q.Processed(w2));
  released.push_back(w2);
  q.Written();  // the outstanding write of w1 completes (unsuccessfully)
  released.push_back(w1);
  EXPECT_TRUE(q.Empty());
  std::vector<int> ids;
  for (StreamSlot* s : released) ids.push_back(Id(s));
  std::sort(ids.begin(), ids.end());
  std::vector<int> want;
  for (Slot* s : pushed) want.push_back(s->id);
  EXPECT_EQ(ids, want);
}

// A random walk through every operation, checked against the invariants: each slot comes back
// once, replies leave in push order (minus drops), the DELIVERY_ALL bound holds whenever the
// stream is read, and DELIVERY_LATEST never has two frames in work.
TEST_F(StreamQueueTest, RandomScheduleKeepsTheInvariants) {
  for (std::uint32_t seed = 1; seed <= 200; ++seed) {
    std::mt19937 rng(seed);
    const std::uint32_t bound = 1 + rng() % 5;
    StreamQueue q(bound);
    std::vector<StreamSlot*> in_work, returned, written;
    std::vector<Slot*> pushed;
    bool writing = false;
    Delivery mode = rng() % 2 ? Delivery::kAll : Delivery::kLatest;
    for (int step = 0; step < 400; ++step) {
      switch (rng() % 6) {
        case 0:
        case 1:
          if (q.CanRead(mode)) {
            Slot* s = Frame(mode);
            pushed.push_back(s);
            if (rng() % 8 == 0) {
              q.PushReply(s);
            } else {
              std::vector<StreamSlot*> dropped;
              q.PushFrame(s, &dropped);
              returned.insert(returned.end(), dropped.begin(), dropped.end());
            }
            if (mode == Delivery::kAll) {
              ASSERT_LE(q.held(), bound) << "seed " << seed;
            }
          }
          break;
        case 2:
          while (StreamSlot* s = q.NextToProcess()) in_work.push_back(s);
          if (mode == Delivery::kLatest) {
            int latest_in_work = 0;
            for (StreamSlot* s : in_work) latest_in_work += s->delivery == Delivery::kLatest;
            ASSERT_LE(latest_in_work, 1) << "seed " << seed;
          }
          break;
        case 3:
          if (!in_work.empty()) {
            const std::size_t i = rng() % in_work.size();
            ASSERT_TRUE(q.Processed(in_work[i]));
            in_work.erase(in_work.begin() + static_cast<long>(i));
          }
          break;
        case 4:
          if (!writing) {
            if (StreamSlot* s = q.NextToWrite()) {
              written.push_back(s);
              writing = true;
            }
          } else {
            q.Written();
            writing = false;
          }
          break;
        case 5:
          if (rng() % 20 == 0) mode = mode == Delivery::kAll ? Delivery::kLatest : Delivery::kAll;
          break;
      }
    }
    // Drain: finish the work and write everything.
    for (StreamSlot* s : in_work) ASSERT_TRUE(q.Processed(s));
    in_work.clear();
    if (writing) q.Written();
    for (;;) {
      while (StreamSlot* s = q.NextToProcess()) ASSERT_TRUE(q.Processed(s));
      StreamSlot* s = q.NextToWrite();
      if (s == nullptr) break;
      written.push_back(s);
      q.Written();
    }
    ASSERT_TRUE(q.Empty()) << "seed " << seed;
    // Written in push order.
    std::vector<int> ids;
    for (StreamSlot* s : written) ids.push_back(Id(s));
    ASSERT_TRUE(std::is_sorted(ids.begin(), ids.end())) << "seed " << seed;
    // Every slot exactly once: written or dropped.
    for (StreamSlot* s : returned) ids.push_back(Id(s));
    std::sort(ids.begin(), ids.end());
    ASSERT_EQ(std::adjacent_find(ids.begin(), ids.end()), ids.end()) << "seed " << seed;
    ASSERT_EQ(ids.size(), pushed.size()) << "seed " << seed;
    ASSERT_EQ(q.written() + q.dropped(), pushed.size()) << "seed " << seed;
  }
}

}  // namespace
}  // namespace cloudcast::server
