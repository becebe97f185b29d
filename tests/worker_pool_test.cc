// The worker pool's order: fair between clients (deficit round robin, weighted by cost), so one
// client's backlog cannot starve another; and its limits on work memory and large tasks. The
// per-call log rate limit.
#include "worker_pool.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "fair_queue.h"
#include "log_limiter.h"

namespace cloudcast::server {
namespace {

// Defect 4: with a FIFO pool, 64 queued Process frames from one client ran before a paced
// stream's next frame. With one worker held, a backlog of one key and a single task of another:
// the other key's task runs right after the first task of the backlog, not after all of it.
TEST(WorkerPoolTest, AKeysTaskOvertakesAnotherKeysBacklog) {
  WorkerPool pool(1);
  std::mutex mu;
  std::condition_variable cv;
  bool release = false;
  std::vector<std::string> order;
  // The worker is busy until `release`.
  ASSERT_TRUE(pool.Submit(
      [&](std::size_t) {
        std::unique_lock<std::mutex> lock(mu);
        cv.wait(lock, [&] { return release; });
      },
      /*client=*/99, /*call=*/1, WorkerPool::kQuantum));
  for (int i = 0; i < 10; ++i) {
    ASSERT_TRUE(pool.Submit(
        [&, i](std::size_t) {
          std::lock_guard<std::mutex> lock(mu);
          order.push_back("greedy" + std::to_string(i));
        },
        /*client=*/1, /*call=*/1, WorkerPool::kQuantum));
  }
  ASSERT_TRUE(pool.Submit(
      [&](std::size_t) {
        std::lock_guard<std::mutex> lock(mu);
        order.push_back("paced");
      },
      /*client=*/2, /*call=*/2, WorkerPool::kQuantum));
  {
    std::lock_guard<std::mutex> lock(mu);
    release = true;
  }
  cv.notify_all();
  pool.Stop();
  ASSERT_EQ(order.size(), 11u);
  EXPECT_EQ(order[0], "greedy0");
  EXPECT_EQ(order[1], "paced");
  for (int i = 1; i < 10; ++i) EXPECT_EQ(order[i + 1], "greedy" + std::to_string(i));
}

TEST(FairQueueTest, RoundRobinBetweenClientsInArrivalOrderWithinACall) {
  FairQueue<int> q(/*quantum=*/1);
  for (int i = 0; i < 3; ++i) q.Push(/*client=*/1, /*call=*/1, /*cost=*/1, 10 + i);
  for (int i = 0; i < 3; ++i) q.Push(2, 1, 1, 20 + i);
  q.Push(3, 1, 1, 30);
  std::vector<int> order;
  while (!q.empty()) order.push_back(q.Pop());
  EXPECT_EQ(order, (std::vector<int>{10, 20, 30, 11, 21, 12, 22}));
}

TEST(FairQueueTest, CostWeightsTheShares) {
  // Key 1 sends frames 8 times the cost of key 2's: per round, key 2 runs about 8 frames for
  // each of key 1's (by pixels, as the server weighs frames).
  FairQueue<int> q(/*quantum=*/8);
  for (int i = 0; i < 4; ++i) q.Push(1, 1, 8, 100 + i);
  for (int i = 0; i < 32; ++i) q.Push(2, 1, 1, i);
  std::vector<int> order;
  while (!q.empty()) order.push_back(q.Pop());
  ASSERT_EQ(order.size(), 36u);
  // Between two of key 1's frames, key 2 runs 8.
  std::vector<std::size_t> big;
  for (std::size_t i = 0; i < order.size(); ++i) {
    if (order[i] >= 100) big.push_back(i);
  }
  ASSERT_EQ(big.size(), 4u);
  for (std::size_t k = 1; k < big.size(); ++k) EXPECT_EQ(big[k] - big[k - 1], 9u) << k;
}

TEST(FairQueueTest, ATaskCostlierThanTheQuantumStillRuns) {
  FairQueue<int> q(/*quantum=*/2);
  q.Push(1, 1, 100, 1);  // 50 rounds of deficit
  q.Push(2, 1, 1, 2);
  q.Push(2, 1, 1, 3);
  std::vector<int> order;
  while (!q.empty()) order.push_back(q.Pop());
  EXPECT_EQ(order, (std::vector<int>{2, 3, 1}));
}

TEST(FairQueueTest, CallsOfOneClientTakeTurns) {
  // One connection: a greedy stream with a backlog and a paced one with a frame now and then.
  FairQueue<int> q(/*quantum=*/100);
  for (int i = 0; i < 6; ++i) q.Push(/*client=*/1, /*call=*/1, /*cost=*/1, i);
  q.Push(1, 2, 1, 100);
  std::vector<int> order;
  while (!q.empty()) order.push_back(q.Pop());
  EXPECT_EQ(order, (std::vector<int>{0, 100, 1, 2, 3, 4, 5}));
}

TEST(FairQueueTest, PopIfSkipsClientsWhoseNextItemMayNotStartAndKeepsTheirPlace) {
  FairQueue<int> q(/*quantum=*/1);
  q.Push(1, 1, 1, 10);  // client 1's next item may not start (say: it does not fit)
  q.Push(1, 1, 1, 11);
  q.Push(2, 1, 1, 20);
  q.Push(2, 1, 1, 21);
  const auto not_tens = [](int v) { return v / 10 != 1; };
  EXPECT_EQ(q.PopIf(not_tens), std::optional<int>(20));
  EXPECT_EQ(q.PopIf(not_tens), std::optional<int>(21));
  EXPECT_EQ(q.PopIf(not_tens), std::nullopt);  // only client 1's are left
  EXPECT_EQ(q.size(), 2u);
  EXPECT_EQ(q.Pop(), 10);
  EXPECT_EQ(q.Pop(), 11);
  EXPECT_TRUE(q.empty());
}

// Issue 18, defect 3: huge frames on every worker made a camera frame wait for one of them to end
// (1.5 s for 4096x4096). A task over the large cost runs on all workers but one at most.
TEST(WorkerPoolTest, LargeTasksLeaveAWorkerForTheRest) {
  WorkerPool pool(2, WorkerPool::Limits{/*work_memory_bytes=*/~0ull, /*large_cost=*/100});
  std::mutex mu;
  std::condition_variable cv;
  bool release = false;
  int large_running = 0, most_large = 0;
  std::vector<std::string> order;
  auto large = [&](std::size_t) {
    std::unique_lock<std::mutex> lock(mu);
    most_large = std::max(most_large, ++large_running);
    order.push_back("large");
    cv.wait(lock, [&] { return release; });
    --large_running;
  };
  for (int i = 0; i < 4; ++i) ASSERT_TRUE(pool.Submit(large, /*client=*/1, i, /*cost=*/1000));
  // The small one is queued behind four large ones of another client, and still runs at once.
  bool small_ran = false;
  ASSERT_TRUE(pool.Submit(
      [&](std::size_t) {
        {
          std::lock_guard<std::mutex> lock(mu);
          order.push_back("small");
          small_ran = true;
        }
        cv.notify_all();  // the large ones wake, see no release and wait on
      },
      /*client=*/2, /*call=*/9, /*cost=*/10));
  {
    // Waits on the small task itself; the deadline only turns a hang into a failure.
    std::unique_lock<std::mutex> lock(mu);
    EXPECT_TRUE(cv.wait_for(lock, std::chrono::seconds(30), [&] { return small_ran; }))
        << "a small task waited behind large ones on every worker";
  }
  {
    std::lock_guard<std::mutex> lock(mu);
    release = true;
  }
  cv.notify_all();
  pool.Stop();
  EXPECT_EQ(most_large, 1);
  EXPECT_EQ(order.size(), 5u);
}

// Tasks that count how many of them run at once. A task that starts first waits (on the others,
// up to a generous 30 s) until `expected` have run together, then works for 20 ms: two tasks that
// only sleep need not overlap on a loaded machine, and a pool that lets two run at once would be
// seen running one. The 20 ms are the window in which a task the pool should have held back, had
// it started, would be counted.
class Concurrency {
 public:
  explicit Concurrency(int expected) : expected_(expected) {}

