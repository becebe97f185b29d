#include "cloudcast/client/client.h"

#include <grpcpp/grpcpp.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <climits>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "cloudcast/client/frame_coder.h"
#include "cloudcast/client/stream_core.h"
#include "cloudcast/core/draco_codec.h"
#include "cloudcast/proto/convert.h"
#include "cloudcast/v1/cloudcast.grpc.pb.h"
#include "frame_builder.h"

namespace cloudcast::client {
namespace {

using Clock = std::chrono::steady_clock;
using Stub = v1::CloudCast::Stub;

// gRPC and Abseil share the google.rpc code numbering, so the code carries over as it is; the
// message gets the call and the target in front, since a bare "Connection refused" names neither.
absl::Status FromGrpc(const grpc::Status& status, const std::string& what) {
  if (status.ok()) return absl::OkStatus();
  return absl::Status(static_cast<absl::StatusCode>(status.error_code()),
                      absl::StrCat(what, ": ", status.error_message()));
}

const char* StateName(grpc_connectivity_state state) {
  switch (state) {
    case GRPC_CHANNEL_IDLE:
      return "IDLE";
    case GRPC_CHANNEL_CONNECTING:
      return "CONNECTING";
    case GRPC_CHANNEL_READY:
      return "READY";
    case GRPC_CHANNEL_TRANSIENT_FAILURE:
      return "TRANSIENT_FAILURE";
    case GRPC_CHANNEL_SHUTDOWN:
      return "SHUTDOWN";
  }
  return "UNKNOWN";
}

int ClampToInt(std::size_t v) { return static_cast<int>(std::min<std::size_t>(v, INT_MAX)); }

std::int64_t MicrosSince(Clock::time_point start) {
  return std::chrono::duration_cast<std::chrono::microseconds>(Clock::now() - start).count();
}

// Decodes result->reply's Draco bytes into result->cloud (or empties it when decoding is off).
void DecodeInto(bool decode, Result* result) {
  if (!decode) {
    result->cloud.ResizeUnorganized(0);
    return;
  }
  const Clock::time_point start = Clock::now();
  if (absl::Status s = DecodeDraco(result->reply.draco(), &result->cloud); !s.ok()) {
    result->cloud.ResizeUnorganized(0);
    result->status = absl::DataLossError(absl::StrCat("reply for frame ", result->sequence,
                                                      " has an undecodable cloud: ", s.message()));
  }
  result->times.decode_us = MicrosSince(start);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Stream: the library's blocking and callback interfaces over the one stream core
// (stream_core.h). The core runs the call; this side turns frames into request bytes (on the
// sending thread), and the core's events into Results.

namespace {

grpc::ByteBuffer SerializedConfig(const v1::StreamConfig& config) {
  v1::StreamRequest request;
  *request.mutable_config() = config;
  const std::string bytes = request.SerializeAsString();
  grpc::Slice slice(bytes.data(), bytes.size());
  return grpc::ByteBuffer(&slice, 1);
}

std::int64_t UnixNanosAt(Clock::time_point t) {
  if (t == Clock::time_point{}) return 0;
  return UnixNanosNow() -
         std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - t).count();
}

// The access unit bytes of a frame's video pictures.
std::uint64_t VideoBytes(const FrameInput& frame) {
  std::uint64_t bytes = 0;
  const auto add = [&](const ColorInput& image) {
    if (const auto* v = std::get_if<PrecodedVideo>(&image); v != nullptr && v->message != nullptr) {
      bytes += v->message->access_unit().size();
    }
  };
  if (const auto* f = std::get_if<DisparityFrame>(&frame)) add(f->colour);
  if (const auto* f = std::get_if<DepthFrame>(&frame)) add(f->colour);
  if (const auto* f = std::get_if<StereoFrame>(&frame)) {
    add(f->left);
    add(f->right);
  }
  return bytes;
}

template <typename Repeated>
std::vector<v1::VideoBitstream> Bitstreams(const Repeated& ids) {
  std::vector<v1::VideoBitstream> out;
  for (int id : ids) out.push_back(static_cast<v1::VideoBitstream>(id));
  return out;
}

// Blocking mode: replies buffered for Read before reading pauses (gRPC flow control then holds
// the server back, as an unread stream always did).
constexpr std::size_t kMaxBufferedResults = 16;

}  // namespace

struct Stream::Impl : public StreamSink {
  std::string target;
  bool decode_clouds = true;
  StreamOptions options;
  // The channel outlives the core's end (the core holds none: stream_core.h); so does this.
  std::shared_ptr<grpc::Channel> channel;
  std::shared_ptr<StreamCore> core;

