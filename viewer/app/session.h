// One streaming run of cloudcast-client: frames from a FrameSource go to the server over one
// Stream, paced (a fixed rate, or as fast as the server answers with a bounded number of frames in
// flight); replies go to a callback on the receiving thread. No GL here: the viewer, the recorder
// and the statistics all hang off the callback.
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
#include <thread>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "app/stats.h"
#include "cloudcast/client/adaptive_jpeg_coder.h"
#include "cloudcast/client/client.h"
#include "cloudcast/sources/frame_source.h"
#include "cloudcast/sources/uplink.h"
#include "cloudcast/video/frame_encoder.h"

namespace cloudcast::client::app {

struct SessionOptions {
  std::string server = kDefaultTarget;
  // TLS and the bearer token (cloudcast/client/security.h).
  ChannelSecurity security;
  std::chrono::milliseconds connect_timeout = ClientOptions{}.connect_timeout;
  // Sent as the stream's first message.
  StreamConfig config;
  // Frames per second; 0: send whenever fewer than max_in_flight frames await their reply.
  double fps = 0;
  int max_in_flight = 2;
  // How frames travel (raw, zstd, png, jpeg).
  sources::UplinkOptions uplink;
  // Set: the colour image (a stereo pair's views) goes as H.264 pictures, coded from the raw
  // images `uplink` gives (--encoding h264), IDRs sent when the server's replies ask.
  std::optional<video::FrameEncoderOptions> video;
  // Decode the Draco replies (off for pure load measurements).
  bool decode_clouds = true;
  // The adaptive sender (--rate-control): the stream's rate controller holds frames past its
  // window (the stream must be DELIVERY_LATEST), and with JPEG colour (no video) the library's
  // AdaptiveJpegCoder makes each frame as it goes: the quality follows its target bitrate frame
  // by frame, and below quality 10 at full resolution the frames go at half resolution (their
  // camera halved) until the target allows full again. Unset: no rate control.
  std::optional<RateControlOptions> rate_control;
};

class Session {
 public:
  // Called on the receiving thread for every reply, in order. It may take (swap out) the
  // result's cloud and bytes; the Result is reused afterwards.
  using ResultCallback = std::function<void(Result&)>;

  // Connects (UNAVAILABLE naming --server when it cannot), asks the server for its info, opens
  // the stream and starts sending. `source` and `stats` must outlive the session.
  static absl::StatusOr<std::unique_ptr<Session>> Start(const SessionOptions& options,
                                                        sources::FrameSource* source,
                                                        StreamStats* stats,
                                                        ResultCallback on_result);
  ~Session();  // Stop() and Wait()

  // Asks the session to end early (any thread): no more frames are sent and the call is
  // cancelled. Wait() then returns OK.
  void Stop();
  // True once every frame was sent and answered (or the stream failed, or Stop ran).
  bool done() const { return done_.load(); }
  // Blocks until done; returns why the session ended: OK (source exhausted and every reply in,
  // or Stop), or the error (stream failure, unreadable frame, rejected config).
  absl::Status Wait();
  // Waits up to `timeout` for done.
  bool WaitFor(std::chrono::milliseconds timeout);

  const v1::ServerInfo& server_info() const { return server_info_; }

 private:
  Session() = default;
  void SendLoop();
  void ReceiveLoop();
  // Stores the first error only; later ones are consequences.
  void SetError(const absl::Status& status);

  SessionOptions options_;
  sources::FrameSource* source_ = nullptr;
  StreamStats* stats_ = nullptr;
  ResultCallback on_result_;
  std::unique_ptr<Client> client_;
  std::unique_ptr<Stream> stream_;
  v1::ServerInfo server_info_;
  std::shared_ptr<video::FrameEncoder> video_;  // options.video: the stream's coder
  // --rate-control with JPEG (and no video): the stream's coder.
  std::shared_ptr<AdaptiveJpegCoder> jpeg_;

  std::mutex mu_;
  std::condition_variable cv_;  // in-flight count changed, stop, receiver ended, done
  std::uint64_t sent_ = 0;
  std::uint64_t answered_ = 0;  // replies to frames (clouds and frame errors)
  std::uint64_t dropped_ = 0;   // the server's running count
  // Frames whose fate is known (each comes back once from the stream: answered, replaced,
  // dropped or lost), and those of them replaced before they were sent.
  std::uint64_t settled_ = 0;
  std::uint64_t replaced_ = 0;
  bool receiver_done_ = false;
  bool stop_ = false;
  absl::Status error_;
  std::atomic<bool> done_{false};

  std::thread sender_, receiver_;
};

}  // namespace cloudcast::client::app
