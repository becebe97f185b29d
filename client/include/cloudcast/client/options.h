// Options of the cloudcast client library, with their defaults.
#pragma once

#include <grpcpp/security/credentials.h>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "absl/status/status.h"
#include "cloudcast/client/rate_controller.h"
#include "cloudcast/client/security.h"

namespace cloudcast::client {

class FrameCoder;  // frame_coder.h

struct Result;

// The server a client program dials when given none: cloudcast-server's default port, here.
inline constexpr char kDefaultTarget[] = "localhost:50051";

// How a Client reaches the server. One Client (one gRPC channel) serves any number of calls and
// streams at once.
struct ClientOptions {
  // How long Connect waits for the channel to become ready. Zero: do not wait; Connect always
  // succeeds and an unreachable server shows up as UNAVAILABLE on the first call.
  std::chrono::milliseconds connect_timeout{5000};

  // Deadline of each unary call (GetInfo, Process). Zero: none. Streams never have one: they
  // live as long as the robot drives.
  std::chrono::milliseconds call_timeout{10000};

  // false (gRPC's default): calls fail at once with UNAVAILABLE while the server is unreachable.
  // true: calls wait for the connection until their deadline (call_timeout for unary calls,
  // connect_timeout for OpenStream), which suits a robot that may start before its server. An
  // open stream never waits: a lost connection ends it, and the robot opens a new one.
  bool wait_for_ready = false;

  // Largest message the channel sends and receives. A frame is about width x height x 7 bytes
  // raw (F32 disparity + BGR colour: 16 MiB at 1920x1080 ... 112 MiB at the server's 2^24-pixel
  // limit), and an unfiltered Draco cloud can be several MiB, both far over gRPC's 4 MiB default.
  // The server applies its own limit (GetInfo().limits().max_message_bytes).
  std::size_t max_message_bytes = std::size_t{256} << 20;

  // Upper bound of gRPC's reconnect backoff. gRPC's own default (120 s) leaves a robot blind for
  // minutes after a Wi-Fi drop; a few seconds keeps reconnecting cheap and prompt.
  std::chrono::milliseconds max_reconnect_backoff{5000};

  // TLS (nullopt: plaintext) and the bearer token sent with every call; see security.h.
  ChannelSecurity security;

  // Ready-made channel credentials, for what `security` does not cover; they must not be
  // combined with security.tls. nullptr: security.tls decides.
  std::shared_ptr<grpc::ChannelCredentials> credentials;

  // false: Results carry the reply (Draco bytes, counts, times) but no decoded cloud, e.g. for a
  // load tester measuring the server rather than the Draco decoder.
  bool decode_clouds = true;

  // How calls are spread over the addresses a target resolves to. "" or "pick_first" (gRPC's
  // default): one address at a time. "round_robin": every address, call by call, and only those
  // whose health service says SERVING (so a draining replica gets no new streams). Use it with a
  // target that names several replicas: "dns:///cloudcast-headless.robots.svc.cluster.local:50051"
  // (a Kubernetes headless Service) or "ipv4:10.0.0.1:50051,10.0.0.2:50051".
  std::string load_balancing;
};

// What happened when a resilient stream lost its call and opened a new one.
struct Reconnect {
  int attempt = 0;                    // 1 for the stream's first reconnect, then 2, ...
  absl::Status cause;                 // how the old call ended (UNAVAILABLE)
  std::string old_instance;           // the replica that answered last before ("" if none did)
  std::chrono::milliseconds took{0};  // from the failure to the new call carrying the resends
  std::uint64_t frames_resent = 0;    // DELIVERY_ALL: sent again on the new call
  std::uint64_t frames_dropped = 0;   // DELIVERY_LATEST: unanswered frames given up on
};

// How one Stream delivers its replies.
struct StreamOptions {
  // Empty (the default): the caller reads replies with Stream::Read. Otherwise this is called
  // once per frame (its reply, or its other fate), in order, one call at a time, on gRPC's
  // callback threads, and Stream::Read must not be used. A slow callback delays the next reply
  // (the stream reads no more meanwhile), never a Send; keep it short, and never destroy or
  // Finish its own Stream from it (Finish waits for the last callback).
  std::function<void(Result&&)> on_result;

  // Resilience. false (the default): a lost connection ends the stream (Finish says why). true:
  // when the call ends with UNAVAILABLE (the replica was killed, drained on shutdown, or sent
  // GOAWAY), or with CANCELLED that the stream did not ask for (a server stopping while the call
  // was opening), the stream opens a new call (on another replica when the channel has one, see
  // ClientOptions::load_balancing) and sends its StreamConfig again. With DELIVERY_ALL it also
  // sends again every frame that was sent but not answered, in order, so each frame is answered
  // exactly once; with DELIVERY_LATEST those frames count as dropped (each comes back as a
  // Result with fate kDropped). While a new call is being opened, Send waits with DELIVERY_ALL
  // (back-pressure) and replaces the waiting frame with DELIVERY_LATEST. After
  // `reconnect_timeout` without a working call the stream gives up: every frame still
  // unanswered comes back as a Result with UNAVAILABLE, and Finish returns UNAVAILABLE saying
  // so. The frames kept for resending are those in flight, which gRPC flow control bounds (a few
  // per stream).
  bool resilient = false;
  std::chrono::milliseconds reconnect_timeout{30000};
  // DELIVERY_ALL (or delivery unset): how many frames may wait for the call's write slot before
  // Send waits (back-pressure). A few let a camera loop ride out a short stall or a reconnect
  // without waiting; each one waiting adds a frame time of latency. At least 1.
  // (DELIVERY_LATEST: one frame waits, the newest; Send never waits.)
  std::size_t max_queued_frames = 4;

  // Called after each reconnect (on a gRPC callback thread, in order with the results).
  std::function<void(const Reconnect&)> on_reconnect;

  // A sender that follows the link (rate_controller.h; docs/client.md, "Sending over a real
  // link"). Unset (the default): every frame is written as soon as the call's write slot is free,
  // and on a link slower than the frames TCP's buffers fill and latency grows for as long as the
  // stream lasts. Set: a rate controller estimates the link from the replies (their round trip
  // and the server's byte count) and holds frames past its window in the sender, where
  // DELIVERY_LATEST replaces them with newer ones (so use it with DELIVERY_LATEST); its target
  // bitrate (Stream::rate(), Result::rate) is what the caller's encoder should follow, for
  // example with QualityFollower (rate_controller.h).
  std::optional<RateControlOptions> rate_control;

  // A coder that makes each frame as it is sent (frame_coder.h): video (video::FrameEncoder).
  // Send then takes raw frames. With DELIVERY_LATEST a raw frame is encoded only when the stream
  // has room for it, so no encoded picture is ever replaced: the newest raw frame waits
  // meanwhile (on a gRPC callback thread once room comes), and an older waiting one is replaced
  // (Result fate kReplaced). With DELIVERY_ALL each frame is encoded in Send. The coder sees the
  // results of the frames it encoded (keyframe requests), and with rate_control its target
  // bitrate before each frame.
  std::shared_ptr<FrameCoder> coder;
};

}  // namespace cloudcast::client
