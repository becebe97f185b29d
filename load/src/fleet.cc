#include "cloudcast/load/fleet.h"

#include <grpcpp/grpcpp.h>
#include <spdlog/fmt/fmt.h>
#include <sys/resource.h>

#include <algorithm>
#include <optional>
#include <queue>
#include <random>
#include <set>
#include <thread>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "cloudcast/client/stream_core.h"
#include "cloudcast/load/thread_cpu.h"
#include "cloudcast/proto/convert.h"
#include "cloudcast/v1/cloudcast.grpc.pb.h"
#include "cloudcast/video/frame_encoder.h"

namespace cloudcast::load {
namespace {

using Clock = std::chrono::steady_clock;
// A send the scheduler itself issues this much after its intended time counts as late.
constexpr auto kSchedulerSlack = std::chrono::milliseconds(1);

std::int64_t Ns(Clock::time_point t) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(t.time_since_epoch()).count();
}

// The process's CPU time so far (user + system), seconds.
double ProcessCpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  const auto seconds = [](const timeval& t) {
    return static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_usec) / 1e6;
  };
  return seconds(u.ru_utime) + seconds(u.ru_stime);
}

}  // namespace

const char* Name(EndReason reason) {
  switch (reason) {
    case EndReason::kNormal:
      return "normal";
    case EndReason::kTimeout:
      return "timeout";
    case EndReason::kCancel:
      return "cancel";
  }
  return "normal";
}

const char* CodeName(int code) {
  static const char* const kNames[] = {"OK",
                                       "CANCELLED",
                                       "UNKNOWN",
                                       "INVALID_ARGUMENT",
                                       "DEADLINE_EXCEEDED",
                                       "NOT_FOUND",
                                       "ALREADY_EXISTS",
                                       "PERMISSION_DENIED",
                                       "RESOURCE_EXHAUSTED",
                                       "FAILED_PRECONDITION",
                                       "ABORTED",
                                       "OUT_OF_RANGE",
                                       "UNIMPLEMENTED",
                                       "INTERNAL",
                                       "UNAVAILABLE",
                                       "DATA_LOSS",
                                       "UNAUTHENTICATED"};
  return code >= 0 && code <= 16 ? kNames[code] : "UNKNOWN";
}

// One robot's stream: the client library's stream core (its calls, queue, replacement, resends,
// reconnects and give-up), fed by the scheduler threads (Due) or, in closed loop, by its own
// answers; its events become the recorder's counts and the stream's account.
class Fleet::Driver : public client::StreamSink {
 public:
  struct Context {
    const FrameStore* store;
    Recorder* recorder;
    Fleet* fleet;
    bool closed_loop;
    int in_flight;
    bool lossless;
    bool resilient;
    std::int64_t reconnect_timeout_ns;
    std::int64_t t0_steady_ns;  // time zero of the schedule, steady clock
    std::int64_t t0_unix_ns;    // the same instant, Unix time (capture_time_unix_ns)
    std::optional<client::RateControlOptions> rate_control;
    double fps;  // the schedule's rate at its start (the rate controller's frame budget)
    const VideoSequence* video;  // the store's picture sequence; null: frames in any order
    FrameLog* frame_log;         // null: none
    std::int64_t Unix(std::int64_t steady_ns) const {
      return t0_unix_ns + (steady_ns - t0_steady_ns);
    }
  };

  Driver(int index, std::uint64_t frame_limit, const grpc::ByteBuffer* config)
      : index_(index), frame_limit_(frame_limit), config_(config) {
    stats_.index = index;
  }
  // The stream has ended by now (Run waits for every stream); its calls are released here.
  ~Driver() {
    if (core_ != nullptr) core_->AwaitEnd().IgnoreError();
  }

  // `channel` (the fleet's) outlives the stream.
  void Start(grpc::Channel* channel, const Context* context) {
    ctx_ = context;
    client::StreamCoreOptions o;
    o.machine.name = "stream";  // the same words for every stream, so the report groups them
    o.machine.reconnect_timeout_name = "--reconnect-timeout";
    // As robots send: DELIVERY_LATEST replaces a frame still waiting for the write slot;
    // DELIVERY_ALL queues every frame due (the generator itself never waits).
    o.machine.latest = !ctx_->lossless;
    o.machine.max_queued = 0;
    if (ctx_->video != nullptr) {
      // A picture is never replaced (the class comment): under DELIVERY_LATEST one frame may
      // wait for the write slot, and a frame due meanwhile is skipped before it is encoded.
      o.machine.latest = false;
      if (!ctx_->lossless && !ctx_->closed_loop) o.machine.max_queued = 1;
    }
    if (const auto& live = ctx_->store->live_video()) {
      // Encoded when the stream has room (WantRoom, OnRoom), as the client library's coder is:
      // a frame due meanwhile waits raw, and a newer one replaces it; a picture made is sent.
      encoder_ = std::make_unique<video::FrameEncoder>(live->encoder);
      next_picture_ = static_cast<std::size_t>(index_);  // streams start on different frames
      o.machine.replace_queued = false;
      o.machine.max_queued = 1;
    }
    o.machine.resilient = ctx_->resilient;
    o.machine.reconnect_timeout = std::chrono::nanoseconds(ctx_->reconnect_timeout_ns);
    if (config_ != nullptr) o.config = *config_;
    o.rate_control = ctx_->rate_control;
    core_ = client::StreamCore::Start(channel, std::move(o), this);
    if (ctx_->closed_loop) TopUp();
  }

