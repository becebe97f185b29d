#include "cloudcast/client/stream_core.h"

#include <grpcpp/support/proto_buffer_reader.h>

#include <algorithm>
#include <atomic>
#include <utility>

#include "absl/strings/str_cat.h"
#include "cloudcast/proto/convert.h"

namespace cloudcast::client {
namespace {

constexpr char kStreamMethod[] = "/cloudcast.v1.CloudCast/Stream";

// gRPC and Abseil share the google.rpc code numbering.
absl::Status FromGrpc(const grpc::Status& status, const std::string& what) {
  if (status.ok()) return absl::OkStatus();
  return absl::Status(static_cast<absl::StatusCode>(status.error_code()),
                      absl::StrCat(what, ": ", status.error_message()));
}

// A StreamRequest's bytes, parsed (false: not one).
bool ParseRequest(const grpc::ByteBuffer& bytes, v1::StreamRequest* out) {
  grpc::ByteBuffer copy(bytes);  // shares the slices; the reader needs a mutable buffer
  grpc::ProtoBufferReader reader(&copy);
  return out->ParseFromZeroCopyStream(&reader);
}

std::chrono::system_clock::time_point SystemTime(std::chrono::steady_clock::time_point t) {
  const auto from_now = t - std::chrono::steady_clock::now();
  return std::chrono::system_clock::now() +
         std::chrono::duration_cast<std::chrono::system_clock::duration>(from_now);
}

// What the machine needs of a reply.
ReplyInfo InfoOf(const v1::StreamReply& reply) {
  ReplyInfo info;
  switch (reply.kind_case()) {
    case v1::StreamReply::kCloud:
      info.sequence = reply.cloud().sequence();
      info.server_dropped = reply.cloud().frames_dropped();
      info.instance = reply.cloud().server_instance();
      break;
    case v1::StreamReply::kError:
      info.sequence = reply.error().sequence();
      info.server_dropped = reply.error().frames_dropped();
      info.instance = reply.error().server_instance();
      info.answers_frame = !convert::AnswersNoFrame(reply.error());
      break;
    case v1::StreamReply::KIND_NOT_SET:
      info.answers_frame = false;
      break;
  }
  return info;
}

// One mutex for every core's alarm callbacks (KickLocked): alarms are rare, a few per reconnect.
std::mutex& AlarmHandoff() {
  static std::mutex mu;
  return mu;
}

}  // namespace

// One gRPC call of the stream. Owned by the core (a few per stream). The core outlives it: its
// owner waits in AwaitEnd until every call's OnDone has returned, then releases the calls on the
// owner's thread (a call's ClientContext holds a reference to the channel, which must not be
// dropped last on one of gRPC's callback threads). A hold keeps the call open while writes may
// still start from the application's threads; another while reading is paused.
class StreamCore::Call : public grpc::ClientBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer> {
 public:
  // handoff_ orders the reactions after the constructor for TSan: gRPC orders them through its
  // own uninstrumented locks, which TSan cannot see (it reported core_'s read in OnDone as a race
  // with the constructor). The server's reactors take their mutex first for the same reason.
  explicit Call(StreamCore* core) : core_(core) { std::lock_guard<std::mutex> lock(handoff_); }
  void OnWriteDone(bool ok) override { Core()->OnWriteDone(this, ok); }
  void OnReadDone(bool ok) override { Core()->OnReadDone(this, ok); }
  void OnDone(const grpc::Status& status) override { Core()->OnDone(this, status); }

  grpc::ClientContext context;
  grpc::ByteBuffer write_buf, read_buf;
  bool read_paused = false;  // under the core's mu_

 private:
  StreamCore* Core() {
    std::lock_guard<std::mutex> lock(handoff_);
    return core_;
  }

