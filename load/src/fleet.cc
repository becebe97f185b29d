#include "cloudcast/load/fleet.h"

#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/support/proto_buffer_reader.h>
#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <deque>
#include <optional>
#include <queue>
#include <random>
#include <set>
#include <thread>

#include "absl/status/status.h"
#include "cloudcast/client/resend_ledger.h"
#include "cloudcast/v1/cloudcast.grpc.pb.h"

namespace cloudcast::load {
namespace {

using Clock = std::chrono::steady_clock;
constexpr char kStreamMethod[] = "/cloudcast.v1.CloudCast/Stream";
// A send the scheduler itself issues this much after its intended time counts as late.
constexpr auto kSchedulerSlack = std::chrono::milliseconds(1);

std::int64_t Ns(Clock::time_point t) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(t.time_since_epoch()).count();
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

// One robot's stream: a sequence of gRPC calls (one, unless resilient), each a callback reactor
// (Call). Writes start from the scheduler threads (Due), from the calls' own callbacks (the next
// queued frame when a write completes) and from Run's timers (a reconnect after a backoff). A
// hold keeps each call alive until no more writes can start on it; one write at a time per call,
// as gRPC requires. Everything below is guarded by the stream's mu_.
class Fleet::Driver {
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
  };

  Driver(int index, std::uint64_t frame_limit, const grpc::ByteBuffer* config)
      : index_(index), frame_limit_(frame_limit), config_(config) {
    stats_.index = index;
  }

  void Start(grpc::GenericStub* stub, const Context* context) {
    ctx_ = context;
    stub_ = stub;
    {
      std::lock_guard<std::mutex> lock(mu_);
      opening_ = true;
    }
    OpenCall(/*after_failure=*/false);
  }

  // The scheduler: the next frame is due at `intended` (steady clock, ns).
  void Due(std::int64_t intended, bool scheduler_late) {
    Call* release = nullptr;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (ended_ || no_more_ || (call_ != nullptr && call_->broken && !ctx_->resilient)) {
        ctx_->recorder->Unsent(1);
        ++stats_.unsent;
        return;
      }
      due_.push_back({next_seq_++, intended});
      if (call_ == nullptr || call_->write_in_flight) {
        ctx_->recorder->Late(/*flow_control=*/true);  // the previous write (or call) is not done
      } else if (scheduler_late) {
        ctx_->recorder->Late(/*flow_control=*/false);
      }
      release = TryWriteLocked(call_);
    }
    if (release != nullptr) release->RemoveHold();
  }