  // Sending side: frames become request bytes on the caller's thread, one sender at a time.
  std::mutex send_mu;
  internal::RequestWriter frames;
  std::uint64_t next_sequence = 0;
  std::atomic<std::uint64_t> image_bytes_sent{0};
  // StreamOptions::coder with DELIVERY_LATEST: the newest raw frame, kept while the core has no
  // room for it (encoded on OnRoom); CloseSend waits for it to go.
  struct Kept {
    internal::HeldFrame frame;
    FrameMeta meta;
    std::uint64_t sequence = 0;
  };
  std::optional<Kept> kept;
  bool latest = false;
  bool close_when_sent = false;
  bool send_closed = false;
  std::size_t other_bytes_per_frame = 0;  // the last coded frame's bytes beside its pictures

  // Receiving side (the core's events, one at a time).
  std::uint64_t dropped_seen = 0;
  std::uint64_t replaced_seen = 0;
  std::optional<RateEstimate> last_rate;  // OnRate -> the next OnReply (gRPC callbacks, in order)
  std::atomic<int> reconnects{0};

  std::mutex results_mu;
  std::condition_variable results_cv;
  std::deque<Result> results;  // blocking mode: ready for Read, undecoded
  bool reads_paused = false;
  bool discard = false;  // Finish: nobody reads any more
  bool ended = false;
  absl::Status final_status;

  std::mutex finish_mu;
  bool finished = false;

  std::string What() const { return absl::StrCat("stream to ", target); }

  absl::Status Ended() const {
    return absl::UnavailableError(
        absl::StrCat(What(), " has ended; Stream::Finish() returns the reason"));
  }

  absl::Status Send(const FrameInput& input, const FrameMeta& meta) {
    std::lock_guard<std::mutex> lock(send_mu);
    const std::uint64_t sequence = meta.sequence.value_or(next_sequence);
    if (options.coder == nullptr || !latest) {
      if (absl::Status s = Submit(input, meta, sequence, /*wait=*/true); !s.ok()) return s;
      next_sequence = sequence + 1;
      return absl::OkStatus();
    }
    // Made at dispatch: the raw frame is encoded only when the core has room, so that no
    // encoded picture is ever replaced (a lost reference); until then the newest waits raw.
    if (send_closed) {
      return absl::FailedPreconditionError(
          absl::StrCat(What(), ": Send after CloseSend or Finish"));
    }
    if (core->ended()) return Ended();
    FrameMeta stamped = meta;
    stamped.sequence = sequence;
    if (stamped.capture_time_unix_ns == 0) stamped.capture_time_unix_ns = UnixNanosNow();
    if (core->WantRoom()) {
      if (kept) ReplaceKept();
      if (absl::Status s = Submit(input, stamped, sequence, /*wait=*/false); !s.ok()) return s;
    } else {
      Kept k;
      if (absl::Status s = k.frame.Hold(input); !s.ok()) return s;
      k.meta = std::move(stamped);
      k.sequence = sequence;
      if (kept) ReplaceKept();
      kept = std::move(k);
    }
    next_sequence = sequence + 1;
    return absl::OkStatus();
  }

  // Under send_mu: the kept raw frame is replaced by a newer one, never encoded.
  void ReplaceKept() {
    core->Unmade(FrameFate::kReplaced, kept->sequence, RecordOf(kept->meta));
    kept.reset();
  }

  static FrameRecord RecordOf(const FrameMeta& meta) {
    FrameRecord record;
    record.frame_id = meta.frame_id;
    record.capture_time_unix_ns = meta.capture_time_unix_ns;
    return record;
  }