  std::mutex handoff_;
  StreamCore* const core_;
};

std::shared_ptr<StreamCore> StreamCore::Start(grpc::Channel* channel, StreamCoreOptions options,
                                              StreamSink* sink) {
  std::shared_ptr<StreamCore> core(new StreamCore(channel, std::move(options), sink));
  {
    std::lock_guard<std::mutex> lock(core->mu_);
    core->machine_.Start(Clock::now());
    core->CollectLocked(Clock::now());
  }
  core->Run(/*deliver=*/false);
  return core;
}

StreamCore::StreamCore(grpc::Channel* channel, StreamCoreOptions options, StreamSink* sink)
    // The stub's reference does not own the channel (an empty owner): see Start.
    : stub_(std::shared_ptr<grpc::ChannelInterface>(std::shared_ptr<void>(), channel)),
      options_(std::move(options)),
      sink_(sink),
      machine_(options_.machine, options_.config) {
  if (options_.rate_control) {
    rate_.emplace(*options_.rate_control);
    machine_.SetMaxUnanswered(static_cast<std::size_t>(rate_->frames_in_flight()), Clock::now());
    // A stream without a config has the server's defaults, as has an empty config: the cap can
    // go in either.
    if (options_.rate_control->cap_replies &&
        (!options_.config || ParseRequest(*options_.config, &stream_config_))) {
      stream_config_.mutable_config();
      reply_cap_.emplace();
      reply_cap_->SetStreamCap(stream_config_.config().draco().max_cloud_bytes());
    }
  }
}

void StreamCore::FollowReplyCapLocked(Clock::time_point now) {
  if (reply_cap_->Update(rate_->estimate(), now)) {
    // Written in order with the frames: the server caps the replies of those after it.
    machine_.Reconfigure(ConfigWithReplyCapLocked(), now).IgnoreError();
  }
}

void StreamCore::CameraFrameLocked(Clock::time_point now) {
  if (!reply_cap_) return;
  reply_cap_->OnFrame(now);
  FollowReplyCapLocked(now);
}

grpc::ByteBuffer StreamCore::ConfigWithReplyCapLocked() const {
  v1::StreamRequest request = stream_config_;
  const std::uint64_t cap = reply_cap_->cap();
  // The stream's own min_color_bits stays; only the cap changes.
  v1::DracoConfig* draco = request.mutable_config()->mutable_draco();
  if (cap == 0) {
    draco->clear_max_cloud_bytes();
  } else {
    draco->set_max_cloud_bytes(cap);
  }
  const std::string bytes = request.SerializeAsString();
  grpc::Slice slice(bytes);
  return grpc::ByteBuffer(&slice, 1);
}

StreamCore::~StreamCore() {
  // Alarms still set are cancelled; their callbacks hold only a weak reference.
  for (Timer& t : alarms_) t.alarm->Cancel();
}

void StreamCore::CollectLocked(Clock::time_point now) {
  CoreMachine::Effects e = machine_.TakeEffects();
  if (e.open_call) {
    if (rate_) rate_->OnCallOpened();
    Op op{Op::kOpen};
    op.after_failure = e.after_failure;
    ops_.push_back(std::move(op));
    Event ev{Event::kCallOpened};
    ev.after_failure = e.after_failure;
    events_.push_back(std::move(ev));
  }
  if (e.write) {
    if (rate_ && e.write->is_frame && !e.write->resend) {
      rate_->OnFrameWritten(e.write->payload.Length());
      written_bytes_.emplace_back(e.write->sequence, e.write->payload.Length());
    }
    Event ev{Event::kWrite};
    ev.write = WriteEvent{e.write->is_frame, e.write->resend, e.write->sequence,
                          e.write->payload.Length(), now};
    events_.push_back(std::move(ev));
    Op op{Op::kWrite};
    op.bytes = std::move(e.write->payload);
    ops_.push_back(std::move(op));
  }
  if (e.writes_done) ops_.push_back(Op{Op::kWritesDone});
  if (e.release_writes) ops_.push_back(Op{Op::kReleaseWrites});
  if (e.cancel_call) ops_.push_back(Op{Op::kCancel});
  for (SettledFrame& s : e.settled) {
    Event ev{Event::kSettled};
    ev.frame = std::move(s);
    events_.push_back(std::move(ev));
  }
  if (e.reconnected) {
    Event ev{Event::kReconnected};
    ev.reconnected = std::move(*e.reconnected);
    events_.push_back(std::move(ev));
  }
  if (e.room) events_.push_back(Event{Event::kRoom});
  if (e.wake_at) KickLocked(*e.wake_at);
  if (e.queue_freed || e.ended) changed_.notify_all();
  if (e.ended) {
    Event ev{Event::kEnded};
    ev.status = machine_.status();
    ev.gave_up = machine_.gave_up();
    events_.push_back(std::move(ev));
  }
}

void StreamCore::KickLocked(Clock::time_point at) {
  if (next_wake_ && *next_wake_ <= at) return;  // an earlier alarm will look again
  next_wake_ = at;
  // Alarms that have fired are no longer needed; keep the list short.
  alarms_.erase(std::remove_if(alarms_.begin(), alarms_.end(),
                               [](const Timer& t) { return t.fired->load(); }),
                alarms_.end());
  Timer timer{std::make_unique<grpc::Alarm>(), std::make_shared<std::atomic<bool>>(false)};
  std::weak_ptr<StreamCore> weak = weak_from_this();
  std::shared_ptr<std::atomic<bool>> fired = timer.fired;
  // AlarmHandoff() orders the callback after its captures were written, for TSan: grpc::Alarm
  // hands the callback to gRPC's thread through locks TSan cannot see. gRPC never runs it inside
  // Set (it runs on its executor), so holding the mutex here cannot deadlock.
  std::lock_guard<std::mutex> handoff(AlarmHandoff());
  timer.alarm->Set(SystemTime(at), [weak, fired](bool expired) {
    { std::lock_guard<std::mutex> ordered(AlarmHandoff()); }
    if (expired) {
      if (std::shared_ptr<StreamCore> core = weak.lock()) core->OnTimer();
    }
    fired->store(true);
  });
  alarms_.push_back(std::move(timer));
}

void StreamCore::OnTimer() {
  const Clock::time_point now = Clock::now();
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (next_wake_ && *next_wake_ <= now) next_wake_.reset();
    machine_.Timer(now);
    CollectLocked(now);
  }
  Run(/*deliver=*/true);
}

