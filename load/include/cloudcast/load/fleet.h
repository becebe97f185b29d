// A fleet of camera streams against one gRPC target: `streams` concurrent Stream calls over
// `connections` channels, each driven by a callback reactor (no thread per stream), frames sent
// on a fixed open-loop schedule by a few scheduler threads, or closed-loop with K in flight.
//
// Open loop, per stream: frame i is due at its intended time (Schedule). When it is due and the
// stream's previous write has completed, it is written at once; otherwise it waits in the
// stream's queue and goes the moment the write slot frees, never rescheduled (a late send).
// Every answer's latency counts from the intended time, so a slow server cannot hide its stalls
// by slowing the sender (coordinated omission).
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "cloudcast/load/frame_store.h"
#include "cloudcast/load/recorder.h"
#include "cloudcast/load/schedule.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace grpc {
class Channel;
}

namespace cloudcast::load {

struct FleetOptions {
  std::string server = "localhost:50051";  // any gRPC target
  int streams = 1;
  int connections = 0;  // channels; 0: one per stream
  // Open loop when > 0 (ScheduleOptions::start is the per-stream rate); closed loop when 0, with
  // `in_flight` frames awaiting their reply per stream.
  bool closed_loop = false;
  int in_flight = 1;
  ScheduleOptions schedule;
  // Bounds: frames are due only within `duration` (0: no time bound) and at most `frames` in
  // all (0: no count bound), shared out evenly over the streams.
  std::chrono::nanoseconds duration = std::chrono::seconds(10);
  std::uint64_t frames = 0;
  std::chrono::nanoseconds connect_timeout = std::chrono::seconds(5);
  // After the last frame is due: how long answers may take before the calls are cancelled.
  std::chrono::nanoseconds drain_timeout = std::chrono::seconds(5);
  std::uint64_t seed = 1;  // the streams' phases
  int scheduler_threads = 1;
  // The first message of every stream; delivery tells how frames missing at the end count.
  v1::StreamConfig config;
  bool send_config = true;
};

enum class EndReason { kNormal, kTimeout, kCancel };
const char* Name(EndReason reason);  // ghz's words: "normal", "timeout", "cancel"

struct FleetResult {
  EndReason end_reason = EndReason::kNormal;
  std::chrono::system_clock::time_point start;  // the schedule's time zero
  double elapsed_s = 0;                         // from time zero to the last call's end
  double sending_s = 0;                         // from time zero to the last frame sent
};

class Fleet {
 public:
  // Checks the options, creates the channels and waits until each is connected. Errors name
  // the flag (or the target that cannot be reached). `store` must outlive the fleet.
  static absl::StatusOr<std::unique_ptr<Fleet>> Connect(const FleetOptions& options,
                                                        const FrameStore* store);
  ~Fleet();
  Fleet(const Fleet&) = delete;
  Fleet& operator=(const Fleet&) = delete;

  // Opens the streams, runs the schedule, waits for the answers (or the drain timeout), and
  // returns when every call has ended. Call once. `on_second` runs on the calling thread once per
  // second of the run and for the last partial second.
  FleetResult Run(const std::function<void(const SecondStats&)>& on_second = {});

  // From any thread (a signal's): no more frames are sent, answers still due are awaited for
  // the drain timeout, and Run() returns with EndReason::kCancel.
  void Stop();

  Recorder& recorder() { return recorder_; }
  const FleetOptions& options() const { return options_; }

  class Driver;  // one per stream (fleet.cc)

 private:
  Fleet(const FleetOptions& options, const FrameStore* store);
  void Schedule(int shard, const load::Schedule& schedule,
                std::chrono::steady_clock::time_point t0);
  void StreamEnded();
  int OpenStreams() const;

  const FleetOptions options_;
  const FrameStore* store_;
  Recorder recorder_;
  std::vector<std::shared_ptr<grpc::Channel>> channels_;
  std::vector<std::unique_ptr<Driver>> drivers_;

  std::atomic<bool> stop_{false};
  std::mutex mu_;
  std::condition_variable cv_;
  int ended_ = 0;
  int schedulers_running_ = 0;
  bool ran_ = false;
};

// The name of a gRPC status code as gRPC spells it ("OK", "UNAVAILABLE", ...).
const char* CodeName(int code);

}  // namespace cloudcast::load