  // Under send_mu: encodes (with a coder) and hands the frame to the core. `wait`: DELIVERY_ALL
  // back-pressure.
  absl::Status Submit(const FrameInput& input, const FrameMeta& meta, std::uint64_t sequence,
                      bool wait) {
    absl::StatusOr<FrameInput> coded;
    const FrameInput* frame = &input;
    const FrameMeta* sent_meta = &meta;
    FrameMeta coded_meta;
    int resolution_divisor = 1;
    if (options.coder != nullptr) {
      if (options.rate_control) {
        if (const std::optional<RateEstimate> rate = core->rate()) {
          options.coder->SetStreamBitrate(static_cast<std::int64_t>(rate->target_bps),
                                          other_bytes_per_frame);
        }
      }
      coded = options.coder->Encode(input, sequence);
      if (!coded.ok()) return coded.status();
      frame = &*coded;
      // A frame made below the camera's resolution carries the camera that matches it.
      FrameCoder::Resolution resolution = options.coder->last_resolution();
      resolution_divisor = resolution.divisor;
      if (resolution.camera) {
        coded_meta = meta;
        coded_meta.camera = std::move(resolution.camera);
        sent_meta = &coded_meta;
      }
    }
    grpc::ByteBuffer bytes;
    if (absl::Status s = frames.Write(*frame, *sent_meta, sequence, &bytes); !s.ok()) return s;
    FrameRecord record;
    record.frame_id = meta.frame_id;
    record.capture_time_unix_ns = frames.frame().capture_time_unix_ns();
    record.image_bytes = frames.image_bytes();
    record.resolution_divisor = resolution_divisor;
    // DELIVERY_ALL waits here while a frame already waits for the write slot (back-pressure);
    // DELIVERY_LATEST never waits.
    const CoreMachine::Submitted submitted =
        wait ? core->SubmitWaiting(sequence, std::move(bytes), std::move(record))
             : core->Submit(sequence, std::move(bytes), std::move(record));
    switch (submitted) {
      case CoreMachine::Submitted::kClosed:
        return absl::FailedPreconditionError(
            absl::StrCat(What(), ": Send after CloseSend or Finish"));
      case CoreMachine::Submitted::kEnded:
      case CoreMachine::Submitted::kFull:
        return Ended();
      case CoreMachine::Submitted::kWriting:
      case CoreMachine::Submitted::kQueued:
        break;
    }
    image_bytes_sent.fetch_add(frames.image_bytes(), std::memory_order_relaxed);
    if (options.coder != nullptr) {
      const std::uint64_t video = VideoBytes(*frame);
      other_bytes_per_frame = frames.image_bytes() > video ? frames.image_bytes() - video : 0;
    }
    return absl::OkStatus();
  }

  // The core has room: the kept raw frame is encoded and sent now (on this gRPC thread).
  void OnRoom() override {
    std::lock_guard<std::mutex> lock(send_mu);
    if (!kept) return;
    Kept k = std::move(*kept);
    kept.reset();
    if (absl::Status s = Submit(k.frame.input(), k.meta, k.sequence, /*wait=*/false); !s.ok()) {
      // Send has returned long ago: the frame's own Result says why it went nowhere.
      core->Unmade(FrameFate::kUnsent, k.sequence, RecordOf(k.meta),
                   absl::Status(s.code(), absl::StrCat("could not be encoded: ", s.message())));
    }
    if (close_when_sent) core->CloseSend();
  }

  absl::Status Reconfigure(const StreamConfig& config) {
    std::lock_guard<std::mutex> lock(send_mu);
    absl::Status s = core->Reconfigure(SerializedConfig(config));
    if (s.code() == absl::StatusCode::kUnavailable) return Ended();
    return s;
  }

  // Hands `r` to the application: the callback, or the buffer Read takes from.
  void Deliver(Result&& r) {
    if (options.on_result) {
      if (r.status.ok()) DecodeInto(decode_clouds, &r);
      options.on_result(std::move(r));
      return;
    }
    bool pause = false;
    {
      std::lock_guard<std::mutex> lock(results_mu);
      if (discard) return;
      results.push_back(std::move(r));
      if (results.size() >= kMaxBufferedResults && !reads_paused) pause = reads_paused = true;
    }
    results_cv.notify_all();
    if (pause) core->PauseReads(true);
  }

