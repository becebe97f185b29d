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
#include <thread>

#include "absl/status/status.h"

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

// One Stream call. Writes start from the scheduler threads (Due) and from the reactor's own
// callbacks (the next queued frame when a write completes); a hold keeps the call alive until
// no more writes can start. One write at a time, as gRPC requires.
class Fleet::Driver : public grpc::ClientBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer> {
 public:
  struct Context {
    const FrameStore* store;
    Recorder* recorder;
    bool closed_loop;
    int in_flight;
    bool lossless;
    std::int64_t t0_steady_ns;  // time zero of the schedule, steady clock
    std::int64_t t0_unix_ns;    // the same instant, Unix time (capture_time_unix_ns)
    std::function<void()> on_done;
  };

  Driver(int index, std::uint64_t frame_limit, const grpc::ByteBuffer* config)
      : index_(index), frame_limit_(frame_limit), config_(config) {}

  void Start(grpc::GenericStub* stub, const Context* context) {
    ctx_ = context;
    stub->PrepareBidiStreamingCall(&call_context_, kStreamMethod, grpc::StubOptions(), this);
    AddHold();  // released when no more writes can start (ReleaseHold)
    StartRead(&read_buf_);
    {
      std::lock_guard<std::mutex> lock(mu_);
      started_ = true;
      TryWriteLocked();
    }
    StartCall();
  }

