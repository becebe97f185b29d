// The bridge's side of the cloudcast stream: one Client, one Stream at a time (resilient by
// default), opened on the first frame and again after a stream has ended; the first frame's
// camera sent as the stream's config, and each frame's camera (its CameraInfo's) as its
// Frame.camera; each reply matched to the header of its frame. The stream is the client library's stream core (cloudcast/client/stream_core.h):
// with delivery latest (the bridge's setting, or the server's default when the bridge leaves it
// unset) Send never waits for the network; a frame still waiting to be sent when the next comes
// is replaced, and counted with the stream's drops.
//
// Transport-free (no ROS 1 or ROS 2 header): frames carry the core's MessageHeader, and the link
// logs through the LogSink its bridge gives it (rosconsole for ROS 1, ros2/src/log.h for ROS 2).
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "bridge_options.h"
#include "cloudcast/client/client.h"
#include "diagnostics.h"
#include "input_source.h"
#include "message_views.h"

namespace cloudcast::client {
class AdaptiveJpegCoder;  // cloudcast/client/adaptive_jpeg_coder.h (~encoding jpeg)
}  // namespace cloudcast::client

namespace cloudcast::ros_bridge {

// What the bridge keeps of a frame it sent, for its reply.
struct SentFrame {
  MessageHeader header;     // the input's: the cloud gets its stamp and frame_id
  CameraModel camera;       // the frame's camera (a DisparityImage's f and T)
};

enum class LogLevel { kInfo, kWarn, kError };
// Where the link's log lines go (any thread; the link adds no prefix and throttles its
// per-frame lines to one per 5 s per kind itself).
using LogSink = std::function<void(LogLevel, const std::string&)>;

class CloudLink {
 public:
  // Called on a gRPC callback thread for each cloud (one at a time, in order), with what was
  // kept of its frame.
  using CloudSink = std::function<void(client::Result&&, const SentFrame&)>;

  CloudLink(const BridgeOptions& options, BridgeStats* stats, CloudSink on_cloud, LogSink log);
  // Closes the stream: the replies still due are published for up to two seconds, then the
  // stream is cancelled.
  ~CloudLink();
  CloudLink(const CloudLink&) = delete;
  CloudLink& operator=(const CloudLink&) = delete;

  // Waits up to ~connect_timeout for the server and says what it found (for the start-up log).
  absl::StatusOr<v1::ServerInfo> Probe();

  // Sends one frame (ROS callback thread). Failures are counted and logged, never thrown: a
  // frame without a stream is dropped, and the next frame tries to open one (at most once a
  // second).
  void Send(const OutgoingFrame& frame);

 private:
  absl::Status EnsureStream(const CameraModel& camera);
  client::StreamConfig StreamConfigFor(const CameraModel& camera) const;
  void CloseStream(const absl::Status& why);
  void OnResult(client::Result&& result);
  // The per-frame lines, at most one per 5 s of each kind (as ROS_*_THROTTLE(5, ...)).
  enum Throttled { kNotSent, kRefused, kFrameFailed, kUnknownReply, kThrottledKinds };
  void LogThrottled(Throttled kind, LogLevel level, const std::string& message);

  const BridgeOptions options_;
  BridgeStats* const stats_;
  CloudSink on_cloud_;
  LogSink log_;
  std::mutex log_mu_;
  std::array<std::chrono::steady_clock::time_point, kThrottledKinds> last_logged_{};
  std::unique_ptr<client::Client> client_;
  std::unique_ptr<client::Stream> stream_;
  std::optional<CameraModel> camera_;  // the last frame's (the stream's config has the first's)
  // ~encoding jpeg: the stream's coder, for /diagnostics (its last quality and resolution) and
  // for a camera that changes mid-stream (the half-resolution frames' camera).
  std::shared_ptr<client::AdaptiveJpegCoder> jpeg_;
  v1::DeliveryMode server_delivery_ = v1::DELIVERY_UNSPECIFIED;  // GetInfo's default
  std::chrono::steady_clock::time_point last_open_attempt_{};
  std::uint64_t next_sequence_ = 0;  // across streams, so that headers are never confused

  std::mutex sent_mu_;
  std::map<std::uint64_t, SentFrame> sent_;  // frames sent and not answered
};

// The stream's options as the link opens it for frames of `camera` (the first frame's):
// resilience, the rate controller (~rate_control) and its coder. With ~encoding h264, a new
// video::FrameEncoder (under ~rate_control the controller sets the encoder's bitrate frame by
// frame, at most ~h264/mbps). With ~encoding jpeg, a new client::AdaptiveJpegCoder of ~jpeg/*
// with `camera` as its stream_camera (what a half-resolution frame's camera is halved from):
// under ~rate_control its quality, then the half-resolution floor, follow the controller's
// target; without, every frame goes at ~jpeg/quality. on_result and on_reconnect are the link's
// to set. INVALID_ARGUMENT for an encoding this build lacks.
absl::StatusOr<client::StreamOptions> StreamOptionsFor(const BridgeOptions& options,
                                                       const CameraModel& camera);

// The stream config a frame with `camera` is sent under: `base` (the parameters) plus the camera.
client::StreamConfig ConfigFor(const client::StreamConfig& base, const CameraModel& camera);
// `camera` as the protocol's message, every field set (Frame.camera, StreamConfig.camera).
v1::CameraModel CameraProto(const CameraModel& camera);
bool SameCamera(const CameraModel& a, const CameraModel& b);

}  // namespace cloudcast::ros_bridge
