// Actions run a while later on a thread of their own: the server answers a call it refuses for
// memory after a pause (--refusal-delay), so that a client sending frames it can never have
// processed, call after call, slows down to its share of places per pause instead of making the
// transport take thousands of them a second. Flush() runs every pending action at once (the
// server is shutting down); so does the destructor. Thread-safe.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <queue>
#include <thread>
#include <utility>
#include <vector>

namespace cloudcast::server {

class DelayedActions {
 public:
  using Clock = std::chrono::steady_clock;

  DelayedActions() : thread_([this] { Loop(); }) {}
  ~DelayedActions() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }
  DelayedActions(const DelayedActions&) = delete;
  DelayedActions& operator=(const DelayedActions&) = delete;

  // Runs `action` at `when` (at once after Flush or during destruction).
  void RunAt(Clock::time_point when, std::function<void()> action) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (!flushed_ && !stop_) {
        queue_.push(Entry{when, next_++, std::move(action)});
        cv_.notify_all();
        return;
      }
    }
    action();
  }

  // Every pending action now, and every later one at once.
  void Flush() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      flushed_ = true;
    }
    cv_.notify_all();
  }

 private:
  struct Entry {
    Clock::time_point when;
    std::uint64_t order;  // ties keep their order
    std::function<void()> action;
    bool operator>(const Entry& o) const {
      return when != o.when ? when > o.when : order > o.order;
    }
  };

  void Loop() {
    std::unique_lock<std::mutex> lock(mu_);
    for (;;) {
      if (queue_.empty()) {
        if (stop_) return;
        cv_.wait(lock);
        continue;
      }
      if (!flushed_ && !stop_ && Clock::now() < queue_.top().when) {
        cv_.wait_until(lock, queue_.top().when);
        continue;
      }
      std::function<void()> action = std::move(const_cast<Entry&>(queue_.top()).action);
      queue_.pop();
      lock.unlock();
      action();
      lock.lock();
    }
  }

  std::mutex mu_;
  std::condition_variable cv_;
  std::priority_queue<Entry, std::vector<Entry>, std::greater<Entry>> queue_;
  std::uint64_t next_ = 0;
  bool flushed_ = false;
  bool stop_ = false;
  std::thread thread_;  // last: it starts once the rest is ready
};

}  // namespace cloudcast::server