  // The scheduler: the next frame is due at `intended` (steady clock, ns).
  void Due(std::int64_t intended, bool scheduler_late) {
    bool release = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (broken_ || no_more_) {
        ctx_->recorder->Unsent(1);
        return;
      }
      pending_.push_back({next_seq_++, intended, 0, 0});
      if (write_in_flight_) {
        ctx_->recorder->Late(/*flow_control=*/true);
      } else if (scheduler_late) {
        ctx_->recorder->Late(/*flow_control=*/false);
      }
      release = TryWriteLocked();
    }
    if (release) ReleaseHold();
  }

  // No more frames will be due. `discard`: frames still queued are not sent (a stop).
  void NoMoreFrames(bool discard) {
    bool release = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (no_more_) return;
      no_more_ = true;
      if (discard && !pending_.empty()) {
        ctx_->recorder->Unsent(pending_.size());
        pending_.clear();
      }
      release = TryWriteLocked();
    }
    if (release) ReleaseHold();
  }

  void Cancel() { call_context_.TryCancel(); }

  std::uint64_t sent() {
    std::lock_guard<std::mutex> lock(mu_);
    return sent_;
  }
  std::int64_t last_send_ns() {
    std::lock_guard<std::mutex> lock(mu_);
    return last_send_ns_;
  }

  void OnWriteDone(bool ok) override {
    bool release = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      write_in_flight_ = false;
      if (!ok) broken_ = true;  // the call is ending; OnDone tells how
      release = TryWriteLocked();
    }
    if (release) ReleaseHold();
  }

  void OnReadDone(bool ok) override {
    if (!ok) {
      bool release = false;
      {
        std::lock_guard<std::mutex> lock(mu_);
        broken_ = true;
        release = TryWriteLocked();
      }
      if (release) ReleaseHold();
      return;
    }
    const std::int64_t now = Ns(Clock::now());
    v1::StreamReply reply;
    const std::size_t bytes = read_buf_.Length();
    {
      grpc::ProtoBufferReader reader(&read_buf_);
      if (!reply.ParseFromZeroCopyStream(&reader)) reply.Clear();
    }
    read_buf_.Clear();
    bool release = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      Match(reply, now, bytes);
      release = TryWriteLocked();  // closed loop: the answer frees a slot
    }
    StartRead(&read_buf_);
    if (release) ReleaseHold();
  }

  void OnDone(const grpc::Status& status) override {
    std::function<void()> notify;
    {
      std::lock_guard<std::mutex> lock(mu_);
      const std::string code = CodeName(status.error_code());
      ctx_->recorder->CallStatus(code);
      if (status.ok() && !ctx_->lossless) {
        // DELIVERY_LATEST: a clean end with frames unanswered means the server skipped them.
        ctx_->recorder->Dropped(in_flight_.size());
      } else {
        ctx_->recorder->Lost(in_flight_.size(), code, status.error_message());
      }
      in_flight_.clear();
      if (!pending_.empty()) ctx_->recorder->Unsent(pending_.size());
      pending_.clear();
      ctx_->recorder->StreamEnded(server_dropped_);
      done_ = true;
      notify = ctx_->on_done;
    }
    notify();
  }

 private:
  struct Frame {
    std::uint64_t seq;
    std::int64_t intended, actual;
    std::size_t bytes;
  };

  // Starts the next write if the slot is free, or half-closes when nothing is left to write.
  // Returns whether the caller must release the hold (done outside the lock).
  bool TryWriteLocked() {
    if (!started_ || write_in_flight_ || hold_released_) return false;
    if (broken_) {
      hold_released_ = true;
      return true;
    }
    if (config_ != nullptr && !config_sent_) {
      config_sent_ = true;
      write_in_flight_ = true;
      write_buf_ = *config_;
      StartWrite(&write_buf_);
      return false;
    }
    if (pending_.empty() && ctx_->closed_loop && !no_more_ && sent_ < frame_limit_ &&
        static_cast<int>(in_flight_.size()) < ctx_->in_flight) {
      // Closed loop: the frame is intended now; there is no schedule to fall behind.
      pending_.push_back({next_seq_++, Ns(Clock::now()), 0, 0});
    }
    if (!pending_.empty()) {
      Frame f = pending_.front();
      pending_.pop_front();
      f.actual = Ns(Clock::now());
      const std::size_t frame_index = static_cast<std::size_t>(index_) + f.seq - 1;
      write_buf_ = ctx_->store->Request(frame_index, f.seq,
                                        ctx_->t0_unix_ns + (f.intended - ctx_->t0_steady_ns));
      f.bytes = write_buf_.Length();
      in_flight_.push_back(f);
      ++sent_;
      last_send_ns_ = f.actual;
      ctx_->recorder->Sent(f.bytes);
      if (ctx_->closed_loop && sent_ >= frame_limit_) no_more_ = true;
      write_in_flight_ = true;
      StartWrite(&write_buf_);
      return false;
    }
    if (no_more_) {
      hold_released_ = true;
      StartWritesDone();
      return true;
    }
    return false;
  }

  void ReleaseHold() { RemoveHold(); }

  void Match(const v1::StreamReply& reply, std::int64_t now, std::size_t bytes) {
    std::uint64_t seq = 0;
    std::string instance;
    if (reply.has_cloud()) {
      seq = reply.cloud().sequence();
      instance = reply.cloud().server_instance();
      server_dropped_ = reply.cloud().frames_dropped();
    } else if (reply.has_error()) {
      seq = reply.error().sequence();
      instance = reply.error().server_instance();
      server_dropped_ = reply.error().frames_dropped();
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
    // Replies come in order: frames before this one that got none were skipped by the server.
    std::uint64_t skipped = 0;
    while (!in_flight_.empty() && in_flight_.front().seq < seq) {
      in_flight_.pop_front();
      ++skipped;
    }
    if (skipped) ctx_->recorder->Dropped(skipped);
    if (in_flight_.empty() || in_flight_.front().seq != seq) {
      ctx_->recorder->FrameError("INTERNAL", "a reply to a frame not in flight", instance);
      return;
    }
    const Frame f = in_flight_.front();
    in_flight_.pop_front();
    if (reply.has_cloud()) {
      ctx_->recorder->Answered(now - f.intended, now - f.actual, instance, bytes);
    } else {
      ctx_->recorder->FrameError(CodeName(reply.error().code()), reply.error().message(), instance);
    }
  }

  const int index_;
  const std::uint64_t frame_limit_;
  const grpc::ByteBuffer* config_;
  const Context* ctx_ = nullptr;
  grpc::ClientContext call_context_;
  grpc::ByteBuffer write_buf_, read_buf_;

  std::mutex mu_;
  bool started_ = false;
  bool config_sent_ = false;
  bool write_in_flight_ = false;
  bool no_more_ = false;
  bool broken_ = false;
  bool hold_released_ = false;
  bool done_ = false;
  std::uint64_t next_seq_ = 1;
  std::uint64_t sent_ = 0;
  std::int64_t last_send_ns_ = 0;
  std::uint64_t server_dropped_ = 0;
  std::deque<Frame> pending_;    // due, not yet written
  std::deque<Frame> in_flight_;  // written, not yet answered
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
  std::unique_ptr<Fleet> fleet(new Fleet(o, store));
  const int channels = o.connections == 0 ? o.streams : std::min(o.connections, o.streams);
  const auto deadline = std::chrono::system_clock::now() + o.connect_timeout;
  for (int c = 0; c < channels; ++c) {
    grpc::ChannelArguments args;
    args.SetMaxReceiveMessageSize(-1);
    args.SetMaxSendMessageSize(-1);
    // A distinct argument per channel keeps gRPC from sharing one connection among them.
    args.SetInt("cloudcast.load.channel", c);
    args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
    auto channel = grpc::CreateCustomChannel(o.server, grpc::InsecureChannelCredentials(), args);
    if (!channel->WaitForConnected(deadline)) {
      return absl::UnavailableError(fmt::format(
          "--server {}: not reachable within --connect-timeout {:g} s (channel {} of {})", o.server,
          o.connect_timeout.count() / 1e9, c + 1, channels));
    }
    fleet->channels_.push_back(std::move(channel));
  }
  return fleet;
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
      o.closed_loop,
      o.in_flight,
      lossless,
      Ns(t0),
      std::chrono::duration_cast<std::chrono::nanoseconds>(result.start.time_since_epoch()).count(),
      [this] { StreamEnded(); }};
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
    const Clock::time_point wake = sending_over && !cancelled
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
