// What a client receives for one frame: the decoded cloud and the server's metadata, or the
// server's error for that frame, plus the client-side times needed to measure latency.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "cloudcast/client/rate_controller.h"
#include "cloudcast/client/stream_machine.h"
#include "cloudcast/core/point.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace cloudcast::client {

// Client clocks around one frame. Steady times measure durations on this machine; Unix times
// compare with the server's and with capture times.
struct ClientTimes {
  // Just before the frame was handed to gRPC. Default-constructed (epoch) when unknown.
  std::chrono::steady_clock::time_point send;
  std::int64_t send_unix_ns = 0;
  // When the reply had arrived, before Draco decoding.
  std::chrono::steady_clock::time_point receive;
  std::int64_t receive_unix_ns = 0;
  // Time spent decoding the Draco cloud on this machine.
  std::int64_t decode_us = 0;
};

struct Result {
  // OK: `cloud` and `reply` hold the frame's cloud. Otherwise why this frame has none: the
  // server's FrameError (its google.rpc code, INVALID_ARGUMENT or RESOURCE_EXHAUSTED, and a
  // message naming the field and the limit), DATA_LOSS when the Draco bytes did not decode, or
  // (streams) the frame's fate when it got no reply at all: ABORTED for a frame replaced or
  // dropped under DELIVERY_LATEST; for one lost or never sent when the stream ended, the code
  // the stream ended with (UNAVAILABLE when the server went away, UNAUTHENTICATED or
  // RESOURCE_EXHAUSTED when it refused the call, CANCELLED after Cancel).
  absl::Status status;

  // Streams: how this frame ended. Every frame a Stream accepted comes back exactly once, as an
  // answer (a cloud or the server's error) or as one of the other fates (frame_id, sequence,
  // capture time and send time from the client's record of it; no reply, no cloud).
  FrameFate fate = FrameFate::kAnswered;

  // Echoed from the frame (set for clouds and errors alike; FrameError does not echo the
  // capture time, so errors on a stream take it from the client's record of the frame).
  std::uint64_t sequence = 0;
  std::string frame_id;
  std::int64_t capture_time_unix_ns = 0;
  // Frames skipped on this stream so far (DELIVERY_LATEST only): by the server, and by a
  // resilient stream's reconnects.
  std::uint64_t frames_dropped = 0;
  // Frames this stream replaced so far before sending them (DELIVERY_LATEST: a newer frame came
  // while they waited for the write slot). Each also comes back as a Result of its own.
  std::uint64_t frames_replaced = 0;
  // The replica that answered (its --instance); empty for frames a stream gave up on.
  std::string server_instance;
  // The error answers a StreamConfig (OpenStream's or a Reconfigure), not a frame: the server
  // keeps the previous settings, and sequence / frame_id are 0 / empty. Streams only.
  bool config_rejected = false;
  // The video bitstreams (v1::VIDEO_BITSTREAM_COLOR, _RIGHT) the server cannot decode until an
  // IDR, as its reply says (CloudReply.keyframe_needed, or the FrameError's): the sender's next
  // picture of each is to be a keyframe. Empty without video, and for frames that got no reply.
  std::vector<v1::VideoBitstream> keyframe_needed;
  // StreamOptions::rate_control: the rate controller's estimate after this reply (its target
  // bitrate, round trip, queueing delay, window). Unset without rate control and for frames that
  // got no reply.
  std::optional<RateEstimate> rate;
  // The resolution the frame went at: 1, the camera's; 2, half its width and height (the floor
  // of a rate-controlled coder, StreamOptions::coder: AdaptiveJpegCoder), with a camera halved to
  // match. Set for every frame that was made (sent or not); 1 for frames replaced before it.
  int resolution_divisor = 1;

  // The decoded cloud: unorganized, finite points, alpha 255. Empty on errors, when the filters
  // left nothing, or with ClientOptions::decode_clouds off.
  PointCloud cloud;
  // The server's reply: Draco bytes (kept, e.g. to save as .drc), point_count,
  // position_error_bound, position_bits, stage counts and times, server clock stamps.
  // Default-valued on errors.
  v1::CloudReply reply;

  ClientTimes times;

  bool ok() const { return status.ok(); }
  std::size_t draco_bytes() const { return reply.draco().size(); }
  // Capture to arrival of the reply, in this machine's clock. Includes the time before Send when
  // the caller set FrameMeta::capture_time_unix_ns; excludes Draco decoding.
  std::chrono::nanoseconds latency() const {
    return std::chrono::nanoseconds(times.receive_unix_ns - capture_time_unix_ns);
  }
  // Send to arrival, steady clock: network both ways + queueing + server work.
  std::chrono::nanoseconds round_trip() const { return times.receive - times.send; }
};

}  // namespace cloudcast::client