  // The scheduler: the next frame is due at `intended` (steady clock, ns).
  void Due(std::int64_t intended, bool scheduler_late) {
    std::uint64_t seq;
    {
      std::lock_guard<std::mutex> lock(mu_);
      ++due_;
      if (ended_ || no_more_) {
        ctx_->recorder->Unsent(1);
        ++stats_.unsent;
        return;
      }
      seq = next_seq_++;
    }
    Submit(seq, intended, scheduler_late);
  }

  // No more frames will be due. `discard`: frames still queued are not sent (a stop); frames
  // waiting for a resend were sent once, so they still go and are awaited.
  void NoMoreFrames(bool discard) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (no_more_) return;
      no_more_ = true;
    }
    if (encoder_ != nullptr) {
      // A live video frame still waiting raw for room is not made any more.
      std::lock_guard<std::mutex> order(submit_mu_);
      if (kept_) {
        core_->Unmade(client::FrameFate::kUnsent, kept_->sequence, kept_->record,
                      absl::CancelledError("the run ended before the stream had room for it"));
        kept_.reset();
      }
    }
    core_->CloseSend(discard);
  }

  // The drain timeout: the stream is cancelled; what it still holds is reported lost.
  void Cancel() { core_->Cancel(); }

  std::uint64_t sent() {
    std::lock_guard<std::mutex> lock(mu_);
    return stats_.sent;
  }
  // Frames that fell due (sent or not).
  std::uint64_t due() {
    std::lock_guard<std::mutex> lock(mu_);
    return due_;
  }
  std::int64_t last_send_ns() {
    std::lock_guard<std::mutex> lock(mu_);
    return last_send_ns_;
  }
  StreamStats stats() {
    std::lock_guard<std::mutex> lock(mu_);
    return stats_;
  }

  // The core's events (one at a time, on gRPC's threads).
  void OnWrite(const client::WriteEvent& w) override {
    if (!w.is_frame) return;
    std::lock_guard<std::mutex> lock(mu_);
    last_send_ns_ = Ns(w.at);
    if (w.resend) {
      ++stats_.resent;
      ctx_->recorder->Resent(w.bytes);
    } else {
      ++stats_.sent;
      ctx_->recorder->Sent(w.bytes);
    }
  }

  void OnReply(v1::StreamReply& reply, std::size_t bytes, const client::SettledFrame* frame,
               Clock::time_point received) override {
    const std::int64_t now = Ns(received);
    std::string instance;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (reply.has_cloud()) {
        instance = reply.cloud().server_instance();
        server_dropped_this_call_ = reply.cloud().frames_dropped();
      } else if (reply.has_error()) {
        instance = reply.error().server_instance();
        server_dropped_this_call_ = reply.error().frames_dropped();
        if (convert::AnswersNoFrame(reply.error())) {
          ctx_->recorder->FrameError(CodeName(reply.error().code()),
                                     "config: " + reply.error().message(), instance);
          return;
        }
      } else {
        ctx_->recorder->FrameError("INTERNAL", "a reply with neither cloud nor error", instance);
        return;
      }
      if (!answered_on_call_) {
        answered_on_call_ = true;
        stats_.replicas.push_back(instance.empty() ? "(unnamed)" : instance);
      }
      if (frame == nullptr) {
        ctx_->recorder->FrameError("INTERNAL", "a reply to a frame not in flight", instance);
        return;
      }
      if (ctx_->video != nullptr || encoder_ != nullptr) {
        const int needed = reply.has_cloud() ? reply.cloud().keyframe_needed_size()
                                             : reply.error().keyframe_needed_size();
        if (needed > 0) {
          ++stats_.keyframe_needed;
          ctx_->recorder->KeyframeNeeded();
          // One request, one IDR: replies to frames sent before the latest IDR ask for nothing.
          if (idr_sequence_ <= frame->sequence) restart_ = true;
        }
      }
      // Latency from the intended time (the schedule's), service time from the latest write.
      const std::int64_t intended = frame->frame.record.intended_ns;
      const std::int64_t actual = Ns(frame->frame.written);
      if (reply.has_cloud()) {
        ++stats_.answered;
        ctx_->recorder->Answered(now - intended, now - actual, instance, bytes);
        ctx_->recorder->Downlink(reply.cloud().color_bits(), reply.cloud().has_over_cap());
        if (ctx_->frame_log != nullptr) LogFrame(reply.cloud(), *frame, now, bytes, instance);
        if (rate_) {
          ctx_->recorder->RateSample(index_, *rate_, frame->frame.record.image_bytes);
        }
      } else {
        ++stats_.frame_errors;
        ctx_->recorder->FrameError(CodeName(reply.error().code()), reply.error().message(),
                                   instance);
      }
    }
    if (ctx_->closed_loop) TopUp();
  }

  // Under mu_: the answered frame's line of --frame-log.
  void LogFrame(const v1::CloudReply& cloud, const client::SettledFrame& frame,
                std::int64_t received_ns, std::size_t reply_bytes, const std::string& instance) {
    FrameLogRow row;
    row.stream = index_;
    row.sequence = frame.sequence;
    row.intended_unix_ns = ctx_->Unix(frame.frame.record.intended_ns);
    row.written_unix_ns = ctx_->Unix(Ns(frame.frame.written));
    row.server_receive_unix_ns = cloud.receive_time_unix_ns();
    row.server_send_unix_ns = cloud.send_time_unix_ns();
    row.received_unix_ns = ctx_->Unix(received_ns);
    row.image_bytes = frame.frame.record.image_bytes;
    row.reply_bytes = reply_bytes;
    row.points = cloud.point_count();
    row.position_bits = cloud.position_bits();
    row.over_cap = cloud.has_over_cap();
    row.queue_us = cloud.times().queue_us();
    row.decode_us = cloud.times().decode_us();
    row.rectify_us = cloud.times().rectify_us();
    row.match_us = cloud.times().match_us();
    row.pipeline_us = cloud.times().pipeline_us();
    row.encode_us = cloud.times().encode_us();
    row.reply_cap_bytes = rate_ ? rate_->reply_cap_bytes : 0;
    row.instance = instance;
    ctx_->frame_log->Add(row);
  }

  void OnRate(const client::RateEstimate& estimate) override {
    std::lock_guard<std::mutex> lock(mu_);
    rate_ = estimate;
  }

  // Live video: the stream has room again; the frame that waited raw is encoded and sent now
  // (on this gRPC thread).
  void OnRoom() override {
    std::lock_guard<std::mutex> order(submit_mu_);
    if (!kept_) return;
    const Kept k = std::move(*kept_);
    kept_.reset();
    EncodeAndSubmit(k.sequence, k.record, k.scheduler_late);
  }

  void OnSettled(client::SettledFrame& s) override {
    {
      std::lock_guard<std::mutex> lock(mu_);
      switch (s.fate) {
        case client::FrameFate::kReplaced:
          ++stats_.replaced;
          ctx_->recorder->Replaced(1);
          break;
        case client::FrameFate::kDropped:
          ++stats_.dropped;
          ctx_->recorder->Dropped(1);
          break;
        case client::FrameFate::kLost:
        case client::FrameFate::kAnswered:
          ++stats_.lost;
          ctx_->recorder->Lost(1, CodeName(static_cast<int>(s.why.code())),
                               std::string(s.why.message()));
          break;
        case client::FrameFate::kUnsent:
          ++stats_.unsent;
          ctx_->recorder->Unsent(1);
          break;
      }
    }
    if (ctx_->closed_loop) TopUp();
  }

  void OnCallOpened(bool after_failure) override {
    std::lock_guard<std::mutex> lock(mu_);
    ++stats_.calls;
    answered_on_call_ = false;
    if (after_failure) {
      ++stats_.reconnect_attempts;
      ctx_->recorder->ReconnectAttempt();
    }
  }

  void OnCallEnded(const absl::Status& status) override {
    std::lock_guard<std::mutex> lock(mu_);
    const std::string code = CodeName(static_cast<int>(status.code()));
    ctx_->recorder->CallStatus(code);
    stats_.end_status = code;
    server_dropped_before_ += server_dropped_this_call_;
    server_dropped_this_call_ = 0;
  }

  void OnReconnected(const client::Reconnected& r) override {
    std::lock_guard<std::mutex> lock(mu_);
    stats_.reconnect_ns.push_back(r.took.count());
    ctx_->recorder->Reconnected();
  }

  void OnDuplicate() override {
    std::lock_guard<std::mutex> lock(mu_);
    ++stats_.duplicates;
    ctx_->recorder->Duplicate();
  }

  void OnEnded(const absl::Status& /*status*/, bool gave_up) override {
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (gave_up) {
        stats_.gave_up = true;
        stats_.end_status = "UNAVAILABLE";  // the stream's end, whatever the last call's was
        ctx_->recorder->GaveUp();
      }
      ctx_->recorder->StreamEnded(server_dropped_before_ + server_dropped_this_call_);
      ended_ = true;
    }
    ctx_->fleet->StreamEnded();
  }

 private:
  // Hands frame `seq`, due at `intended`, to the core.
  void Submit(std::uint64_t seq, std::int64_t intended, bool scheduler_late) {
    if (ctx_->video != nullptr) {
      SubmitPicture(seq, intended, scheduler_late);
      return;
    }
    if (encoder_ != nullptr) {
      SubmitLive(seq, intended, scheduler_late);
      return;
    }
    // The same bytes for every send of a frame: a new 20-byte header before the shared image.
    const std::size_t frame_index = static_cast<std::size_t>(index_) + seq - 1;
    std::size_t level = 0;
    if (ctx_->rate_control) {
      std::lock_guard<std::mutex> lock(mu_);
      // Before the first reply: the controller's starting rate.
      const double target = rate_ ? rate_->target_bps : ctx_->rate_control->start_bps;
      level = ctx_->store->LevelFor(target / 8 / ctx_->fps);
    }
    grpc::ByteBuffer bytes = ctx_->store->Request(
        frame_index, seq, ctx_->t0_unix_ns + (intended - ctx_->t0_steady_ns), level);
    client::FrameRecord record;
    record.intended_ns = intended;
    record.image_bytes = bytes.Length();
    Account(core_->Submit(seq, std::move(bytes), std::move(record)), scheduler_late);
  }

  // A video stream's frame `seq`: the next picture of the store's sequence (its start, an IDR,
  // when a reply asked for one). Pictures go to the core in sequence order, so one at a time.
  void SubmitPicture(std::uint64_t seq, std::int64_t intended, bool scheduler_late) {
    std::lock_guard<std::mutex> order(submit_mu_);
    std::size_t position;
    bool asked;
    {
      std::lock_guard<std::mutex> lock(mu_);
      asked = restart_;
      position = asked ? 0 : next_picture_;
    }
    grpc::ByteBuffer bytes =
        ctx_->store->Request(position, seq, ctx_->t0_unix_ns + (intended - ctx_->t0_steady_ns));
    client::FrameRecord record;
    record.intended_ns = intended;
    record.image_bytes = bytes.Length();
    const auto submitted = core_->Submit(seq, std::move(bytes), std::move(record));
    if (submitted == client::CoreMachine::Submitted::kWriting ||
        submitted == client::CoreMachine::Submitted::kQueued) {
      std::lock_guard<std::mutex> lock(mu_);
      next_picture_ = (position + 1) % ctx_->video->length;
      if (ctx_->video->keyframe[position]) {
        idr_sequence_ = seq;
        restart_ = false;
        ctx_->recorder->KeyframeSent(asked);
      }
    } else if (submitted == client::CoreMachine::Submitted::kFull) {
      // One frame already waits: this one is never encoded (DELIVERY_LATEST's skip, before the
      // encoder rather than after it).
      std::lock_guard<std::mutex> lock(mu_);
      ++stats_.skipped;
      ctx_->recorder->Skipped(1);
      return;
    }
    Account(submitted, scheduler_late);
  }

  // A live video stream's frame `seq`: encoded and sent now if the stream has room, else kept
  // raw (a newer one replaces it) until OnRoom.
  void SubmitLive(std::uint64_t seq, std::int64_t intended, bool scheduler_late) {
    std::lock_guard<std::mutex> order(submit_mu_);
    client::FrameRecord record;
    record.intended_ns = intended;
    if (kept_) {
      core_->Unmade(client::FrameFate::kReplaced, kept_->sequence, kept_->record);
      kept_.reset();
    }
    if (core_->WantRoom()) {
      EncodeAndSubmit(seq, record, scheduler_late);
    } else {
      kept_ = Kept{seq, record, scheduler_late};
    }
  }

  // Under submit_mu_: the stream's next frame of the source, its colour (a pair's both views)
  // encoded at the rate controller's bitrate, submitted.
  void EncodeAndSubmit(std::uint64_t seq, client::FrameRecord record, bool scheduler_late) {
    const LiveVideo& live = *ctx_->store->live_video();
    const std::size_t position = next_picture_++ % live.originals.size();
    bool asked;
    double target;
    {
      std::lock_guard<std::mutex> lock(mu_);
      asked = restart_;
      target = rate_ ? rate_->target_bps : ctx_->rate_control ? ctx_->rate_control->start_bps : 0;
    }
    if (asked) encoder_->RequestKeyframe();
    if (target > 0) {
      encoder_->SetStreamBitrate(static_cast<std::int64_t>(target),
                                 ctx_->store->RequestBytes(position));
    }
    absl::Status status = uplink_.Encode(live.originals[position], live.raw);
    absl::StatusOr<client::FrameInput> coded = absl::UnknownError("");
    double encode_ms = 0;
    if (status.ok()) {
      const double before = ThreadCpuMs();
      coded = encoder_->Encode(uplink_.input(), seq);
      encode_ms = ThreadCpuMs() - before;
      status = coded.status();
    }
    absl::StatusOr<std::string> pictures = absl::UnknownError("");
    if (status.ok()) {
      pictures = PictureFields(*coded);
      status = pictures.status();
    }
    if (!status.ok()) {
      core_->Unmade(
          client::FrameFate::kUnsent, seq, std::move(record),
          absl::Status(status.code(), absl::StrCat("could not be encoded: ", status.message())));
      return;
    }
    ctx_->recorder->LiveEncoded(encode_ms, pictures->size());
    const bool keyframe = IsKeyframe(*coded);
    grpc::ByteBuffer bytes = ctx_->store->RequestWith(
        position, seq, ctx_->t0_unix_ns + (record.intended_ns - ctx_->t0_steady_ns), *pictures);
    record.image_bytes = bytes.Length();
    const auto submitted = core_->Submit(seq, std::move(bytes), std::move(record));
    if (keyframe && (submitted == client::CoreMachine::Submitted::kWriting ||
                     submitted == client::CoreMachine::Submitted::kQueued)) {
      std::lock_guard<std::mutex> lock(mu_);
      idr_sequence_ = seq;
      restart_ = false;
      ctx_->recorder->KeyframeSent(asked);
    }
    Account(submitted, scheduler_late);
  }

  static bool IsKeyframe(const client::FrameInput& coded) {
    const auto picture = [](const client::ColorInput& image) {
      const auto* v = std::get_if<client::PrecodedVideo>(&image);
      return v != nullptr && v->message != nullptr && v->message->keyframe();
    };
    if (const auto* d = std::get_if<client::DisparityFrame>(&coded)) return picture(d->colour);
    if (const auto* d = std::get_if<client::DepthFrame>(&coded)) return picture(d->colour);
    return picture(std::get<client::StereoFrame>(coded).left);
  }

  // What became of a Submit, counted.
  void Account(client::CoreMachine::Submitted submitted, bool scheduler_late) {
    switch (submitted) {
      case client::CoreMachine::Submitted::kWriting:
        if (scheduler_late) ctx_->recorder->Late(/*flow_control=*/false);
        break;
      case client::CoreMachine::Submitted::kQueued:
        // The previous write (or call) is not done. (Closed loop has no schedule to be late for.)
        if (!ctx_->closed_loop) ctx_->recorder->Late(/*flow_control=*/true);
        break;
      case client::CoreMachine::Submitted::kFull:
      case client::CoreMachine::Submitted::kClosed:
      case client::CoreMachine::Submitted::kEnded: {
        std::lock_guard<std::mutex> lock(mu_);
        ctx_->recorder->Unsent(1);
        ++stats_.unsent;
        break;
      }
    }
  }

  // Closed loop: frames intended now, while fewer than `in_flight` await their fate.
  void TopUp() {
    for (;;) {
      std::uint64_t seq;
      {
        std::lock_guard<std::mutex> lock(mu_);
        if (ended_ || no_more_) return;
        if (submitted_ >= frame_limit_) {
          no_more_ = true;
          break;
        }
        const std::uint64_t settled = stats_.answered + stats_.frame_errors + stats_.lost +
                                      stats_.dropped + stats_.replaced + stats_.skipped +
                                      stats_.unsent;
        if (submitted_ - std::min(submitted_, settled) >=
            static_cast<std::uint64_t>(ctx_->in_flight)) {
          return;
        }
        seq = next_seq_++;
        ++submitted_;
        ++due_;
      }
      Submit(seq, Ns(Clock::now()), /*scheduler_late=*/false);
    }
    core_->CloseSend();  // the frame limit is reached
  }

  const int index_;
  const std::uint64_t frame_limit_;
  const grpc::ByteBuffer* config_;
  const Context* ctx_ = nullptr;
  std::shared_ptr<client::StreamCore> core_;
  std::optional<client::RateEstimate> rate_;  // the controller's, after the latest reply
  std::mutex submit_mu_;  // video: a picture's choice and its Submit, one frame at a time
  // Live video: the stream's encoder and its raw views; the frame waiting raw for room.
  struct Kept {
    std::uint64_t sequence;
    client::FrameRecord record;
    bool scheduler_late;
  };
  std::unique_ptr<video::FrameEncoder> encoder_;
  sources::UplinkFrame uplink_;
  std::optional<Kept> kept_;

  std::mutex mu_;
  bool no_more_ = false;
  bool ended_ = false;
  bool answered_on_call_ = false;
  std::uint64_t next_seq_ = 1;
  std::uint64_t submitted_ = 0;  // closed loop
  std::uint64_t due_ = 0;
  std::int64_t last_send_ns_ = 0;
  std::uint64_t server_dropped_before_ = 0;  // frames_dropped of the calls that ended
  std::uint64_t server_dropped_this_call_ = 0;
  // Video: the next picture of the sequence; the sequence of the latest frame sent with IDRs;
  // whether a reply asked for an IDR since.
  std::size_t next_picture_ = 0;
  std::uint64_t idr_sequence_ = 0;
  bool restart_ = false;
  StreamStats stats_;
};