void StreamCore::Run(bool deliver) {
  RunOps();
  if (deliver) {
    DeliverEvents();
  } else {
    // Only what the application waits for is worth a timer's thread hop; write and call-opened
    // notes go with the reaction that always follows them (the write's completion).
    std::lock_guard<std::mutex> lock(mu_);
    const bool urgent = std::any_of(events_.begin(), events_.end(), [](const Event& e) {
      return e.kind != Event::kWrite && e.kind != Event::kCallOpened;
    });
    if (urgent && !delivering_) KickLocked(Clock::now());
  }
}

void StreamCore::RunOps() {
  std::unique_lock<std::mutex> lock(mu_);
  if (running_ops_) return;  // the thread running them takes these too, in order
  running_ops_ = true;
  while (!ops_.empty()) {
    Op op = std::move(ops_.front());
    ops_.pop_front();
    lock.unlock();
    Call* c = current_;
    switch (op.kind) {
      case Op::kOpen: {
        auto owned = std::make_unique<Call>(this);
        c = owned.get();
        // A call replacing a lost one waits for a ready replica (the give-up timer bounds it).
        c->context.set_wait_for_ready(op.after_failure || options_.wait_for_ready);
        stub_.PrepareBidiStreamingCall(&c->context, kStreamMethod, grpc::StubOptions(), c);
        c->AddHold();  // released when no more writes can start (kReleaseWrites)
        c->StartRead(&c->read_buf);
        lock.lock();
        ++live_calls_;  // before the call can end
        lock.unlock();
        c->StartCall();
        current_ = c;
        lock.lock();
        calls_.push_back(std::move(owned));
        lock.unlock();
        break;
      }
      case Op::kWrite:
        c->write_buf = std::move(op.bytes);
        c->StartWrite(&c->write_buf);
        break;
      case Op::kWritesDone:
        c->StartWritesDone();
        break;
      case Op::kReleaseWrites:
        c->RemoveHold();
        break;
      case Op::kCancel:
        if (c != nullptr) c->context.TryCancel();
        break;
      case Op::kResumeRead:
        op.call->StartRead(&op.call->read_buf);
        op.call->RemoveHold();
        break;
    }
    lock.lock();
  }
  running_ops_ = false;
}

void StreamCore::DeliverEvents() {
  std::unique_lock<std::mutex> lock(mu_);
  if (delivering_) return;  // the thread delivering takes these too, in order
  delivering_ = true;
  while (!events_.empty() && !end_delivered_) {
    Event ev = std::move(events_.front());
    events_.pop_front();
    lock.unlock();
    switch (ev.kind) {
      case Event::kReply:
        if (ev.rate) sink_->OnRate(*ev.rate);
        sink_->OnReply(ev.reply, ev.bytes, ev.frame ? &*ev.frame : nullptr, ev.at);
        break;
      case Event::kSettled:
        sink_->OnSettled(*ev.frame);
        break;
      case Event::kWrite:
        sink_->OnWrite(ev.write);
        break;
      case Event::kCallOpened:
        sink_->OnCallOpened(ev.after_failure);
        break;
      case Event::kCallEnded:
        sink_->OnCallEnded(ev.status);
        break;
      case Event::kReconnected:
        sink_->OnReconnected(ev.reconnected);
        break;
      case Event::kDuplicate:
        sink_->OnDuplicate();
        break;
      case Event::kRoom:
        sink_->OnRoom();
        break;
      case Event::kEnded:
        sink_->OnEnded(ev.status, ev.gave_up);
        break;
    }
    lock.lock();
    if (ev.kind == Event::kEnded) {
      events_.clear();  // nothing follows the end
      end_delivered_ = true;
      changed_.notify_all();
    }
  }
  delivering_ = false;
}

