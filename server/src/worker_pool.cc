#include "worker_pool.h"

#include <utility>

namespace cloudcast::server {

WorkerPool::WorkerPool(int threads) : size_(threads > 0 ? static_cast<std::size_t>(threads) : 0) {
  threads_.reserve(threads);
  for (int i = 0; i < threads; ++i) {
    threads_.emplace_back([this, i] { Loop(static_cast<std::size_t>(i)); });
  }
}

WorkerPool::~WorkerPool() { Stop(); }

bool WorkerPool::Submit(Task task, std::uint64_t client, std::uint64_t call, std::uint64_t cost) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_) return false;
    tasks_.Push(client, call, cost, std::move(task));
  }
  cv_.notify_one();
  return true;
}

void WorkerPool::Stop() {
  std::lock_guard<std::mutex> stop_lock(stop_mu_);
  {
    std::lock_guard<std::mutex> lock(mu_);
    stopping_ = true;
  }
  cv_.notify_all();
  for (std::thread& t : threads_) {
    if (t.joinable()) t.join();
  }
}

std::size_t WorkerPool::queued() const {
  std::lock_guard<std::mutex> lock(mu_);
  return tasks_.size();
}

void WorkerPool::Loop(std::size_t worker) {
  for (;;) {
    Task task;
    {
      std::unique_lock<std::mutex> lock(mu_);
      cv_.wait(lock, [this] { return stopping_ || !tasks_.empty(); });
      // Drain before exiting: a queued task may hold a reference that only it releases.
      if (tasks_.empty()) return;
      task = tasks_.Pop();
    }
    task(worker);
  }
}

}  // namespace cloudcast::server
