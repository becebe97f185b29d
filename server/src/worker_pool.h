// A fixed set of threads that run tasks fairly between clients and between each client's calls
// (FairQueue). The server processes frames here, never on gRPC's own threads, so a slow frame
// cannot stall the transport; with the client (its address or tenant), the call and the frame's
// pixels as cost, one client's backlog cannot starve another, however many connections it uses.
//
// Two limits decide when a task may start, so that no one client's frames can take every worker
// or the server's memory:
//   - work memory: each task states the bytes it will need (a frame's decoded images and the
//     pipeline's working memory, estimated from its header before anything is decoded); a task
//     starts only while the tasks running plus it fit in `work_memory_bytes`;
//   - large tasks (cost over `large_cost`) run on at most all workers but one, so that a worker is
//     always left for ordinary frames while huge ones are processed (with one worker: one);
//   - while two or more clients are active (a task of theirs queued, running, or submitted in the
//     last second), no client runs on more than all workers but one: a greedy client cannot take
//     every worker, and every core, from a paced one, whose next frame then starts at once. A
//     client alone has them all.
// When no task is running, the next one starts whatever it states (progress, whatever the limits).
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <mutex>
#include <thread>
#include <unordered_map>
#include <vector>

#include "fair_queue.h"

namespace cloudcast::server {

class WorkerPool {
 public:
  // A task learns which worker runs it (0 .. size() - 1), so that it can use that worker's own
  // scratch (a Pipeline is not thread-safe, one per worker is).
  using Task = std::function<void(std::size_t worker)>;

  struct Limits {
    std::uint64_t work_memory_bytes = std::numeric_limits<std::uint64_t>::max();
    std::uint64_t large_cost = std::numeric_limits<std::uint64_t>::max();
  };

  explicit WorkerPool(int threads) : WorkerPool(threads, Limits()) {}
  WorkerPool(int threads, const Limits& limits);
  ~WorkerPool();  // Stop()
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  // A turn's worth of cost: one 640x480 frame and some, in pixels.
  static constexpr std::uint64_t kQuantum = std::uint64_t{1} << 19;

  // Queues `task` for `client` and its `call` at `cost`, needing `work_bytes` of work memory
  // while it runs; false (and the task is dropped unrun) once Stop() has begun.
  bool Submit(Task task, std::uint64_t client, std::uint64_t call, std::uint64_t cost,
              std::uint64_t work_bytes = 0);

  // Runs every task already queued, then joins the threads. Idempotent.
  void Stop();

  std::size_t size() const { return size_; }
  std::size_t queued() const;
  // Work memory the running tasks stated, and the most it has been.
  std::uint64_t work_bytes_in_use() const;
  std::uint64_t work_bytes_high_water() const;
  const Limits& limits() const { return limits_; }

 private:
  struct Queued {
    Task task;
    std::uint64_t client;
    std::uint64_t work_bytes;
    bool large;
  };
  struct ClientState {
    std::size_t running = 0;
    std::chrono::steady_clock::time_point last_submit;
  };
  bool MayStart(const Queued& q) const;  // under mu_
  // Clients active now: a task running or submitted within the last second (under mu_; forgets
  // the others).
  std::size_t ActiveClients();
  void Loop(std::size_t worker);

  const std::size_t size_;
  const Limits limits_;
  const std::size_t max_large_;  // large tasks running at once
  std::mutex stop_mu_;           // serialises Stop(): threads are joined once
  mutable std::mutex mu_;
  std::condition_variable cv_;
  FairQueue<Queued> tasks_{kQuantum};
  bool stopping_ = false;
  std::size_t running_ = 0, large_running_ = 0;  // under mu_
  std::uint64_t work_in_use_ = 0, work_high_water_ = 0;
  std::unordered_map<std::uint64_t, ClientState> clients_;
  std::size_t active_clients_ = 0;  // as of the last ActiveClients()
  std::vector<std::thread> threads_;
};

}  // namespace cloudcast::server