CoreMachine::Submitted StreamCore::Submit(std::uint64_t sequence, grpc::ByteBuffer bytes,
                                          FrameRecord record) {
  CoreMachine::Submitted result;
  {
    std::lock_guard<std::mutex> lock(mu_);
    const Clock::time_point now = Clock::now();
    CameraFrameLocked(now);
    result = machine_.Submit(sequence, std::move(bytes), std::move(record), now);
    CollectLocked(now);
  }
  Run(/*deliver=*/false);
  return result;
}

CoreMachine::Submitted StreamCore::SubmitWaiting(std::uint64_t sequence, grpc::ByteBuffer bytes,
                                                 FrameRecord record,
                                                 const std::function<bool()>& give_up) {
  CoreMachine::Submitted result;
  {
    std::unique_lock<std::mutex> lock(mu_);
    for (;;) {
      const Clock::time_point now = Clock::now();
      // The machine copies nothing until it accepts the frame.
      result = machine_.Submit(sequence, bytes, record, now);
      if (result != CoreMachine::Submitted::kFull) {
        CameraFrameLocked(now);
        CollectLocked(now);
        break;
      }
      if (give_up && give_up()) break;
      // Bounded waits, so that `give_up` is looked at even without a wake-up.
      changed_.wait_for(lock, std::chrono::milliseconds(100));
    }
  }
  Run(/*deliver=*/false);
  return result;
}

bool StreamCore::WantRoom() {
  std::lock_guard<std::mutex> lock(mu_);
  return machine_.WantRoom();
}

void StreamCore::Unmade(FrameFate fate, std::uint64_t sequence, FrameRecord record,
                        absl::Status why) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    const Clock::time_point now = Clock::now();
    CameraFrameLocked(now);  // the camera made it: its reply was due too
    machine_.Unmade(fate, sequence, std::move(record), now, std::move(why));
    CollectLocked(now);
  }
  Run(/*deliver=*/false);
}

absl::Status StreamCore::Reconfigure(grpc::ByteBuffer config) {
  absl::Status s;
  {
    std::lock_guard<std::mutex> lock(mu_);
    const Clock::time_point now = Clock::now();
    v1::StreamRequest parsed;
    if (reply_cap_ && ParseRequest(config, &parsed) && parsed.has_config()) {
      // The owner's new config, with the replies' cap in force (never above its own).
      stream_config_ = std::move(parsed);
      reply_cap_->SetStreamCap(stream_config_.config().draco().max_cloud_bytes());
      config = ConfigWithReplyCapLocked();
    }
    s = machine_.Reconfigure(std::move(config), now);
    CollectLocked(now);
  }
  Run(/*deliver=*/false);
  return s;
}

void StreamCore::CloseSend(bool discard_queued) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    const Clock::time_point now = Clock::now();
    machine_.CloseSend(discard_queued, now);
    CollectLocked(now);
  }
  Run(/*deliver=*/false);
}

void StreamCore::Cancel() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    machine_.Cancel();
    CollectLocked(Clock::now());
    // A paused reader would keep the cancelled call from ending.
    pause_reads_ = false;
    ResumePausedReadsLocked();
  }
  Run(/*deliver=*/false);
}

void StreamCore::ResumePausedReadsLocked() {
  for (auto& c : calls_) {
    if (c->read_paused) {
      c->read_paused = false;
      Op op{Op::kResumeRead};
      op.call = c.get();
      ops_.push_back(std::move(op));
    }
  }
}

void StreamCore::PauseReads(bool paused) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    pause_reads_ = paused;
    if (paused) return;
    ResumePausedReadsLocked();
  }
  Run(/*deliver=*/false);
}

void StreamCore::OnWriteDone(Call* /*call*/, bool ok) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    const Clock::time_point now = Clock::now();
    machine_.WriteDone(ok, now);
    CollectLocked(now);
  }
  Run(/*deliver=*/true);
}