  void Run() {
    {
      std::unique_lock<std::mutex> lock(mu_);
      most_ = std::max(most_, ++running_);
      cv_.notify_all();
      if (!cv_.wait_for(lock, std::chrono::seconds(30),
                        [&] { return most_ >= expected_ || gave_up_; })) {
        gave_up_ = true;  // the others go on at once; most() says how many ran together
      }
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));  // the work
    std::lock_guard<std::mutex> lock(mu_);
    --running_;
  }

  int most() const {
    std::lock_guard<std::mutex> lock(mu_);
    return most_;
  }

 private:
  const int expected_;
  mutable std::mutex mu_;
  std::condition_variable cv_;
  int running_ = 0, most_ = 0;
  bool gave_up_ = false;
};

// Defect 4: tasks start only while their stated work memory fits beside the running ones'; the
// pool never states more in use than its limit (but for a lone task, which always may start).
TEST(WorkerPoolTest, TasksStartOnlyWhileTheirWorkMemoryFits) {
  WorkerPool pool(4, WorkerPool::Limits{/*work_memory_bytes=*/100, /*large_cost=*/~0ull});
  Concurrency tasks(/*expected=*/2);
  for (int i = 0; i < 12; ++i) {
    ASSERT_TRUE(pool.Submit([&](std::size_t) { tasks.Run(); },
                            /*client=*/static_cast<std::uint64_t>(i % 3), i, /*cost=*/1,
                            /*work_bytes=*/40));
  }
  pool.Stop();
  EXPECT_EQ(tasks.most(), 2);  // 2 x 40 fit in 100, 3 x 40 do not
  EXPECT_LE(pool.work_bytes_high_water(), 100u);
  EXPECT_EQ(pool.work_bytes_in_use(), 0u);
}

// Defect 3, greedy streams: a client with a backlog on every worker (and so every core) made a
// paced client's frame wait and share the CPU. While two clients are active, neither runs on more
// than all workers but one; alone, a client has them all.
TEST(WorkerPoolTest, AClientLeavesAWorkerWhileAnotherIsActive) {
  for (const bool other_active : {false, true}) {
    SCOPED_TRACE(other_active ? "another client active" : "alone");
    WorkerPool pool(2);
    Concurrency tasks(/*expected=*/other_active ? 1 : 2);
    if (other_active) {
      ASSERT_TRUE(pool.Submit([](std::size_t) {}, /*client=*/2, 1, 1));
    }
    for (int i = 0; i < 8; ++i) {
      ASSERT_TRUE(pool.Submit([&](std::size_t) { tasks.Run(); }, /*client=*/1,
                              /*call=*/1 + i % 2, /*cost=*/1));
    }
    pool.Stop();
    EXPECT_EQ(tasks.most(), other_active ? 1 : 2);
  }
}

// A clock the test moves by hand: the limiter's one-second window passes without sleeping.
class FakeClock {
 public:
  LogLimiter::Now Now() {
    return [this] { return now_.load(); };
  }
  void Advance(std::chrono::milliseconds d) { now_.store(now_.load() + d); }