  void OnReply(v1::StreamReply& reply, std::size_t /*reply_bytes*/, const SettledFrame* frame,
               Clock::time_point received) override {
    Result r;
    r.times.receive = received;
    r.times.receive_unix_ns = UnixNanosAt(received);
    switch (reply.kind_case()) {
      case v1::StreamReply::kCloud:
        // Swapped, not copied: the Draco bytes move into the result.
        r.reply.Swap(reply.mutable_cloud());
        r.keyframe_needed = Bitstreams(r.reply.keyframe_needed());
        r.sequence = r.reply.sequence();
        r.frame_id = r.reply.frame_id();
        r.capture_time_unix_ns = r.reply.capture_time_unix_ns();
        r.server_instance = r.reply.server_instance();
        break;
      case v1::StreamReply::kError: {
        const v1::FrameError& error = reply.error();
        r.status = convert::ToStatus(error);
        r.sequence = error.sequence();
        r.frame_id = error.frame_id();
        r.server_instance = error.server_instance();
        r.config_rejected = error.kind() == v1::ERROR_KIND_CONFIG;
        r.keyframe_needed = Bitstreams(error.keyframe_needed());
        break;
      }
      case v1::StreamReply::KIND_NOT_SET:
        r.status = absl::InternalError(
            absl::StrCat(What(), ": the server sent a reply with neither a cloud nor an error"));
        break;
    }
    if (frame != nullptr) {
      r.times.send = frame->frame.written;
      r.times.send_unix_ns = UnixNanosAt(frame->frame.written);
      // FrameError does not echo the capture time; the client knows what it sent.
      if (r.capture_time_unix_ns == 0) {
        r.capture_time_unix_ns = frame->frame.record.capture_time_unix_ns;
      }
      r.resolution_divisor = frame->frame.record.resolution_divisor;
    }
    r.frames_dropped = dropped_seen;
    r.frames_replaced = replaced_seen;
    r.rate = std::exchange(last_rate, std::nullopt);
    if (options.coder != nullptr && frame != nullptr) options.coder->OnResult(r);
    Deliver(std::move(r));
  }

  // Just before the OnReply it belongs to (the core's events come one at a time).
  void OnRate(const RateEstimate& estimate) override { last_rate = estimate; }

  void OnSettled(SettledFrame& s) override {
    Result r;
    r.fate = s.fate;
    r.sequence = s.sequence;
    r.frame_id = std::move(s.frame.record.frame_id);
    r.capture_time_unix_ns = s.frame.record.capture_time_unix_ns;
    r.resolution_divisor = s.frame.record.resolution_divisor;
    r.times.send = s.frame.written;
    r.times.send_unix_ns = UnixNanosAt(s.frame.written);
    switch (s.fate) {
      case FrameFate::kReplaced:
        ++replaced_seen;
        r.status = absl::AbortedError(
            absl::StrCat("frame ", s.sequence,
                         " was replaced by a newer frame before it was sent (DELIVERY_LATEST)"));
        break;
      case FrameFate::kDropped:
        ++dropped_seen;
        r.status = absl::AbortedError(absl::StrCat(
            "frame ", s.sequence,
            " was sent but skipped for a newer frame (DELIVERY_LATEST: by the server, or with a "
            "lost call)"));
        break;
      // A frame the call took down with it keeps the call's code: a refused call
      // (UNAUTHENTICATED, RESOURCE_EXHAUSTED, INVALID_ARGUMENT, ...) says so on its frames as
      // Finish does, and a caller that stops at the first failed Result learns why.
      case FrameFate::kLost:
      case FrameFate::kAnswered:
        r.status = absl::Status(
            s.why.ok() ? absl::StatusCode::kUnavailable : s.why.code(),
            absl::StrCat("frame ", s.sequence, " was sent but never answered: ",
                         s.why.ok() ? "the stream ended first" : s.why.message()));
        break;
      case FrameFate::kUnsent:
        r.status = absl::Status(
            s.why.ok() ? absl::StatusCode::kUnavailable : s.why.code(),
            absl::StrCat("frame ", s.sequence, " was never answered (never sent): ",
                         s.why.ok() ? "the stream ended first" : s.why.message()));
        break;
    }
    r.frames_dropped = dropped_seen;
    r.frames_replaced = replaced_seen;
    r.cloud.ResizeUnorganized(0);
    // A replaced frame (the core only replaces raw frames when there is a coder) was never
    // encoded; the coder hears of every frame it did encode.
    if (options.coder != nullptr && s.fate != FrameFate::kReplaced) {
      options.coder->OnResult(r);
    }
    Deliver(std::move(r));
  }