void StreamCore::OnReadDone(Call* call, bool ok) {
  const Clock::time_point now = Clock::now();
  if (!ok) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      machine_.ReadFailed(now);
      CollectLocked(now);
    }
    Run(/*deliver=*/true);
    return;
  }
  Event ev{Event::kReply};
  ev.at = now;
  ev.bytes = call->read_buf.Length();
  {
    grpc::ProtoBufferReader reader(&call->read_buf);
    if (!ev.reply.ParseFromZeroCopyStream(&reader)) ev.reply.Clear();
  }
  call->read_buf.Clear();
  bool paused = false;
  {
    std::lock_guard<std::mutex> lock(mu_);
    CoreMachine::Answer answer = machine_.Reply(InfoOf(ev.reply));
    if (rate_ && answer.frame) {
      // The frame's size as written; frames before it that got no reply are gone too.
      std::size_t frame_bytes = 0;
      while (!written_bytes_.empty() && written_bytes_.front().first <= answer.frame->sequence) {
        if (written_bytes_.front().first == answer.frame->sequence) {
          frame_bytes = written_bytes_.front().second;
        }
        written_bytes_.pop_front();
      }
      const v1::CloudReply& cloud = ev.reply.cloud();  // the default instance for an error
      rate_->OnReply({answer.frame->frame.written, now, frame_bytes, cloud.receive_time_unix_ns(),
                      cloud.send_time_unix_ns(), cloud.stream_bytes_received(), ev.bytes});
      machine_.SetMaxUnanswered(static_cast<std::size_t>(rate_->frames_in_flight()), now);
      ev.rate = rate_->estimate();
      if (reply_cap_) {
        FollowReplyCapLocked(now);
        ev.rate->reply_cap_bytes = reply_cap_->cap();
      }
    }
    CollectLocked(now);  // frames skipped before this one come first
    if (answer.kind == CoreMachine::Answer::kDuplicate) {
      events_.push_back(Event{Event::kDuplicate});
    } else {
      if (answer.frame) ev.frame = std::move(answer.frame);
      events_.push_back(std::move(ev));
    }
    if (pause_reads_) {
      call->read_paused = true;
      call->AddHold();  // the call stays open until reading resumes
      paused = true;
    }
  }
  Run(/*deliver=*/true);
  if (!paused) call->StartRead(&call->read_buf);
}

void StreamCore::OnDone(Call* call, const grpc::Status& status) {
  const Clock::time_point now = Clock::now();
  {
    std::lock_guard<std::mutex> lock(mu_);
    const absl::Status ended = FromGrpc(status, options_.machine.name);
    Event ev{Event::kCallEnded};
    ev.status = ended;
    events_.push_back(std::move(ev));
    call->read_paused = false;
    machine_.CallDone(ended, now);
    CollectLocked(now);
  }
  Run(/*deliver=*/true);
  // The last this call does: AwaitEnd may release it (and the core) once this is seen.
  std::lock_guard<std::mutex> lock(mu_);
  --live_calls_;
  changed_.notify_all();
}

absl::Status StreamCore::AwaitEnd() {
  std::vector<std::unique_ptr<Call>> done;
  absl::Status status;
  {
    std::unique_lock<std::mutex> lock(mu_);
    changed_.wait(lock, [&] { return end_delivered_ && live_calls_ == 0; });
    status = machine_.status();
    done.swap(calls_);
  }
  return status;  // `done` goes here, on the caller's thread
}

bool StreamCore::ended() const {
  std::lock_guard<std::mutex> lock(mu_);
  return machine_.ended();
}

std::optional<RateEstimate> StreamCore::rate() const {
  std::lock_guard<std::mutex> lock(mu_);
  if (!rate_) return std::nullopt;
  return rate_->estimate();
}

#define CLOUDCAST_CORE_COUNTER(type, name)         \
  type StreamCore::name() const {                  \
    std::lock_guard<std::mutex> lock(mu_);         \
    return machine_.name();                        \
  }
CLOUDCAST_CORE_COUNTER(std::uint64_t, submitted)
CLOUDCAST_CORE_COUNTER(std::uint64_t, written)
CLOUDCAST_CORE_COUNTER(std::uint64_t, resent)
CLOUDCAST_CORE_COUNTER(std::uint64_t, replaced)
CLOUDCAST_CORE_COUNTER(int, reconnects)
CLOUDCAST_CORE_COUNTER(int, calls)
CLOUDCAST_CORE_COUNTER(bool, gave_up)
CLOUDCAST_CORE_COUNTER(std::uint64_t, frames_dropped_reported)
#undef CLOUDCAST_CORE_COUNTER

}  // namespace cloudcast::client
