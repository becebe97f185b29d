#include "open_streams.h"

#include <algorithm>
#include <string>
#include <unordered_map>

#include "absl/strings/str_cat.h"
#include "call_helpers.h"
#include "stream_reactor.h"

namespace cloudcast::server {

OpenStreams::Snapshot::~Snapshot() {
  for (StreamReactor* s : streams_) s->Unref();
}

void OpenStreams::Add(StreamReactor* stream) {
  std::lock_guard<std::mutex> lock(mu_);
  streams_.insert(stream);
}

void OpenStreams::Remove(StreamReactor* stream) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    streams_.erase(stream);
  }
  cv_.notify_all();
}

OpenStreams::Snapshot OpenStreams::Take() {
  Snapshot snapshot;
  std::lock_guard<std::mutex> lock(mu_);
  for (StreamReactor* s : streams_) {
    s->Ref();
    snapshot.streams_.push_back(s);
  }
  return snapshot;
}

void OpenStreams::ProcessDone() {
  process_calls_.fetch_sub(1);
  // Taken so that a waiter cannot miss the wake-up between its check and its wait.
  std::lock_guard<std::mutex> lock(mu_);
  cv_.notify_all();
}

bool OpenStreams::idle() {
  std::lock_guard<std::mutex> lock(mu_);
  return streams_.empty() && process_calls_.load() == 0;
}

bool OpenStreams::WaitUntilIdle(std::chrono::steady_clock::time_point deadline) {
  std::unique_lock<std::mutex> lock(mu_);
  return cv_.wait_until(lock, deadline,
                        [this] { return streams_.empty() && process_calls_.load() == 0; });
}

bool OpenStreams::ShedQuietest(const Caller& newcomer, std::chrono::milliseconds quiet_after,
                               std::uint32_t max_streams, Metrics* metrics, CallLog* log) {
  if (quiet_after.count() == 0) return false;
  const Snapshot streams = Take();
  // The quiet streams of each client (never the newcomer's own).
  const Clock::time_point now = Clock::now();
  std::unordered_map<std::string, int> per_client;
  struct Quiet {
    StreamReactor* stream;
    Clock::duration quiet;
  };
  std::vector<Quiet> quiet;
  for (StreamReactor* s : streams) {
    if (s->client() == newcomer.client.key) continue;
    ++per_client[s->client()];
    if (auto q = s->QuietFor(now); q && *q >= quiet_after) quiet.push_back({s, *q});
  }
  // The client holding the most streams gives first, its quietest stream first.
  std::sort(quiet.begin(), quiet.end(), [&](const Quiet& a, const Quiet& b) {
    const int na = per_client[a.stream->client()], nb = per_client[b.stream->client()];
    return na != nb ? na > nb : a.quiet > b.quiet;
  });
  for (const Quiet& q : quiet) {
    const double s = Seconds(q.quiet);
    if (q.stream->Shed(grpc::Status(
            grpc::StatusCode::UNAVAILABLE,
            absl::StrCat("the server is full (--max-streams ", max_streams,
                         ") and this stream sent no frame for ", static_cast<int>(s),
                         " s: ended to make room for another client (--shed-quiet-after)")))) {
      metrics->streams_shed.Increment();
      log->Log(spdlog::level::info, "stream of {} shed after {} s without a frame, for {}",
               q.stream->client(), s, newcomer.label);
      return true;
    }
  }
  return false;
}

void OpenStreams::NoteQueued(std::uint32_t held) {
  std::uint32_t seen = queued_high_water_.load(std::memory_order_relaxed);
  while (held > seen && !queued_high_water_.compare_exchange_weak(seen, held)) {
  }
}

}  // namespace cloudcast::server