// ---------------------------------------------------------------------------------------------

Fleet::Fleet(const FleetOptions& options, const FrameStore* store)
    : options_(options), store_(store) {}

Fleet::~Fleet() = default;

absl::StatusOr<std::unique_ptr<Fleet>> Fleet::Connect(const FleetOptions& o,
                                                      const FrameStore* store) {
  if (o.streams < 1) return absl::InvalidArgumentError("--streams must be at least 1");
  if (o.connections < 0) return absl::InvalidArgumentError("--connections must be >= 0");
  if (o.in_flight < 1) return absl::InvalidArgumentError("--in-flight must be at least 1");
  if (o.duration.count() <= 0 && o.frames == 0) {
    return absl::InvalidArgumentError("set --duration or --frames: a run must be bounded");
  }
  if (!o.closed_loop) {
    if (auto s = Schedule::Create(o.schedule); !s.ok()) return s.status();
  }
  if (store == nullptr || store->size() == 0) {
    return absl::InvalidArgumentError("no frames to send");
  }
  std::string lb = o.lb_policy.empty() ? DefaultLbPolicy(o.server) : o.lb_policy;
  if (lb != "round_robin" && lb != "pick_first") {
    return absl::InvalidArgumentError(
        fmt::format("--lb must be round_robin or pick_first, got '{}'", o.lb_policy));
  }
  if (o.resilient && o.reconnect_timeout.count() <= 0) {
    return absl::InvalidArgumentError("--reconnect-timeout must be positive");
  }
  std::unique_ptr<Fleet> fleet(new Fleet(o, store));
  fleet->lb_policy_ = lb;
  const int channels = o.connections == 0 ? o.streams : std::min(o.connections, o.streams);
  const auto deadline = std::chrono::system_clock::now() + o.connect_timeout;
  // One connection per channel: CreateChannel never lets gRPC share one among them.
  for (int c = 0; c < channels; ++c) {
    grpc::ChannelArguments args;
    args.SetMaxReceiveMessageSize(-1);
    args.SetMaxSendMessageSize(-1);
    // As the client library: a lost replica is retried within seconds, not gRPC's 2 minutes.
    args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS,
                static_cast<int>(client::ClientOptions{}.max_reconnect_backoff.count()));
    if (lb == "round_robin") {
      // Health checking makes round_robin pass over replicas that are draining (NOT_SERVING).
      args.SetServiceConfigJSON(
          R"({"loadBalancingConfig": [{"round_robin": {}}],)"
          R"( "healthCheckConfig": {"serviceName": "cloudcast.v1.CloudCast"}})");
      // A DNS TXT record must not replace the policy asked for.
      args.SetInt(GRPC_ARG_SERVICE_CONFIG_DISABLE_RESOLUTION, 1);
    }
    auto created = client::CreateChannel(o.server, o.security, args);
    if (!created.ok()) return created.status();
    std::shared_ptr<grpc::Channel> channel = *std::move(created);
    channel->GetState(/*try_to_connect=*/true);  // every channel connects meanwhile
    fleet->channels_.push_back(std::move(channel));
  }
  for (int c = 0; c < channels; ++c) {
    if (!fleet->channels_[c]->WaitForConnected(deadline)) {
      return absl::UnavailableError(fmt::format(
          "--server {}: not reachable within --connect-timeout {:g} s (channel {} of {})", o.server,
          o.connect_timeout.count() / 1e9, c + 1, channels));
    }
  }
  if (lb == "round_robin") fleet->WarmUp(deadline);
  return fleet;
}