  // No more frames will be due. `discard`: frames still queued are not sent (a stop); frames
  // waiting for a resend were sent once, so they still go and are awaited.
  void NoMoreFrames(bool discard) {
    Call* release = nullptr;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (no_more_) return;
      no_more_ = true;
      if (discard && !due_.empty()) {
        ctx_->recorder->Unsent(due_.size());
        stats_.unsent += due_.size();
        due_.clear();
      }
      release = TryWriteLocked(call_);
    }
    if (release != nullptr) release->RemoveHold();
  }

  // The drain timeout: the current call is cancelled (its OnDone reports what it held); a stream
  // waiting to reconnect ends at once.
  void Cancel() {
    Call* cancel = nullptr;
    bool ended_now = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (ended_) return;
      cancelled_ = true;
      if (call_ != nullptr) {
        cancel = call_;
      } else if (!opening_) {
        EndLocked(grpc::Status(grpc::StatusCode::CANCELLED, "cancelled at the drain timeout"));
        ended_now = true;
      }
    }
    if (cancel != nullptr) cancel->context.TryCancel();
    if (ended_now) ctx_->fleet->StreamEnded();
  }

  // Run's loop, at or after a time this stream asked for: a reconnect whose backoff is over, or
  // the give-up deadline of a stream that has not found a working call.
  void OnTimer(std::int64_t now) {
    Call* cancel = nullptr;
    bool open = false, ended_now = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (ended_ || failing_since_ == 0) return;
      if (now - failing_since_ >= ctx_->reconnect_timeout_ns) {
        if (call_ != nullptr) {
          giving_up_ = true;  // its OnDone gives up
          cancel = call_;
        } else if (!opening_) {
          GiveUpLocked();
          ended_now = true;
        }
      } else if (retry_at_ != 0 && now >= retry_at_ && call_ == nullptr && !opening_) {
        retry_at_ = 0;
        opening_ = true;
        open = true;
      }
    }
    if (cancel != nullptr) cancel->context.TryCancel();
    if (open) OpenCall(/*after_failure=*/true);
    if (ended_now) ctx_->fleet->StreamEnded();
  }

  std::uint64_t sent() {
    std::lock_guard<std::mutex> lock(mu_);
    return sent_;
  }
  std::int64_t last_send_ns() {
    std::lock_guard<std::mutex> lock(mu_);
    return last_send_ns_;
  }
  StreamStats stats() {
    std::lock_guard<std::mutex> lock(mu_);
    return stats_;
  }

 private:
  // A frame that is due and not written yet.
  struct DueFrame {
    std::uint64_t seq;
    std::int64_t intended;
  };
  // What the stream keeps of a frame written and not answered (the ledger holds its sequence).
  struct Written {
    std::int64_t intended = 0, actual = 0;
    std::size_t bytes = 0;
  };
  using Ledger = client::ResendLedger<Written>;

  // One gRPC call of the stream. Its fields are guarded by the driver's mu_; the driver owns it
  // until the driver itself goes (a call ends a few times per stream at most).
  class Call : public grpc::ClientBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer> {
   public:
    explicit Call(Driver* driver) : driver_(driver) {}
    void OnWriteDone(bool ok) override { driver_->WriteDone(this, ok); }
    void OnReadDone(bool ok) override { driver_->ReadDone(this, ok); }
    void OnDone(const grpc::Status& status) override { driver_->CallDone(this, status); }

    grpc::ClientContext context;
    grpc::ByteBuffer write_buf, read_buf;
    bool started = false;
    bool after_failure = false;  // opened to replace a failed call
    bool config_sent = false;
    bool wrote_once = false;  // a write completed: the call is on a replica
    bool write_in_flight = false;
    bool broken = false;  // a read or write failed: the call is ending
    std::int64_t broken_at = 0;
    bool hold_released = false;
    bool answered = false;
    std::uint64_t server_dropped = 0;

   private:
    Driver* const driver_;
  };

  // Opens a call (the first, or one replacing a failed call) and starts its reads and writes.
  // The caller set opening_.
  void OpenCall(bool after_failure) {
    auto owned = std::make_unique<Call>(this);
    Call* c = owned.get();
    c->after_failure = after_failure;
    // A replacement waits for a ready replica rather than failing on a channel that has just
    // lost one; the give-up deadline bounds the wait.
    if (after_failure) c->context.set_wait_for_ready(true);
    stub_->PrepareBidiStreamingCall(&c->context, kStreamMethod, grpc::StubOptions(), c);
    c->AddHold();  // released when no more writes can start (TryWriteLocked)
    c->StartRead(&c->read_buf);
    bool cancel = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      calls_.push_back(std::move(owned));
      call_ = c;
      opening_ = false;
      c->started = true;
      ++stats_.calls;
      if (after_failure) {
        ++stats_.reconnect_attempts;
        ctx_->recorder->ReconnectAttempt();
      }
      cancel = cancelled_ || giving_up_;
      TryWriteLocked(c);  // the config (and frames) queue until StartCall
    }
    c->StartCall();
    if (cancel) c->context.TryCancel();
  }

  // Starts the next write on `c` if it is the current call and its slot is free, or half-closes
  // when nothing is left to write. Returns the call whose hold the caller must release (outside
  // the lock), or nullptr.
  Call* TryWriteLocked(Call* c) {
    if (c == nullptr || !c->started || c->write_in_flight || c->hold_released) return nullptr;
    if (c->broken) {
      c->hold_released = true;
      return c;
    }
    if (config_ != nullptr && !c->config_sent) {
      c->config_sent = true;
      c->write_in_flight = true;
      c->write_buf = *config_;
      c->StartWrite(&c->write_buf);
      return nullptr;
    }
    // Frames sent on a lost call go again first, in order, with their intended times.
    if (Ledger::Entry* again = ledger_.NextResend()) {
      Written& w = again->record;
      WriteFrameLocked(c, again->sequence, w.intended, &w);
      ++stats_.resent;
      ctx_->recorder->Resent(w.bytes);
      return nullptr;
    }
    if (due_.empty() && ctx_->closed_loop && !no_more_ && sent_ < frame_limit_ &&
        static_cast<int>(ledger_.in_flight()) < ctx_->in_flight) {
      // Closed loop: the frame is intended now; there is no schedule to fall behind.
      due_.push_back({next_seq_++, Ns(Clock::now())});
    }
    if (!due_.empty()) {
      const DueFrame d = due_.front();
      due_.pop_front();
      Written w;
      WriteFrameLocked(c, d.seq, d.intended, &w);
      ++sent_;
      ++stats_.sent;
      ctx_->recorder->Sent(w.bytes);
      ledger_.Sent(d.seq, w, /*resendable=*/ctx_->lossless);
      if (ctx_->closed_loop && sent_ >= frame_limit_) no_more_ = true;
      return nullptr;
    }
    if (no_more_) {
      c->hold_released = true;
      c->StartWritesDone();
      return c;
    }
    return nullptr;
  }

  // Starts the write of frame `seq` on `c`, and notes when and how big it went in `w`.
  void WriteFrameLocked(Call* c, std::uint64_t seq, std::int64_t intended, Written* w) {
    w->intended = intended;
    w->actual = Ns(Clock::now());
    // The same bytes as the first send: a new 20-byte header before the shared image slice.
    const std::size_t frame_index = static_cast<std::size_t>(index_) + seq - 1;
    c->write_buf =
        ctx_->store->Request(frame_index, seq, ctx_->t0_unix_ns + (intended - ctx_->t0_steady_ns));
    w->bytes = c->write_buf.Length();
    last_send_ns_ = w->actual;
    c->write_in_flight = true;
    c->StartWrite(&c->write_buf);
  }

  void MarkBrokenLocked(Call* c) {
    if (c->broken) return;
    c->broken = true;
    c->broken_at = Ns(Clock::now());
  }

  void WriteDone(Call* c, bool ok) {
    Call* release = nullptr;
    {
      std::lock_guard<std::mutex> lock(mu_);
      c->write_in_flight = false;
      if (ok) {
        if (!c->wrote_once && c->after_failure && ledger_.empty() && due_.empty()) {
          // Nothing awaits an answer: the new call being on a replica is the reconnect.
          ReconnectedLocked();
        }
        c->wrote_once = true;
      } else {
        MarkBrokenLocked(c);  // the call is ending; OnDone tells how
      }
      release = TryWriteLocked(c);
    }
    if (release != nullptr) release->RemoveHold();
  }

  void ReadDone(Call* c, bool ok) {
    if (!ok) {
      Call* release = nullptr;
      {
        std::lock_guard<std::mutex> lock(mu_);
        MarkBrokenLocked(c);
        release = TryWriteLocked(c);
      }
      if (release != nullptr) release->RemoveHold();
      return;
    }
    const std::int64_t now = Ns(Clock::now());
    v1::StreamReply reply;
    const std::size_t bytes = c->read_buf.Length();
    {
      grpc::ProtoBufferReader reader(&c->read_buf);
      if (!reply.ParseFromZeroCopyStream(&reader)) reply.Clear();
    }
    c->read_buf.Clear();
    Call* release = nullptr;
    {
      std::lock_guard<std::mutex> lock(mu_);
      Match(c, reply, now, bytes);
      release = TryWriteLocked(c);  // closed loop: the answer frees a slot
    }
    c->StartRead(&c->read_buf);
    if (release != nullptr) release->RemoveHold();
  }

  void CallDone(Call* c, const grpc::Status& status) {
    bool open = false, ended_now = false;
    std::optional<Clock::time_point> wake;
    {
      std::lock_guard<std::mutex> lock(mu_);
      const std::string code = CodeName(status.error_code());
      ctx_->recorder->CallStatus(code);
      if (ended_) return;  // a call the stream no longer waited for
      stats_.end_status = code;
      server_dropped_before_ += c->server_dropped;
      if (call_ == c) call_ = nullptr;
      const bool has_work = !ledger_.empty() || !due_.empty() || !no_more_;
      if (giving_up_) {
        GiveUpLocked();
        ended_now = true;
      } else if (ctx_->resilient && !cancelled_ && has_work &&
                 (status.error_code() == grpc::StatusCode::UNAVAILABLE ||
                  // a server stopping while this call was opening cancels it
                  status.error_code() == grpc::StatusCode::CANCELLED)) {
        const std::int64_t now = Ns(Clock::now());
        if (failing_since_ == 0) failing_since_ = c->broken_at != 0 ? c->broken_at : now;
        cause_ = status.error_message();
        if (now - failing_since_ >= ctx_->reconnect_timeout_ns) {
          GiveUpLocked();
          ended_now = true;
        } else {
          RequeueUnansweredLocked();
          // The first attempt goes at once; a replacement that failed too backs off (20 ms,
          // doubling, at most 1 s), so a replica refusing calls is not hammered.
          ++attempts_;
          if (attempts_ == 1) {
            opening_ = true;
            open = true;
          } else {
            const std::int64_t backoff =
                std::min<std::int64_t>(20'000'000LL << std::min(attempts_ - 2, 6), 1'000'000'000);
            retry_at_ = now + backoff;
            wake = Clock::time_point(std::chrono::nanoseconds(retry_at_));
          }
          // Run's loop checks the give-up deadline too (a replacement may wait for a replica).
          ctx_->fleet->WakeAt(index_, Clock::time_point(std::chrono::nanoseconds(
                                          failing_since_ + ctx_->reconnect_timeout_ns)));
        }
      } else {
        EndLocked(status);
        ended_now = true;
      }
    }
    if (wake) ctx_->fleet->WakeAt(index_, *wake);
    if (open) OpenCall(/*after_failure=*/true);
    if (ended_now) ctx_->fleet->StreamEnded();
  }

  // The frames the lost call left unanswered: in DELIVERY_ALL they go again first, in order, on
  // the next call; in DELIVERY_LATEST they count as dropped (the server would have skipped
  // them for newer ones anyway).
  void RequeueUnansweredLocked() {
    if (const std::uint64_t dropped = ledger_.CallLost(); dropped > 0) {
      ctx_->recorder->Dropped(dropped);
      stats_.dropped += dropped;
    }
  }

  void ReconnectedLocked() {
    if (failing_since_ == 0) return;
    stats_.reconnect_ns.push_back(Ns(Clock::now()) - failing_since_);
    ctx_->recorder->Reconnected();
    failing_since_ = 0;
    attempts_ = 0;
  }

  // The stream is over: frames it still holds are accounted for as the final status says.
  void EndLocked(const grpc::Status& status) {
    const std::string code = CodeName(status.error_code());
    const std::uint64_t unanswered = ledger_.TakeUnanswered().size();
    const std::uint64_t unsent = due_.size();
    if (status.ok() && !ctx_->lossless) {
      // DELIVERY_LATEST: a clean end with frames unanswered means the server skipped them.
      ctx_->recorder->Dropped(unanswered);
      stats_.dropped += unanswered;
    } else {
      ctx_->recorder->Lost(unanswered, code, status.error_message());
      stats_.lost += unanswered;
    }
    if (unsent > 0) {
      ctx_->recorder->Unsent(unsent);
      stats_.unsent += unsent;
    }
    due_.clear();
    ctx_->recorder->StreamEnded(server_dropped_before_);
    ended_ = true;
  }

  // reconnect_timeout passed without a working call: every frame sent and unanswered is
  // reported lost, saying so.
  void GiveUpLocked() {
    stats_.gave_up = true;
    stats_.end_status = "UNAVAILABLE";  // the stream's end, whatever the last call's was
    ctx_->recorder->GaveUp();
    EndLocked(grpc::Status(
        grpc::StatusCode::UNAVAILABLE,
        fmt::format("gave up: no working call within --reconnect-timeout {:g} s (last: {})",
                    ctx_->reconnect_timeout_ns / 1e9, cause_.empty() ? "none" : cause_)));
  }

  void Match(Call* c, const v1::StreamReply& reply, std::int64_t now, std::size_t bytes) {
    std::uint64_t seq = 0;
    std::string instance;
    if (reply.has_cloud()) {
      seq = reply.cloud().sequence();
      instance = reply.cloud().server_instance();
      c->server_dropped = reply.cloud().frames_dropped();
    } else if (reply.has_error()) {
      seq = reply.error().sequence();
      instance = reply.error().server_instance();
      c->server_dropped = reply.error().frames_dropped();
      if (reply.error().kind() == v1::ERROR_KIND_CONFIG ||
          reply.error().kind() == v1::ERROR_KIND_REQUEST) {
        ctx_->recorder->FrameError(CodeName(reply.error().code()),
                                   "config: " + reply.error().message(), instance);
        return;
      }
    } else {
      ctx_->recorder->FrameError("INTERNAL", "a reply with neither cloud nor error", instance);
      return;
    }
    if (!c->answered) {
      c->answered = true;
      stats_.replicas.push_back(instance.empty() ? "(unnamed)" : instance);
    }
    // Exactly once: a sequence answered before (on an earlier call) is not counted again.
    Ledger::Reply booked = ledger_.Answer(seq);
    if (booked.match == Ledger::Match::kDuplicate) {
      ++stats_.duplicates;
      ctx_->recorder->Duplicate();
      return;
    }
    if (booked.match == Ledger::Match::kUnknown) {
      ctx_->recorder->FrameError("INTERNAL", "a reply to a frame not in flight", instance);
      return;
    }
    // Replies come in order: frames before this one that got none were skipped by the server.
    if (booked.skipped > 0) {
      ctx_->recorder->Dropped(booked.skipped);
      stats_.dropped += booked.skipped;
    }
    const Written& f = booked.entry->record;
    ReconnectedLocked();
    if (reply.has_cloud()) {
      ++stats_.answered;
      ctx_->recorder->Answered(now - f.intended, now - f.actual, instance, bytes);
    } else {
      ++stats_.frame_errors;
      ctx_->recorder->FrameError(CodeName(reply.error().code()), reply.error().message(), instance);
    }
  }

  const int index_;
  const std::uint64_t frame_limit_;
  const grpc::ByteBuffer* config_;
  const Context* ctx_ = nullptr;
  grpc::GenericStub* stub_ = nullptr;

  std::mutex mu_;
  std::vector<std::unique_ptr<Call>> calls_;
  Call* call_ = nullptr;  // the current call; nullptr between a failed call and its replacement
  bool opening_ = false;  // a call is being opened (OpenCall has not taken the lock yet)
  bool no_more_ = false;
  bool cancelled_ = false;
  bool giving_up_ = false;
  bool ended_ = false;
  std::uint64_t next_seq_ = 1;
  std::uint64_t sent_ = 0;
  std::int64_t last_send_ns_ = 0;
  std::uint64_t server_dropped_before_ = 0;  // frames_dropped of the calls that ended
  // Resilience: when the calls started failing (0: they are not), the attempts since, the time
  // of the next attempt after a backoff (0: none), and how the last call ended.
  std::int64_t failing_since_ = 0;
  int attempts_ = 0;
  std::int64_t retry_at_ = 0;
  std::string cause_;
  std::deque<DueFrame> due_;  // due, not yet written
  Ledger ledger_;             // written, not yet answered: in flight, or to be sent again
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

void Fleet::WakeAt(int driver, Clock::time_point when) {
  std::lock_guard<std::mutex> lock(mu_);
  timers_.push({when, driver});
  cv_.notify_all();
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

  std::vector<std::unique_ptr<grpc::GenericStub>> stubs;
  for (const auto& channel : channels_)
    stubs.push_back(std::make_unique<grpc::GenericStub>(channel));
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
      std::chrono::duration_cast<std::chrono::nanoseconds>(result.start.time_since_epoch())
          .count()};
  for (int s = 0; s < n; ++s) {
    drivers_[s]->Start(stubs[static_cast<std::size_t>(s) % stubs.size()].get(), &ctx);
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
    if (!timers_.empty()) wake = std::min(wake, timers_.top().first);
    cv_.wait_until(lock, wake);
    const Clock::time_point now = Clock::now();
    // Drivers' timers that are due (reconnects after a backoff, give-up deadlines).
    std::vector<int> due;
    while (!timers_.empty() && timers_.top().first <= now) {
      due.push_back(timers_.top().second);
      timers_.pop();
    }
    if (!due.empty()) {
      lock.unlock();
      for (int d : due) drivers_[d]->OnTimer(Ns(now));
      lock.lock();
    }
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
            std::uint64_t sent = 0;
            lock.unlock();
            for (auto& d : drivers_) sent += d->sent();
            lock.lock();
            count_bound = sent + recorder_.totals().unsent >= o.frames;
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
  return result;
}

}  // namespace cloudcast::load
