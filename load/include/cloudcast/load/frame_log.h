// cloudcast-load --frame-log: one CSV line per answered frame, saying where its time went. The
// report's percentiles say how late the worst frames were; this says which way each one waited:
// the load's write, the server's receipt and send (CloudReply's clock), the load's receipt, all
// on the Unix clock, with the frame's and the reply's bytes and what the server spent on it.
// Client and server on one host (or with synchronised clocks: PTP) make each way's delay
// absolute; otherwise only its changes mean anything (the offset is constant).
//
// Opt-in and per frame, unlike the report (ghz's JSON keeps no per-request details for the same
// reason: a fleet of thousands of streams writes megabytes a second); lines are buffered and
// written under a lock, off nothing the schedule waits for.
#pragma once

#include <cstdint>
#include <fstream>
#include <memory>
#include <mutex>
#include <string>
#include <utility>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace cloudcast::load {

struct FrameLogRow {
  int stream = 0;
  std::uint64_t sequence = 0;
  std::int64_t intended_unix_ns = 0;  // the schedule's send time
  std::int64_t written_unix_ns = 0;   // the frame's (latest) write started
  // The server's (CloudReply receive_time_unix_ns, send_time_unix_ns; 0: not sent).
  std::int64_t server_receive_unix_ns = 0;
  std::int64_t server_send_unix_ns = 0;
  std::int64_t received_unix_ns = 0;  // its reply arrived whole
  std::uint64_t image_bytes = 0;      // the frame's images as sent
  std::uint64_t reply_bytes = 0;
  std::uint32_t points = 0;
  int position_bits = 0;
  bool over_cap = false;  // the cloud stayed over its cap at the floors (CloudReply.over_cap)
  // The server's stage times (CloudReply.times), microseconds.
  std::uint32_t queue_us = 0, decode_us = 0, rectify_us = 0, match_us = 0, pipeline_us = 0,
                encode_us = 0;
  std::uint64_t reply_cap_bytes = 0;  // the cap the stream had asked for (0: none)
  std::string instance;               // the replica that answered
};

class FrameLog {
 public:
  // Creates (truncates) `path` and writes the header line; the error names `flag`.
  static absl::StatusOr<std::unique_ptr<FrameLog>> Open(const std::string& path,
                                                        const std::string& flag);
  // Thread-safe.
  void Add(const FrameLogRow& row);
  // Flushes; an error if any write failed (a full disk).
  absl::Status Close();

 private:
  FrameLog(std::string path, std::string flag) : path_(std::move(path)), flag_(std::move(flag)) {}

  const std::string path_, flag_;
  std::mutex mu_;
  std::ofstream out_;
};

}  // namespace cloudcast::load