// round_robin reports a channel ready once one replica is; the others are still connecting (and
// passing their health checks). Streams opened then would all land on the first. So before any
// stream opens, each channel is asked GetInfo (answered by the replica round_robin picks) until
// every address of an ipv4:/ipv6: list has answered, or, when the resolver decides the addresses
// (dns:///), until no new replica has answered for a moment; bounded by --connect-timeout.
void Fleet::WarmUp(std::chrono::system_clock::time_point deadline) {
  const int listed = ListedAddresses(options_.server);
  const auto settle_until = std::chrono::system_clock::now() + std::chrono::milliseconds(200);
  std::set<std::string> instances;
  for (const auto& channel : channels_) {
    auto stub = v1::CloudCast::NewStub(channel);
    // Replicas are told apart by the address that answered (two may share an instance name,
    // the host name by default).
    std::set<std::string> peers;
    int calls_since_new = 0;
    for (int call = 0; call < 10000; ++call) {
      const auto now = std::chrono::system_clock::now();
      const bool complete =
          listed > 0 ? static_cast<int>(peers.size()) >= listed
                     : now >= settle_until && calls_since_new >= 3 * std::max<int>(1, peers.size());
      if (complete || now >= deadline) break;
      grpc::ClientContext context;
      context.set_deadline(std::min(deadline, now + std::chrono::seconds(1)));
      v1::ServerInfo info;
      if (stub->GetInfo(&context, v1::GetInfoRequest(), &info).ok()) {
        instances.insert(info.instance());
        if (peers.insert(context.peer()).second) {
          calls_since_new = 0;
          continue;
        }
      }
      ++calls_since_new;
      // Nothing new: give the other replicas' connections a moment.
      if (calls_since_new % 8 == 0) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    replicas_answering_ = std::max<int>(replicas_answering_, peers.size());
  }
  replicas_at_start_.assign(instances.begin(), instances.end());
}

std::string DefaultLbPolicy(const std::string& target) {
  if (target.rfind("dns:///", 0) == 0) return "round_robin";
  return ListedAddresses(target) > 1 ? "round_robin" : "pick_first";
}

int ListedAddresses(const std::string& target) {
  for (const char* scheme : {"ipv4:", "ipv6:"}) {
    if (target.rfind(scheme, 0) == 0) {
      return 1 + static_cast<int>(std::count(target.begin(), target.end(), ','));
    }
  }
  return 0;
}

std::vector<StreamStats> Fleet::streams() const {
  std::vector<StreamStats> out;
  for (const auto& d : drivers_) out.push_back(d->stats());
  return out;
}

void Fleet::Stop() {
  stop_.store(true);
  std::lock_guard<std::mutex> lock(mu_);
  cv_.notify_all();
}

void Fleet::StreamEnded() {
  std::lock_guard<std::mutex> lock(mu_);
  ++ended_;
  cv_.notify_all();
}

int Fleet::OpenStreams() const { return static_cast<int>(drivers_.size()) - ended_; }

void Fleet::Schedule(int shard, const load::Schedule& schedule, Clock::time_point t0) {
  // A min-heap of (intended time since t0, stream) over this shard's streams.
  using Event = std::pair<std::int64_t, int>;
  std::priority_queue<Event, std::vector<Event>, std::greater<Event>> heap;
  std::vector<std::uint64_t> due(drivers_.size(), 0);
  std::mt19937_64 rng(options_.seed * 7919 + static_cast<std::uint64_t>(shard));
  std::uniform_real_distribution<double> phase(0.0, 1.0);
  const int shards = std::max(1, options_.scheduler_threads);
  const std::int64_t horizon = options_.duration.count();
  std::vector<std::uint64_t> limit(drivers_.size(), UINT64_MAX);
  if (options_.frames > 0) {
    for (std::size_t s = 0; s < drivers_.size(); ++s) {
      limit[s] = options_.frames / drivers_.size() + (s < options_.frames % drivers_.size());
    }
  }
  for (int s = shard; s < static_cast<int>(drivers_.size()); s += shards) {
    if (limit[s] == 0) {
      drivers_[s]->NoMoreFrames(false);
      continue;
    }
    heap.push({schedule.First(phase(rng)).count(), s});
  }
  while (!heap.empty() && !stop_.load()) {
    const auto [at, s] = heap.top();
    const Clock::time_point when = t0 + std::chrono::nanoseconds(at);
    {
      std::unique_lock<std::mutex> lock(mu_);
      // Wakes for a stop; timed waits on the steady clock otherwise.
      if (cv_.wait_until(lock, when, [&] { return stop_.load(); })) break;
    }
    heap.pop();
    const bool late = Clock::now() - when > kSchedulerSlack;
    drivers_[s]->Due(Ns(when), late);
    const std::int64_t next = schedule.Next(std::chrono::nanoseconds(at)).count();
    if (++due[s] < limit[s] && (horizon <= 0 || next < horizon)) {
      heap.push({next, s});
    } else {
      drivers_[s]->NoMoreFrames(false);
    }
  }
  const bool stopped = stop_.load();
  while (!heap.empty()) {
    drivers_[heap.top().second]->NoMoreFrames(stopped);
    heap.pop();
  }
  std::lock_guard<std::mutex> lock(mu_);
  --schedulers_running_;
  cv_.notify_all();
}

FleetResult Fleet::Run(const std::function<void(const SecondStats&)>& on_second) {
  FleetResult result;
  if (ran_) return result;
  ran_ = true;
  const FleetOptions& o = options_;
  const int n = o.streams;
  grpc::ByteBuffer config;
  if (o.send_config) config = SerializeConfig(o.config);
  const bool lossless = o.config.delivery() == v1::DELIVERY_ALL;

  std::vector<std::uint64_t> limit(n, UINT64_MAX);
  if (o.frames > 0) {
    for (int s = 0; s < n; ++s) {
      limit[s] = o.frames / n + (static_cast<std::uint64_t>(s) < o.frames % n);
    }
  }
  for (int s = 0; s < n; ++s) {
    drivers_.push_back(std::make_unique<Driver>(s, limit[s], o.send_config ? &config : nullptr));
  }

  // Time zero a little after the calls start, so that the first frames do not wait for the
  // calls to open.
  const Clock::time_point t0 = Clock::now() + std::chrono::milliseconds(100);
  result.start = std::chrono::system_clock::now() + std::chrono::milliseconds(100);
  Driver::Context ctx{
      store_,
      &recorder_,
      this,
      o.closed_loop,
      o.in_flight,
      lossless,
      o.resilient,
      o.reconnect_timeout.count(),
      Ns(t0),
      std::chrono::duration_cast<std::chrono::nanoseconds>(result.start.time_since_epoch()).count(),
      o.rate_control,
      o.closed_loop ? 30.0 : o.schedule.start,
      store_->video() ? &*store_->video() : nullptr,
      o.frame_log};
  const double cpu_start = ProcessCpuSeconds();
  for (int s = 0; s < n; ++s) {
    drivers_[s]->Start(channels_[static_cast<std::size_t>(s) % channels_.size()].get(), &ctx);
  }

  std::vector<std::thread> schedulers;
  std::optional<load::Schedule> schedule;
  if (!o.closed_loop) {
    schedule = Schedule::Create(o.schedule).value();
    const int shards = std::clamp(o.scheduler_threads, 1, n);
    {
      std::lock_guard<std::mutex> lock(mu_);
      schedulers_running_ = shards;
    }
    for (int k = 0; k < shards; ++k) {
      schedulers.emplace_back([this, k, &schedule, t0] { Schedule(k, *schedule, t0); });
    }
  }

  // The run's own clock: one interval per second, the closed loop's duration, the drain timeout
  // once nothing more is due, and a stop.
  EndReason reason = EndReason::kNormal;
  bool sending_over = false;
  Clock::time_point sending_over_at{};
  Clock::time_point next_second = t0 + std::chrono::seconds(1);
  bool cancelled = false;
  std::unique_lock<std::mutex> lock(mu_);
  while (ended_ < n) {
    Clock::time_point wake = sending_over && !cancelled
                                 ? std::min(next_second, sending_over_at + o.drain_timeout)
                                 : next_second;
    cv_.wait_until(lock, wake);
    const Clock::time_point now = Clock::now();
    if (stop_.load() && reason != EndReason::kCancel) reason = EndReason::kCancel;
    if (!sending_over) {
      const bool duration_over = o.duration.count() > 0 && now - t0 >= o.duration;
      if (o.closed_loop && (duration_over || stop_.load())) {
        lock.unlock();
        for (auto& d : drivers_) d->NoMoreFrames(stop_.load());
        lock.lock();
        sending_over = true;
      } else if (!o.closed_loop && schedulers_running_ == 0) {
        sending_over = true;
      } else if (o.closed_loop) {
        bool all = true;
        lock.unlock();
        for (int s = 0; s < n && all; ++s) all = drivers_[s]->sent() >= limit[s];
        lock.lock();
        if (all) sending_over = true;
      }
      if (sending_over) {
        sending_over_at = now;
        if (reason != EndReason::kCancel) {
          bool count_bound = o.frames > 0;
          if (count_bound) {
            std::uint64_t due = 0;
            lock.unlock();
            for (auto& d : drivers_) due += d->due();
            lock.lock();
            count_bound = due >= o.frames;
          }
          reason = count_bound ? EndReason::kNormal : EndReason::kTimeout;
        }
      }
    }
    if (sending_over && !cancelled && now >= sending_over_at + o.drain_timeout) {
      cancelled = true;
      lock.unlock();
      for (auto& d : drivers_) d->Cancel();
      lock.lock();
    }
    if (now >= next_second) {
      const int open = OpenStreams();
      lock.unlock();
      const SecondStats s =
          recorder_.CloseInterval(std::chrono::duration<double>(next_second - t0).count(), open);
      if (on_second) on_second(s);
      lock.lock();
      next_second += std::chrono::seconds(1);
    }
  }
  lock.unlock();
  for (auto& t : schedulers) t.join();
  const Clock::time_point end = Clock::now();
  const double t_end = std::chrono::duration<double>(end - t0).count();
  const SecondStats last = recorder_.CloseInterval(t_end, 0);
  if (on_second && last.duration_s > 0.05) on_second(last);
  std::int64_t last_send = Ns(t0);
  for (auto& d : drivers_) last_send = std::max(last_send, d->last_send_ns());
  result.end_reason = reason;
  result.elapsed_s = t_end;
  result.sending_s = (last_send - Ns(t0)) / 1e9;
  result.cpu_s = ProcessCpuSeconds() - cpu_start;
  return result;
}

}  // namespace cloudcast::load
