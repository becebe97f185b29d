// A fleet of camera streams against one gRPC target: `streams` concurrent Stream calls over
// `connections` channels, each driven by a callback reactor (no thread per stream), frames sent
// on a fixed open-loop schedule by a few scheduler threads, or closed-loop with K in flight.
//
// Open loop, per stream: frame i is due at its intended time (Schedule). When it is due and the
// stream's previous write has completed, it is written at once; otherwise it waits in the
// stream's queue and goes the moment the write slot frees, never rescheduled (a late send).
// Every answer's latency counts from the intended time, so a slow server cannot hide its stalls
// by slowing the sender (coordinated omission).
//
// Each stream is the client library's stream core (cloudcast/client/stream_core.h), as robots
// run it: with DELIVERY_LATEST a frame still waiting for the write slot when the next is due is
// replaced (counted as replaced); with DELIVERY_ALL every frame waits its turn.
//
// Video streams (a FrameStore with video(), --encoding h264) send the store's picture sequence in
// order from its IDR, and a picture sent is never replaced: the pictures after it reference it.
// So under DELIVERY_LATEST such a stream lets one frame wait for the write slot and skips (never
// encodes) a frame due while one waits, counted as skipped; the server still skips stale frames
// after decoding them. A reply whose keyframe_needed names a bitstream sends the sequence back to
// its start (an IDR) unless an IDR went after the frame it answers.
//
// Resilient streams (FleetOptions::resilient): a stream is a sequence of calls. When a call ends
// with UNAVAILABLE (a replica killed, drained, or sending GOAWAY), the stream opens a new one (the
// channel's round_robin picks a live replica), sends its StreamConfig again and, in DELIVERY_ALL,
// every frame that was sent and not answered, with its intended time unchanged: latency keeps
// counting from it. Answers are counted once per sequence. After `reconnect_timeout` without a
// working call the stream gives up and reports every unanswered frame lost.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "cloudcast/client/options.h"
#include "cloudcast/client/security.h"
#include "cloudcast/load/frame_log.h"
#include "cloudcast/load/frame_store.h"
#include "cloudcast/load/recorder.h"
#include "cloudcast/load/schedule.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace grpc {
class Channel;
}

namespace cloudcast::load {

struct FleetOptions {
  std::string server = client::kDefaultTarget;  // any gRPC target
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
  std::chrono::nanoseconds connect_timeout = client::ClientOptions{}.connect_timeout;
  // After the last frame is due: how long answers may take before the calls are cancelled.
  std::chrono::nanoseconds drain_timeout = std::chrono::seconds(5);
  std::uint64_t seed = 1;  // the streams' phases
  int scheduler_threads = 1;
  // The first message of every stream; delivery tells how frames missing at the end count.
  v1::StreamConfig config;
  bool send_config = true;
  // How calls are spread over the addresses the target resolves to: "round_robin" (with
  // client-side health checking of cloudcast.v1.CloudCast, so a draining replica gets no new
  // calls), "pick_first", or "" for DefaultLbPolicy(server).
  std::string lb_policy;
  bool resilient = false;
  std::chrono::nanoseconds reconnect_timeout = client::StreamOptions{}.reconnect_timeout;
  // The adaptive sender (client::RateControlOptions): each stream's rate controller sets its
  // window and picks each frame's level of the store's ladder (FrameSourceOptions::jpeg_ladder)
  // from its target bitrate at the schedule's rate. Unset: a fixed encoding.
  std::optional<client::RateControlOptions> rate_control;
  // TLS and the bearer token of every channel (cloudcast/client/security.h); default plaintext.
  client::ChannelSecurity security;
  // A line per answered frame (--frame-log); the caller's, open for the whole run. Null: none.
  FrameLog* frame_log = nullptr;
};

// round_robin for a target that names several addresses ("ipv4:a:p,b:p", "ipv6:...") or asks
// the DNS resolver for all of them ("dns:///name:port"), else pick_first (gRPC's default).
std::string DefaultLbPolicy(const std::string& target);

// The addresses an "ipv4:" / "ipv6:" target lists; 0 for any other target (the resolver decides).
int ListedAddresses(const std::string& target);

// One stream's account, for the per-stream report. Every frame due ends in exactly one of
// answered, frame_errors, dropped, lost, replaced, skipped or unsent.
struct StreamStats {
  int index = 0;
  std::uint64_t sent = 0;             // distinct frames sent (a resend is not counted again)
  std::uint64_t answered = 0;         // clouds
  std::uint64_t frame_errors = 0;     // FrameError replies
  std::uint64_t resent = 0;           // frames written again on a new call (DELIVERY_ALL)
  std::uint64_t lost = 0;             // sent, never answered, reported lost
  std::uint64_t dropped = 0;          // skipped (DELIVERY_LATEST)
  std::uint64_t unsent = 0;           // due, never sent
  std::uint64_t replaced = 0;         // due, replaced by a newer frame before it was sent (LATEST)
  std::uint64_t skipped = 0;          // due, not encoded: a video frame already waited (LATEST)
  std::uint64_t keyframe_needed = 0;  // video: replies asking for an IDR
  std::uint64_t duplicates = 0;       // answers to a sequence already answered (ignored)
  int calls = 0;                      // gRPC calls the stream used
  int reconnect_attempts = 0;         // calls opened after a failure
  // Reconnects that worked: from the failure to the new call having written the config and every
  // frame it sent again, ns.
  std::vector<std::int64_t> reconnect_ns;
  std::vector<std::string> replicas;  // the replica of each call that answered, in order
  std::string end_status;             // the last call's status code
  bool gave_up = false;               // reconnect_timeout passed without a working call
};

enum class EndReason { kNormal, kTimeout, kCancel };
const char* Name(EndReason reason);  // ghz's words: "normal", "timeout", "cancel"

struct FleetResult {
  EndReason end_reason = EndReason::kNormal;
  std::chrono::system_clock::time_point start;  // the schedule's time zero
  double elapsed_s = 0;                         // from time zero to the last call's end
  double sending_s = 0;                         // from time zero to the last frame sent
  // The generator's own CPU time during Run (user + system, every thread of the process): what
  // it costs to drive the streams.
  double cpu_s = 0;
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
  // After Run: each stream's account, in stream order.
  std::vector<StreamStats> streams() const;
  // The load-balancing policy the channels use, and the replicas (GetInfo's instance names) that
  // answered on them before the streams opened.
  const std::string& lb_policy() const { return lb_policy_; }
  const std::vector<std::string>& replicas_at_start() const { return replicas_at_start_; }
  // The most addresses that answered on one channel then (0 without round_robin).
  int replicas_answering() const { return replicas_answering_; }

  class Driver;  // one per stream (fleet.cc)

 private:
  Fleet(const FleetOptions& options, const FrameStore* store);
  void Schedule(int shard, const load::Schedule& schedule,
                std::chrono::steady_clock::time_point t0);
  void WarmUp(std::chrono::system_clock::time_point deadline);
  void StreamEnded();
  int OpenStreams() const;

  const FleetOptions options_;
  const FrameStore* store_;
  Recorder recorder_;
  std::vector<std::shared_ptr<grpc::Channel>> channels_;
  std::vector<std::unique_ptr<Driver>> drivers_;
  std::string lb_policy_;
  std::vector<std::string> replicas_at_start_;
  int replicas_answering_ = 0;

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