  void OnReconnected(const Reconnected& e) override {
    reconnects.fetch_add(1);
    if (!options.on_reconnect) return;
    ::cloudcast::client::Reconnect event;
    event.attempt = e.attempt;
    event.cause = e.cause;
    event.old_instance = e.old_instance;
    event.took = std::chrono::duration_cast<std::chrono::milliseconds>(e.took);
    event.frames_resent = e.frames_resent;
    event.frames_dropped = e.frames_dropped;
    options.on_reconnect(event);
  }

  void OnEnded(const absl::Status& status, bool /*gave_up*/) override {
    // A raw frame still kept for room never went: its Result comes before the end (delivered
    // outside send_mu, which a callback's Send would take).
    std::optional<Result> unsent;
    {
      std::lock_guard<std::mutex> lock(send_mu);
      send_closed = true;
      if (kept) {
        Result& r = unsent.emplace();
        r.fate = FrameFate::kUnsent;
        r.sequence = kept->sequence;
        r.frame_id = kept->meta.frame_id;
        r.capture_time_unix_ns = kept->meta.capture_time_unix_ns;
        r.status = absl::Status(
            status.ok() ? absl::StatusCode::kUnavailable : status.code(),
            absl::StrCat("frame ", kept->sequence, " was never answered (never sent): ",
                         status.ok() ? "the stream ended first" : status.message()));
        r.frames_dropped = dropped_seen;
        r.frames_replaced = replaced_seen;
        kept.reset();
      }
    }
    if (unsent) Deliver(std::move(*unsent));
    {
      std::lock_guard<std::mutex> lock(results_mu);
      ended = true;
      final_status = status;
    }
    results_cv.notify_all();
  }

  bool Read(Result* result) {
    bool resume = false;
    {
      std::unique_lock<std::mutex> lock(results_mu);
      results_cv.wait(lock, [&] { return !results.empty() || ended; });
      if (results.empty()) return false;
      *result = std::move(results.front());
      results.pop_front();
      if (reads_paused && results.size() <= kMaxBufferedResults / 2) {
        reads_paused = false;
        resume = true;
      }
    }
    if (resume) core->PauseReads(false);
    if (result->status.ok()) DecodeInto(decode_clouds, result);
    return true;
  }

  absl::Status CloseSend() {
    std::lock_guard<std::mutex> lock(send_mu);
    CloseSendLocked();
    return absl::OkStatus();
  }

  // Under send_mu. A kept raw frame is still sent (OnRoom closes after it).
  void CloseSendLocked() {
    send_closed = true;
    if (kept) {
      close_when_sent = true;
    } else {
      core->CloseSend();
    }
  }