 private:
  // Far from the steady clock's epoch, as a real one is: a window's start is never special.
  std::atomic<LogLimiter::Clock::time_point> now_{LogLimiter::Clock::time_point{} +
                                                  std::chrono::hours(1)};
};

TEST(LogLimiterTest, LetsPerSecondLinesThroughAndSaysHowManyWereLeftOut) {
  FakeClock clock;
  LogLimiter limiter(3, clock.Now());
  std::uint64_t suppressed = 99;
  for (int i = 0; i < 3; ++i) {
    EXPECT_TRUE(limiter.Allow(&suppressed));
    EXPECT_EQ(suppressed, 0u);
  }
  for (int i = 0; i < 5; ++i) EXPECT_FALSE(limiter.Allow(&suppressed));
  EXPECT_EQ(limiter.total_suppressed(), 5u);
  // Still the same second, a millisecond before its end.
  clock.Advance(std::chrono::milliseconds(999));
  EXPECT_FALSE(limiter.Allow(&suppressed));
  EXPECT_EQ(limiter.total_suppressed(), 6u);
  // A second after the window's first line, the next window opens.
  clock.Advance(std::chrono::milliseconds(1));
  EXPECT_TRUE(limiter.Allow(&suppressed));
  EXPECT_EQ(suppressed, 6u);  // the first line of the next second says so
  EXPECT_TRUE(limiter.Allow(&suppressed));
  EXPECT_EQ(suppressed, 0u);  // and only the first
  EXPECT_TRUE(limiter.Allow(&suppressed));
  EXPECT_FALSE(limiter.Allow(&suppressed));
  EXPECT_EQ(limiter.total_suppressed(), 7u);
}

// A window lasts a second from its first line, not from the last window's end: after a quiet
// spell the next line opens a full window of its own.
TEST(LogLimiterTest, AWindowStartsAtItsFirstLine) {
  FakeClock clock;
  LogLimiter limiter(2, clock.Now());
  std::uint64_t suppressed = 0;
  EXPECT_TRUE(limiter.Allow(&suppressed));
  clock.Advance(std::chrono::milliseconds(2500));
  EXPECT_TRUE(limiter.Allow(&suppressed));  // opens a window at 2.5 s
  clock.Advance(std::chrono::milliseconds(900));
  EXPECT_TRUE(limiter.Allow(&suppressed));
  EXPECT_FALSE(limiter.Allow(&suppressed));  // 3.4 s: still the window of 2.5 s
  clock.Advance(std::chrono::milliseconds(100));
  EXPECT_TRUE(limiter.Allow(&suppressed));  // 3.5 s: a new one
  EXPECT_EQ(suppressed, 1u);
  EXPECT_EQ(limiter.total_suppressed(), 1u);
}

}  // namespace
}  // namespace cloudcast::server
