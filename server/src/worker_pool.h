// A fixed set of threads that run tasks in submission order. The server processes frames here,
// never on gRPC's own threads, so a slow frame cannot stall the transport.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

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

  // Queues `task`; false (and the task is dropped unrun) once Stop() has begun.
  bool Submit(Task task);

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
  std::deque<Task> tasks_;
  bool stopping_ = false;
  std::vector<std::thread> threads_;
};

}  // namespace cloudcast::server
