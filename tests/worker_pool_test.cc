// The worker pool's order: fair between clients (deficit round robin, weighted by cost), so one
// client's backlog cannot starve another.
#include "worker_pool.h"

#include <gtest/gtest.h>

#include <condition_variable>
#include <mutex>
#include <string>
#include <vector>

#include "fair_queue.h"

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

}  // namespace
}  // namespace cloudcast::server
