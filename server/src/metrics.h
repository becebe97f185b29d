// The server's Prometheus metrics. Counters and histograms are updated on the hot path with a
// handful of atomic adds (histograms take a short lock), never with a look-up by name.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "prometheus/collectable.h"
#include "prometheus/counter.h"
#include "prometheus/family.h"
#include "prometheus/gauge.h"
#include "prometheus/histogram.h"
#include "prometheus/registry.h"

namespace cloudcast::server {

class Metrics {
 public:
  Metrics();
  Metrics(const Metrics&) = delete;
  Metrics& operator=(const Metrics&) = delete;

  // Everything in Prometheus' text format, as /metrics serves it.
  std::string Serialize() const;

  // The errors counter for one status code (labelled with its name, e.g. INVALID_ARGUMENT).
  prometheus::Counter& FrameErrors(absl::StatusCode code);

 private:
  std::shared_ptr<prometheus::Registry> registry_;
  std::shared_ptr<prometheus::Collectable> process_;  // CPU time and resident memory
  prometheus::Family<prometheus::Counter>& frame_errors_family_;

 public:
  prometheus::Counter& frames_processed;  // clouds sent (Stream and Process)
  prometheus::Counter& frames_dropped;    // replaced while waiting (DELIVERY_LATEST)
  prometheus::Counter& bytes_received;    // serialized request size of frames and configs
  prometheus::Counter& bytes_sent;        // serialized reply size
  // The downlink cap (DracoConfig.max_cloud_bytes): clouds sent over it at the floors of the
  // client's bounds (CloudReply.over_cap), and clouds it thinned by raising the voxel minimum
  // (DracoConfig.cap_min_points_per_voxel, contract revision 5).
  prometheus::Counter& replies_over_cap;
  prometheus::Counter& replies_voxels_dropped;
  prometheus::Gauge& active_streams;
  prometheus::Counter& streams_accepted;
  prometheus::Counter& streams_rejected_limit;     // over --max-streams
  prometheus::Counter& streams_rejected_shutdown;  // arrived while shutting down
  // Process calls refused the same ways: at a limit (the server's or the client's share), or
  // while shutting down. Both RPCs are admitted by one path (CallAdmitter).
  prometheus::Counter& process_rejected_limit;
  prometheus::Counter& process_rejected_shutdown;
  prometheus::Counter& streams_idle_timeout;
  // Streams the client cancelled (a rapid reset shows here), and quiet streams the server ended
  // to make room for a new client when it was full (--shed-quiet-after).
  prometheus::Counter& streams_cancelled;
  prometheus::Counter& streams_shed;
  // Log lines left out by the rate limit on per-call lines (a flood of calls cannot flood the log).
  prometheus::Counter& log_lines_suppressed;
  // Calls refused for a missing or invalid bearer token (--tokens-file).
  prometheus::Counter& calls_unauthenticated;

 private:
  prometheus::Family<prometheus::Counter>& unparsable_family_;

 public:
  // Requests whose bytes were not a valid message of their RPC (the call ends).
  prometheus::Counter& stream_requests_unparsable;
  prometheus::Counter& process_requests_unparsable;

 private:
  prometheus::Family<prometheus::Counter>& refused_family_;

 public:
  // Frames refused for memory, before anything was decoded: the server's budget for frames held
  // was in use (--memory-budget-mb), or the frame needs more work memory than the server has
  // (--work-memory-mb). Each is also a FrameError RESOURCE_EXHAUSTED.
  prometheus::Counter& frames_refused_memory_budget;
  prometheus::Counter& frames_refused_work_memory;

 private:
  prometheus::Family<prometheus::Histogram>& stage_family_;

 public:
  // Per-stage latency, seconds.
  prometheus::Histogram& decode_seconds;    // PNG / JPEG decoding (frames that had any)
  prometheus::Histogram& pipeline_seconds;  // conversion + passthrough + voxel grid
  prometheus::Histogram& encode_seconds;    // Draco
  prometheus::Histogram& match_seconds;     // stereo pairs: rectification, grey and matching
  prometheus::Histogram& queue_seconds;     // received -> a worker starts on it
  prometheus::Histogram& total_seconds;     // received -> reply handed to gRPC
  // CPU time of the worker thread inside the core pipeline and Draco, and in the whole frame
  // task (decode, checks, reply). Against the process' CPU time these give the share spent
  // outside the core (transport, protobuf, scheduling).
  prometheus::Counter& core_cpu_seconds;
  prometheus::Counter& worker_cpu_seconds;
};

}  // namespace cloudcast::server