  absl::Status Finish() {
    std::lock_guard<std::mutex> lock(finish_mu);
    if (finished) return final_status;
    // A dead call still finishes, with its real status.
    if (options.coder != nullptr && latest) {
      std::lock_guard<std::mutex> lock(send_mu);  // a kept raw frame goes first
      CloseSendLocked();
    } else {
      core->CloseSend();  // never waits for a Send held by back-pressure
    }
    bool resume = false;
    {
      // Nobody reads what is still to come: it is discarded, and reading goes on to the end.
      std::lock_guard<std::mutex> lock(results_mu);
      discard = true;
      results.clear();
      resume = reads_paused;
      reads_paused = false;
    }
    if (resume) core->PauseReads(false);
    const absl::Status status = core->AwaitEnd();
    std::lock_guard<std::mutex> results_lock(results_mu);
    final_status = status;
    finished = true;
    return final_status;
  }
};

Stream::Stream(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

Stream::~Stream() {
  if (impl_ == nullptr) return;
  {
    std::lock_guard<std::mutex> lock(impl_->finish_mu);
    if (!impl_->finished) impl_->core->Cancel();
  }
  impl_->Finish().IgnoreError();
}

absl::Status Stream::Send(const FrameInput& input, const FrameMeta& meta) {
  return impl_->Send(input, meta);
}

absl::Status Stream::Send(const DisparityInput& disparity, const ColorInput& colour,
                          const FrameMeta& meta) {
  return impl_->Send(DisparityFrame{disparity, colour}, meta);
}

absl::Status Stream::Reconfigure(const StreamConfig& config) { return impl_->Reconfigure(config); }

bool Stream::Read(Result* result) {
  if (impl_->options.on_result) return false;
  return impl_->Read(result);
}

absl::Status Stream::CloseSend() { return impl_->CloseSend(); }

absl::Status Stream::Finish() { return impl_->Finish(); }

void Stream::Cancel() { impl_->core->Cancel(); }

std::uint64_t Stream::image_bytes_sent() const {
  return impl_->image_bytes_sent.load(std::memory_order_relaxed);
}

std::uint64_t Stream::frames_sent() const {
  return impl_->core->submitted() - impl_->core->replaced();
}

std::uint64_t Stream::frames_replaced() const { return impl_->core->replaced(); }
std::optional<RateEstimate> Stream::rate() const { return impl_->core->rate(); }

int Stream::reconnects() const { return impl_->core->reconnects(); }

std::uint64_t Stream::frames_resent() const { return impl_->core->resent(); }

// ---------------------------------------------------------------------------------------------
// Client

struct Client::Impl {
  std::string target;
  ClientOptions options;
  std::shared_ptr<grpc::Channel> channel;
  std::shared_ptr<Stub> stub;

  void PrepareUnary(grpc::ClientContext* context) const {
    if (options.call_timeout.count() > 0) {
      context->set_deadline(std::chrono::system_clock::now() + options.call_timeout);
    }
    context->set_wait_for_ready(options.wait_for_ready);
  }
};

Client::Client(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Client::~Client() = default;

absl::StatusOr<std::unique_ptr<Client>> Client::Connect(const std::string& target,
                                                        const ClientOptions& options) {
  if (target.empty()) return absl::InvalidArgumentError("cloudcast client: empty server target");
  grpc::ChannelArguments args;
  if (options.load_balancing == "round_robin") {
    // Health checking makes round_robin pass over replicas that are draining (NOT_SERVING).
    args.SetServiceConfigJSON(
        R"({"loadBalancingConfig": [{"round_robin": {}}],)"
        R"( "healthCheckConfig": {"serviceName": "cloudcast.v1.CloudCast"}})");
    // A DNS TXT record must not replace the policy the robot asked for.
    args.SetInt(GRPC_ARG_SERVICE_CONFIG_DISABLE_RESOLUTION, 1);
  } else if (!options.load_balancing.empty() && options.load_balancing != "pick_first") {
    return absl::InvalidArgumentError(
        absl::StrCat("ClientOptions::load_balancing is '", options.load_balancing,
                     "'; it must be empty, \"pick_first\" or \"round_robin\""));
  }
  args.SetMaxReceiveMessageSize(ClampToInt(options.max_message_bytes));
  args.SetMaxSendMessageSize(ClampToInt(options.max_message_bytes));
  if (options.max_reconnect_backoff.count() > 0) {
    args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS,
                static_cast<int>(options.max_reconnect_backoff.count()));
  }
  auto created = CreateChannel(target, options.security, args, options.credentials);
  if (!created.ok()) return created.status();
  std::shared_ptr<grpc::Channel> channel = *std::move(created);
  if (options.connect_timeout.count() > 0 &&
      !channel->WaitForConnected(std::chrono::system_clock::now() + options.connect_timeout)) {
    return absl::UnavailableError(absl::StrCat(
        "cannot connect to the cloudcast server at ", target, " within ",
        options.connect_timeout.count(), " ms (channel ", StateName(channel->GetState(false)),
        "); is the server running, and are the address and port right?",
        options.security.tls.has_value()
            ? " With TLS: does the server speak TLS, does its certificate chain to the CA given "
              "and name the host (or the server name override), and does it accept this "
              "client's certificate?"
            : " (A server that speaks TLS refuses plaintext clients.)"));
  }
  auto impl = std::make_unique<Impl>();
  impl->target = target;
  impl->options = options;
  impl->stub = std::shared_ptr<Stub>(v1::CloudCast::NewStub(channel));
  impl->channel = std::move(channel);
  return std::unique_ptr<Client>(new Client(std::move(impl)));
}

absl::StatusOr<v1::ServerInfo> Client::GetInfo() {
  grpc::ClientContext context;
  impl_->PrepareUnary(&context);
  v1::ServerInfo info;
  grpc::Status s = impl_->stub->GetInfo(&context, v1::GetInfoRequest(), &info);
  if (!s.ok()) return FromGrpc(s, absl::StrCat("GetInfo on ", impl_->target));
  return info;
}

absl::StatusOr<Result> Client::Process(const DisparityInput& disparity, const ColorInput& colour,
                                       const StreamConfig& config, const FrameMeta& meta) {
  return Process(DisparityFrame{disparity, colour}, config, meta);
}

absl::StatusOr<Result> Client::Process(const FrameInput& input, const StreamConfig& config,
                                       const FrameMeta& meta) {
  v1::ProcessRequest request;
  if (absl::Status s = internal::FillImages(input, request.mutable_frame()); !s.ok()) return s;
  internal::FillMeta(meta, meta.sequence.value_or(0), request.mutable_frame());
  *request.mutable_config() = config;

  grpc::ClientContext context;
  impl_->PrepareUnary(&context);
  Result result;
  result.times.send = Clock::now();
  result.times.send_unix_ns = UnixNanosNow();
  grpc::Status s = impl_->stub->Process(&context, request, &result.reply);
  result.times.receive = Clock::now();
  result.times.receive_unix_ns = UnixNanosNow();
  if (!s.ok()) return FromGrpc(s, absl::StrCat("Process on ", impl_->target));

  result.sequence = result.reply.sequence();
  result.frame_id = result.reply.frame_id();
  result.capture_time_unix_ns = result.reply.capture_time_unix_ns();
  result.frames_dropped = result.reply.frames_dropped();
  result.keyframe_needed = Bitstreams(result.reply.keyframe_needed());
  DecodeInto(impl_->options.decode_clouds, &result);
  if (!result.status.ok()) return result.status;
  return result;
}

absl::StatusOr<std::unique_ptr<Stream>> Client::OpenStream(const StreamConfig& config,
                                                           StreamOptions options) {
  // The first Write would wait for the connection without any limit (a stream has no deadline),
  // so the wait is bounded here instead.
  if (impl_->options.wait_for_ready && impl_->options.connect_timeout.count() > 0 &&
      !impl_->channel->WaitForConnected(std::chrono::system_clock::now() +
                                        impl_->options.connect_timeout)) {
    return absl::UnavailableError(
        absl::StrCat("cannot open a stream: no connection to the cloudcast server at ",
                     impl_->target, " within ", impl_->options.connect_timeout.count(), " ms"));
  }
  auto impl = std::make_unique<Stream::Impl>();
  impl->target = impl_->target;
  impl->decode_clouds = impl_->options.decode_clouds;
  impl->options = std::move(options);
  StreamCoreOptions core;
  core.machine.name = impl->What();
  // Client-side replacement only when the stream asks for DELIVERY_LATEST itself: an unset
  // delivery may be a server's DELIVERY_ALL, whose frames must all be sent.
  core.machine.latest = config.delivery() == v1::DELIVERY_LATEST;
  core.machine.max_queued = std::max<std::size_t>(1, impl->options.max_queued_frames);
  core.machine.resilient = impl->options.resilient;
  core.machine.reconnect_timeout = impl->options.reconnect_timeout;
  core.wait_for_ready = impl_->options.wait_for_ready;
  core.config = SerializedConfig(config);
  core.rate_control = impl->options.rate_control;
  // A coder's frames are made when the core has room, and never replaced once made.
  impl->latest = core.machine.latest;
  core.machine.replace_queued = impl->options.coder == nullptr;
  impl->channel = impl_->channel;
  impl->core = StreamCore::Start(impl->channel.get(), std::move(core), impl.get());
  return std::unique_ptr<Stream>(new Stream(std::move(impl)));
}

const std::string& Client::target() const { return impl_->target; }
const ClientOptions& Client::options() const { return impl_->options; }

}  // namespace cloudcast::client
