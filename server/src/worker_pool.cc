#include "worker_pool.h"

#include <algorithm>
#include <optional>
#include <utility>

namespace cloudcast::server {

WorkerPool::WorkerPool(int threads, const Limits& limits)
    : size_(threads > 0 ? static_cast<std::size_t>(threads) : 0),
      limits_(limits),
      max_large_(std::max<std::size_t>(1, size_ > 0 ? size_ - 1 : 0)) {
  threads_.reserve(threads);
  for (int i = 0; i < threads; ++i) {
    threads_.emplace_back([this, i] { Loop(static_cast<std::size_t>(i)); });
  }
}

WorkerPool::~WorkerPool() { Stop(); }

bool WorkerPool::Submit(Task task, std::uint64_t client, std::uint64_t call, std::uint64_t cost,
                        std::uint64_t work_bytes) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_) return false;
    clients_[client].last_submit = std::chrono::steady_clock::now();
    tasks_.Push(client, call, cost,
                Queued{std::move(task), client, work_bytes, cost > limits_.large_cost});
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

std::uint64_t WorkerPool::work_bytes_in_use() const {
  std::lock_guard<std::mutex> lock(mu_);
  return work_in_use_;
}

std::uint64_t WorkerPool::work_bytes_high_water() const {
  std::lock_guard<std::mutex> lock(mu_);
  return work_high_water_;
}

std::size_t WorkerPool::ActiveClients() {
  const auto now = std::chrono::steady_clock::now();
  for (auto it = clients_.begin(); it != clients_.end();) {
    if (it->second.running == 0 && now - it->second.last_submit > std::chrono::seconds(1)) {
      it = clients_.erase(it);
    } else {
      ++it;
    }
  }
  return clients_.size();
}

bool WorkerPool::MayStart(const Queued& q) const {
  if (running_ == 0) return true;
  if (q.large && large_running_ >= max_large_) return false;
  if (size_ >= 2 && active_clients_ >= 2) {
    const auto it = clients_.find(q.client);
    if (it != clients_.end() && it->second.running >= size_ - 1) return false;
  }
  return q.work_bytes <= limits_.work_memory_bytes &&
         work_in_use_ <= limits_.work_memory_bytes - q.work_bytes;
}

void WorkerPool::Loop(std::size_t worker) {
  for (;;) {
    std::optional<Queued> next;
    {
      std::unique_lock<std::mutex> lock(mu_);
      for (;;) {
        if (!tasks_.empty()) {
          active_clients_ = ActiveClients();
          next = tasks_.PopIf([this](const Queued& q) { return MayStart(q); });
          if (next) break;
        } else if (stopping_) {
          return;  // drained: a queued task may hold a reference that only it releases
        }
        // Woken when a task ends or arrives; the timeout notices a client that went quiet.
        cv_.wait_for(lock, std::chrono::milliseconds(100));
      }
      ++running_;
      ++clients_[next->client].running;
      large_running_ += next->large ? 1 : 0;
      work_in_use_ += next->work_bytes;
      work_high_water_ = std::max(work_high_water_, work_in_use_);
    }
    next->task(worker);
    {
      std::lock_guard<std::mutex> lock(mu_);
      --running_;
      --clients_[next->client].running;
      large_running_ -= next->large ? 1 : 0;
      work_in_use_ -= next->work_bytes;
    }
    // What was waiting for this task's memory or its large-task place may start now.
    cv_.notify_all();
  }
}

}  // namespace cloudcast::server
