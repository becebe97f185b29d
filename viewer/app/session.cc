#include "app/session.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "cloudcast/client/adaptive_jpeg_coder.h"

namespace cloudcast::client::app {
namespace {

using Clock = std::chrono::steady_clock;

// Frame errors are logged individually up to this many, then every 100th, so a misconfigured
// stream does not flood the terminal.
constexpr std::uint64_t kErrorsLoggedInFull = 5;

}  // namespace

absl::StatusOr<std::unique_ptr<Session>> Session::Start(const SessionOptions& options,
                                                        sources::FrameSource* source,
                                                        StreamStats* stats,
                                                        ResultCallback on_result) {
  std::unique_ptr<Session> s(new Session());
  s->options_ = options;
  s->source_ = source;
  s->stats_ = stats;
  s->on_result_ = std::move(on_result);
  if (options.video) s->video_ = std::make_shared<video::FrameEncoder>(*options.video);
  if (options.rate_control && !options.video && options.uplink.encoding == sources::Uplink::kJpeg) {
    // The library's adaptive JPEG coder: quality, then half resolution, follow the target.
    AdaptiveJpegOptions jpeg;
    jpeg.fps = options.fps > 0 ? options.fps : 30.0;  // unpaced: at most 30 replies a second
    jpeg.start_quality = options.uplink.jpeg_quality;
    jpeg.stream_camera = options.config.camera();
    s->jpeg_ = std::make_shared<AdaptiveJpegCoder>(jpeg);
  }

  ClientOptions client_options;
  client_options.security = options.security;
  client_options.connect_timeout = options.connect_timeout;
  client_options.decode_clouds = options.decode_clouds;
  auto client = Client::Connect(options.server, client_options);
  if (!client.ok()) {
    return absl::Status(client.status().code(),
                        absl::StrCat("--server ", options.server, ": ", client.status().message()));
  }
  s->client_ = *std::move(client);
  auto info = s->client_->GetInfo();
  if (!info.ok()) {
    return absl::Status(info.status().code(),
                        absl::StrCat("--server ", options.server, ": ", info.status().message()));
  }
  s->server_info_ = *std::move(info);
  spdlog::info("server {}: cloudcast {}, {} workers, Draco {}", options.server,
               s->server_info_.version(), s->server_info_.worker_threads(),
               s->server_info_.draco_version());

  StreamOptions stream_options;
  stream_options.rate_control = options.rate_control;
  // The stream encodes each raw frame when it can send it (never replacing an encoded picture),
  // asks the encoder for the IDRs the server's replies ask for and, with --rate-control, sets
  // its bitrate to the controller's target frame by frame (less the other images' bytes, at most
  // --h264-mbps).
  // --rate-control --encoding jpeg: the adaptive JPEG coder makes each frame from raw images as
  // it is sent, the same way.
  stream_options.coder = s->video_;
  if (s->jpeg_ != nullptr) stream_options.coder = s->jpeg_;
  auto stream = s->client_->OpenStream(options.config, std::move(stream_options));
  if (!stream.ok()) {
    return absl::Status(stream.status().code(),
                        absl::StrCat("--server ", options.server, ": ", stream.status().message()));
  }
  s->stream_ = *std::move(stream);
  s->receiver_ = std::thread([p = s.get()] { p->ReceiveLoop(); });
  s->sender_ = std::thread([p = s.get()] { p->SendLoop(); });
  return s;
}

Session::~Session() {
  Stop();
  Wait().IgnoreError();
}

void Session::Stop() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stop_ || done_) return;
    stop_ = true;
  }
  cv_.notify_all();
  // Unblocks a Send held by flow control and the receiver's Read.
  if (stream_ != nullptr) stream_->Cancel();
}

absl::Status Session::Wait() {
  if (sender_.joinable()) sender_.join();
  std::lock_guard<std::mutex> lock(mu_);
  return error_;
}

bool Session::WaitFor(std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(mu_);
  return cv_.wait_for(lock, timeout, [this] { return done_.load(); });
}

void Session::SetError(const absl::Status& status) {
  std::lock_guard<std::mutex> lock(mu_);
  if (error_.ok() && !stop_) error_ = status;
}

