#include "cloud_link.h"

#include <condition_variable>
#include <thread>
#include <utility>

#include "absl/strings/str_cat.h"
#ifdef CLOUDCAST_BRIDGE_VIDEO
#include "cloudcast/video/frame_encoder.h"
#endif
#ifdef CLOUDCAST_BRIDGE_JPEG
#include "cloudcast/client/adaptive_jpeg_coder.h"
#endif

namespace cloudcast::ros_bridge {

client::StreamConfig ConfigFor(const client::StreamConfig& base, const CameraModel& camera) {
  client::StreamConfig config = base;
  client::SetCamera(camera, &config);
  return config;
}

v1::CameraModel CameraProto(const CameraModel& camera) {
  v1::StreamConfig config;
  client::SetCamera(camera, &config);
  return std::move(*config.mutable_camera());
}

bool SameCamera(const CameraModel& a, const CameraModel& b) {
  return a.fx == b.fx && a.fy == b.fy && a.cx == b.cx && a.cy == b.cy && a.baseline == b.baseline &&
         a.disparity_scale == b.disparity_scale && a.disparity_offset == b.disparity_offset &&
         a.invalid_disparities == b.invalid_disparities && a.depth_scale == b.depth_scale;
}

absl::StatusOr<client::StreamOptions> StreamOptionsFor(const BridgeOptions& options,
                                                       const CameraModel& camera) {
  client::StreamOptions so;
  so.resilient = options.resilient;
  so.reconnect_timeout = options.reconnect_timeout;
  if (options.rate_control) so.rate_control = options.rate;
  if (options.uplink == Uplink::kH264) {
#ifdef CLOUDCAST_BRIDGE_VIDEO
    // A new encoder per stream: a new stream (after the old one ended) starts at an IDR. The
    // stream encodes each raw frame when it can send it, so with delivery latest no encoded
    // picture is ever replaced; it passes the server's keyframe requests and (rate_control) the
    // controller's target on to the encoder.
    so.coder = std::make_shared<video::FrameEncoder>(
        video::ToFrameEncoderOptions(options.h264, options.h264_fps));
#else
    return absl::InvalidArgumentError("encoding h264: this bridge was built without video");
#endif
  }
  if (options.uplink == Uplink::kJpeg) {
#ifdef CLOUDCAST_BRIDGE_JPEG
    // A new coder per stream (as cloudcast-client --rate-control --encoding jpeg makes it): with
    // delivery latest a raw frame is encoded only once the stream can send it, at the quality the
    // controller's target carries then. Without rate_control it never gets a target and keeps
    // its start quality at full resolution.
    client::AdaptiveJpegOptions jpeg;
    jpeg.fps = options.jpeg.fps;
    jpeg.start_quality = options.jpeg.quality;
    jpeg.min_quality = options.jpeg.min_quality;
    jpeg.max_quality = options.jpeg.max_quality;
    jpeg.half_resolution_floor = options.jpeg.half_resolution;
    jpeg.stream_camera = CameraProto(camera);
    so.coder = std::make_shared<client::AdaptiveJpegCoder>(std::move(jpeg));
#else
    (void)camera;
    return absl::InvalidArgumentError("encoding jpeg: this bridge was built without OpenCV");
#endif
  }
  return so;
}

namespace {

// The frame as ~encoding sends it. zstd: every raw image compressed (losslessly). h264: the
// disparity or depth map compressed losslessly, the colour images left raw for the stream's
// video coder. jpeg: every image raw, for the stream's AdaptiveJpegCoder (it compresses the
// disparity or depth itself, and halves the raw images at its floor).
client::FrameInput ForUplink(const client::FrameInput& images, Uplink uplink) {
  switch (uplink) {
    case Uplink::kRaw:
      return images;
    case Uplink::kZstd:
      return client::CompressRaw(images);
    case Uplink::kH264:
      return client::CompressGeometry(images);
    case Uplink::kJpeg:
      return images;
  }
  return images;
}

}  // namespace

CloudLink::CloudLink(const BridgeOptions& options, BridgeStats* stats, CloudSink on_cloud,
                     LogSink log)
    : options_(options), stats_(stats), on_cloud_(std::move(on_cloud)), log_(std::move(log)) {}

void CloudLink::LogThrottled(Throttled kind, LogLevel level, const std::string& message) {
  const auto now = std::chrono::steady_clock::now();
  {
    std::lock_guard<std::mutex> lock(log_mu_);
    auto& last = last_logged_[kind];
    if (last != std::chrono::steady_clock::time_point{} && now - last < std::chrono::seconds(5)) {
      return;
    }
    last = now;
  }
  log_(level, message);
}

CloudLink::~CloudLink() { CloseStream(absl::OkStatus()); }

absl::StatusOr<v1::ServerInfo> CloudLink::Probe() {
  // A client that waits for the server at start, then one that never blocks the ROS thread: a
  // frame's stream fails at once while the server is unreachable, and the next frame retries.
  client::ClientOptions waiting = options_.client;
  auto probe = client::Client::Connect(options_.server, waiting);
  client::ClientOptions lazy = options_.client;
  lazy.connect_timeout = std::chrono::milliseconds(0);
  lazy.wait_for_ready = false;
  auto connected = client::Client::Connect(options_.server, lazy);
  if (!connected.ok()) return connected.status();  // a malformed target or TLS setting
  client_ = *std::move(connected);
  if (!probe.ok()) return probe.status();
  absl::StatusOr<v1::ServerInfo> info = (*probe)->GetInfo();
  if (info.ok()) server_delivery_ = info->defaults().delivery();
  return info;
}

client::StreamConfig CloudLink::StreamConfigFor(const CameraModel& camera) const {
  client::StreamConfig config = ConfigFor(options_.config, camera);
  // The client library replaces a frame still waiting to be sent only when the stream says
  // DELIVERY_LATEST itself; when the bridge leaves delivery to the server and the server's is
  // latest, it is said explicitly, so that Send never holds up the ROS callback thread.
  if (config.delivery() == v1::DELIVERY_UNSPECIFIED &&
      server_delivery_ == v1::DELIVERY_LATEST) {
    config.set_delivery(v1::DELIVERY_LATEST);
  }
  return config;
}

absl::Status CloudLink::EnsureStream(const CameraModel& camera) {
  if (client_ == nullptr) return absl::FailedPreconditionError("no client (Probe not called)");
  if (stream_ != nullptr) {
    // Each frame carries its own camera (Frame.camera, see Send): a camera that changes needs
    // no Reconfigure, only a log line.
    if (camera_ && !SameCamera(*camera_, camera)) {
      camera_ = camera;
      log_(LogLevel::kInfo, absl::StrCat("camera changed (", camera.ToString(),
                                         "); each frame carries its own"));
    }
    return absl::OkStatus();
  }
  const auto now = std::chrono::steady_clock::now();
  if (now - last_open_attempt_ < std::chrono::seconds(1)) {
    return absl::UnavailableError("no stream to the server (retrying once a second)");
  }
  last_open_attempt_ = now;
  absl::StatusOr<client::StreamOptions> made = StreamOptionsFor(options_, camera);
  if (!made.ok()) return made.status();
  client::StreamOptions so = *std::move(made);
#ifdef CLOUDCAST_BRIDGE_JPEG
  jpeg_ = std::dynamic_pointer_cast<client::AdaptiveJpegCoder>(so.coder);
#endif
  so.on_result = [this](client::Result&& r) { OnResult(std::move(r)); };
  so.on_reconnect = [this](const client::Reconnect& r) {
    stats_->Reconnected();
    log_(LogLevel::kWarn,
         absl::StrCat("stream reconnected (attempt ", r.attempt, " after ", r.cause.message(), ", ",
                      r.took.count(), " ms; ", r.frames_resent, " frames resent, ",
                      r.frames_dropped, " dropped)"));
  };
  auto opened = client_->OpenStream(StreamConfigFor(camera), std::move(so));
  if (!opened.ok()) return opened.status();
  stream_ = *std::move(opened);
  camera_ = camera;
  log_(LogLevel::kInfo, absl::StrCat("stream open to ", options_.server, " (", camera.ToString(),
                                     "; encoding ", std::string(Name(options_.uplink)), ")"));
  return absl::OkStatus();
}

void CloudLink::CloseStream(const absl::Status& why) {
  if (stream_ == nullptr) return;
  if (!why.ok()) {
    log_(LogLevel::kError, absl::StrCat("stream to ", options_.server, " lost: ", why.message()));
  }
  (void)stream_->CloseSend();
  // Finish waits for the replies still due; a server that is gone could hold it for the whole
  // reconnect timeout, so it gets two seconds before the call is cancelled.
  std::mutex mu;
  std::condition_variable cv;
  bool done = false;
  std::thread watchdog([&] {
    std::unique_lock<std::mutex> lock(mu);
    if (!cv.wait_for(lock, std::chrono::seconds(2), [&] { return done; })) stream_->Cancel();
  });
  const absl::Status finished = stream_->Finish();
  {
    std::lock_guard<std::mutex> lock(mu);
    done = true;
  }
  cv.notify_one();
  watchdog.join();
  if (!finished.ok() && why.ok()) {
    log_(LogLevel::kWarn, absl::StrCat("stream ended with ", finished.ToString()));
  }
  stats_->StreamClosed();
  stream_.reset();
  jpeg_.reset();
  camera_.reset();
}

void CloudLink::Send(const OutgoingFrame& frame) {
  const bool camera_changed = stream_ != nullptr && camera_ && !SameCamera(*camera_, frame.camera);
  if (absl::Status s = EnsureStream(frame.camera); !s.ok()) {
    stats_->NotSent(s);
    LogThrottled(kNotSent, LogLevel::kWarn, absl::StrCat("frame not sent: ", s.message()));
    return;
  }
  client::FrameMeta meta;
  meta.sequence = next_sequence_++;
  meta.frame_id = frame.header.frame_id;
  // The camera of this frame's CameraInfo (Frame.camera): a few dozen bytes, and the server
  // applies it to this frame alone, so a frame resent after a reconnect, or one queued while the
  // camera changed, is never reprojected with another frame's camera.
  meta.camera = CameraProto(frame.camera);
#ifdef CLOUDCAST_BRIDGE_JPEG
  // A half-resolution frame carries the coder's camera, halved: from this frame on, this one's.
  if (camera_changed && jpeg_ != nullptr) jpeg_->SetCamera(*meta.sequence, *meta.camera);
#else
  (void)camera_changed;
#endif
  {
    std::lock_guard<std::mutex> lock(sent_mu_);
    sent_[*meta.sequence] = {frame.header, frame.camera};  // before Send: the reply may come first
  }
  const absl::Status s = stream_->Send(ForUplink(frame.images, options_.uplink), meta);
  if (s.ok()) {
    stats_->Sent();
    return;
  }
  {
    std::lock_guard<std::mutex> lock(sent_mu_);
    sent_.erase(*meta.sequence);
  }
  stats_->NotSent(s);
  if (s.code() == absl::StatusCode::kInvalidArgument) {
    LogThrottled(kRefused, LogLevel::kError,
                 absl::StrCat("frame refused by the client library: ", s.message()));
    return;
  }
  // The call has ended (a non-resilient stream lost its connection, or a resilient one gave up).
  CloseStream(s);
}

void CloudLink::OnResult(client::Result&& result) {
  if (result.config_rejected) {
    stats_->Reply(result);
    log_(LogLevel::kError,
         absl::StrCat("the server refused the stream config: ", result.status.message()));
    return;
  }
  if (result.fate == client::FrameFate::kReplaced || result.fate == client::FrameFate::kDropped) {
    // Delivery latest: a newer frame took its place, in the client or on the server. Counted
    // with the stream's drops, not as an error.
    {
      std::lock_guard<std::mutex> lock(sent_mu_);
      sent_.erase(result.sequence);
    }
    stats_->StreamDropped(result.frames_dropped + result.frames_replaced);
    return;
  }
  SentFrame sent;
  bool known = false;
  {
    // Replies come in send order; frames passed over have had their own Result.
    std::lock_guard<std::mutex> lock(sent_mu_);
    auto it = sent_.find(result.sequence);
    if (it != sent_.end()) {
      sent = std::move(it->second);
      known = true;
      sent_.erase(sent_.begin(), std::next(it));
    }
  }
  stats_->StreamDropped(result.frames_dropped + result.frames_replaced);
  stats_->Reply(result);
#ifdef CLOUDCAST_BRIDGE_JPEG
  if (jpeg_ != nullptr) stats_->JpegCoded(jpeg_->last_quality(), jpeg_->last_half());
#endif
  if (!result.ok()) {
    LogThrottled(kFrameFailed, LogLevel::kWarn,
                 absl::StrCat("frame ", result.sequence, ": ", result.status.message()));
    return;
  }
  if (!known) {
    LogThrottled(kUnknownReply, LogLevel::kWarn,
                 absl::StrCat("a reply for frame ", result.sequence,
                              ", which this bridge did not send"));
    return;
  }
  on_cloud_(std::move(result), sent);
}

}  // namespace cloudcast::ros_bridge
