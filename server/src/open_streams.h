// The calls open now: every Stream reactor (for the idle check, draining and shedding) and the
// count of Process calls, so that shutdown can wait for both. Also the most frames one stream
// held at once. Thread-safe; lock order: this registry's, then a stream's own.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <set>
#include <vector>

#include "call_log.h"
#include "caller.h"
#include "metrics.h"

namespace cloudcast::server {

class StreamReactor;

class OpenStreams {
 public:
  // The streams open when it was taken, each held by a reference until the list goes.
  class Snapshot {
   public:
    Snapshot() = default;
    Snapshot(Snapshot&& other) noexcept : streams_(std::move(other.streams_)) {}
    Snapshot& operator=(Snapshot&&) = delete;
    ~Snapshot();
    std::vector<StreamReactor*>::const_iterator begin() const { return streams_.begin(); }
    std::vector<StreamReactor*>::const_iterator end() const { return streams_.end(); }
    std::size_t size() const { return streams_.size(); }

   private:
    friend class OpenStreams;
    std::vector<StreamReactor*> streams_;
  };

  void Add(StreamReactor* stream);
  void Remove(StreamReactor* stream);
  Snapshot Take();

  void ProcessStarted() { process_calls_.fetch_add(1); }
  void ProcessDone();
  // No stream and no Process call open.
  bool idle();
  // Waits until idle() or `deadline`; true if idle.
  bool WaitUntilIdle(std::chrono::steady_clock::time_point deadline);

  // When the server is full: ends the stream that has been quiet longest (no frame for
  // `quiet_after` or more) of the client holding the most streams, never `newcomer`'s; true if
  // one was ended (its place is free). `max_streams` is for its status message.
  bool ShedQuietest(const Caller& newcomer, std::chrono::milliseconds quiet_after,
                    std::uint32_t max_streams, Metrics* metrics, CallLog* log);

  void NoteQueued(std::uint32_t held);
  std::uint32_t queued_high_water() const { return queued_high_water_.load(); }
  void ResetQueuedHighWater() { queued_high_water_.store(0); }

 private:
  std::mutex mu_;
  std::condition_variable cv_;  // a stream or Process call went
  std::set<StreamReactor*> streams_;
  std::atomic<int> process_calls_{0};
  std::atomic<std::uint32_t> queued_high_water_{0};
};

}  // namespace cloudcast::server