void Session::ReceiveLoop() {
  Result result;
  std::uint64_t errors = 0;
  while (stream_->Read(&result)) {
    if (result.fate == client::FrameFate::kReplaced ||
        result.fate == client::FrameFate::kDropped) {
      // Delivery latest: a newer frame took its place (in the client before it was sent, or on
      // the server). Not an error; it frees its place in the window.
      {
        std::lock_guard<std::mutex> lock(mu_);
        ++settled_;
        replaced_ += result.fate == client::FrameFate::kReplaced ? 1 : 0;
        dropped_ = std::max<std::uint64_t>(dropped_, result.frames_dropped);
      }
      cv_.notify_all();
      continue;
    }
    if (result.config_rejected) {
      SetError(absl::InvalidArgumentError(
          absl::StrCat("the server rejected the stream settings: ", result.status.message())));
      Stop();
      continue;
    }
    if (!result.ok()) {
      ++errors;
      if (errors <= kErrorsLoggedInFull || errors % 100 == 0) {
        spdlog::warn(
            "frame {} ({}): {}{}", result.sequence, result.frame_id,
            std::string(result.status.message()),
            errors == kErrorsLoggedInFull ? " (further errors: every 100th is shown)" : "");
      }
    }
    stats_->RecordResult(result);
    if (result.rate) {
      stats_->RecordRate(*result.rate, jpeg_ != nullptr ? jpeg_->last_quality() : 0);
    }
    if (on_result_) on_result_(result);
    {
      std::lock_guard<std::mutex> lock(mu_);
      ++answered_;
      ++settled_;
      dropped_ = std::max<std::uint64_t>(dropped_, result.frames_dropped);
    }
    cv_.notify_all();
  }
  {
    std::lock_guard<std::mutex> lock(mu_);
    receiver_done_ = true;
  }
  cv_.notify_all();
}

void Session::SendLoop() {
  const bool paced = options_.fps > 0;
  const auto period = paced ? std::chrono::duration_cast<Clock::duration>(
                                  std::chrono::duration<double>(1.0 / options_.fps))
                            : Clock::duration::zero();
  const std::uint64_t window = static_cast<std::uint64_t>(std::max(1, options_.max_in_flight));
  Clock::time_point due = Clock::now();
  sources::SourceFrame frame;
  sources::UplinkFrame uplink;
  bool tiff_noted = false;
  sources::UplinkOptions uplink_options = options_.uplink;
  // The adaptive JPEG coder takes raw images.
  if (jpeg_ != nullptr) uplink_options.encoding = sources::Uplink::kRaw;
  std::uint64_t bytes_recorded = 0;

  for (;;) {
    // The next frame is read (decoded) before waiting, so its decoding overlaps the wait.
    absl::StatusOr<bool> got = source_->Next(&frame);
    if (!got.ok()) {
      SetError(got.status());
      break;
    }
    if (!*got) break;

    {
      std::unique_lock<std::mutex> lock(mu_);
      if (paced) {
        // A camera does not catch up on frames it missed: when far behind, restart the clock.
        const Clock::time_point now = Clock::now();
        if (now > due + period) due = now;
        cv_.wait_until(lock, due, [this] { return stop_ || receiver_done_; });
        due += period;
      } else {
        cv_.wait(lock, [&] {
          return stop_ || receiver_done_ || sent_ - std::min(sent_, settled_) < window;
        });
      }
      if (stop_ || receiver_done_) break;
    }

    FrameMeta meta;
    meta.capture_time_unix_ns = UnixNanosNow();  // encoding below counts as latency
    meta.frame_id = frame.name;
    if (absl::Status s = uplink.Encode(frame, uplink_options); !s.ok()) {
      SetError(absl::Status(s.code(), absl::StrCat("frame ", frame.name, ": ", s.message())));
      break;
    }
    if (uplink.float_disparity_as_tiff() && !tiff_noted) {
      tiff_noted = true;
      spdlog::info("float disparities and depths are sent as TIFF (PNG has no float samples)");
    }
    // With --encoding h264 the colour images go raw: the stream's coder (video_) encodes them
    // when the stream can send the frame; the disparity or depth map goes lossless, zstd (raw,
    // a 640x480 map alone is 300 KB a frame, 74 Mbit/s at 30 fps).
    const client::FrameInput input =
        video_ != nullptr ? client::CompressGeometry(uplink.input()) : uplink.input();
    const absl::Status status = stream_->Send(input, meta);
    if (!status.ok()) {
      // A failed write means the call ended; Finish below says why. Bad inputs are ours.
      if (status.code() != absl::StatusCode::kUnavailable) {
        SetError(absl::Status(status.code(),
                              absl::StrCat("frame ", frame.name, ": ", status.message())));
      }
      break;
    }
    // The bytes that went out since the last frame (a kept video frame's are counted when it is
    // encoded, on a gRPC thread).
    const std::uint64_t bytes_now = stream_->image_bytes_sent();
    const std::uint64_t frame_bytes = bytes_now - bytes_recorded;
    bytes_recorded = bytes_now;
    stats_->RecordSent(frame_bytes);
    {
      std::lock_guard<std::mutex> lock(mu_);
      ++sent_;
    }
  }

  stream_->CloseSend().IgnoreError();
  if (receiver_.joinable()) receiver_.join();
  absl::Status final_status = stream_->Finish();
  bool stopped = false;
  {
    std::lock_guard<std::mutex> lock(mu_);
    stopped = stop_;
  }
  if (!final_status.ok() && !(stopped && final_status.code() == absl::StatusCode::kCancelled)) {
    SetError(final_status);
  }
  {
    std::lock_guard<std::mutex> lock(mu_);
    done_ = true;
  }
  cv_.notify_all();
}

}  // namespace cloudcast::client::app
