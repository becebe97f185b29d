// A fixed set of threads that run tasks fairly between clients and between each client's calls
// (FairQueue). The server processes frames here, never on gRPC's own threads, so a slow frame
// cannot stall the transport; with the client's connection, the call and the frame's pixels as
// cost, one client's backlog cannot starve another.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

#include "fair_queue.h"

namespace cloudcast::server {

class WorkerPool {
 public:
  // A task learns which worker runs it (0 .. size() - 1), so that it can use that worker's own
  // scratch (a Pipeline is not thread-safe, one per worker is).
  using Task = std::function<void(std::size_t worker)>;

  explicit WorkerPool(int threads);
  ~WorkerPool();  // Stop()
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  // A turn's worth of cost: one 640x480 frame and some, in pixels.
  static constexpr std::uint64_t kQuantum = std::uint64_t{1} << 19;

  // Queues `task` for `client` and its `call` at `cost`; false (and the task is dropped unrun)
  // once Stop() has begun.
  bool Submit(Task task, std::uint64_t client, std::uint64_t call, std::uint64_t cost);

  // Runs every task already queued, then joins the threads. Idempotent.
  void Stop();

  std::size_t size() const { return size_; }
  std::size_t queued() const;

 private:
  void Loop(std::size_t worker);

  const std::size_t size_;
  std::mutex stop_mu_;  // serialises Stop(): threads are joined once
  mutable std::mutex mu_;
  std::condition_variable cv_;
  FairQueue<Task> tasks_{kQuantum};
  bool stopping_ = false;
  std::vector<std::thread> threads_;
};

}  // namespace cloudcast::server
