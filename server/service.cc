#include "service.h"

#include <algorithm>
#include <deque>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/limits.h"
#include "draco/core/draco_version.h"
#include "spdlog/spdlog.h"

#ifndef CLOUDCAST_VERSION
#define CLOUDCAST_VERSION "unknown"
#endif

namespace cloudcast::server {
namespace {

using Clock = std::chrono::steady_clock;

std::int64_t UnixNanos() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

grpc::Status ToGrpc(const absl::Status& s) {
  // absl and gRPC share the canonical code numbers.
  return grpc::Status(static_cast<grpc::StatusCode>(s.code()), std::string(s.message()));
}

std::uint32_t Micros(Clock::duration d) {
  return static_cast<std::uint32_t>(std::clamp<std::int64_t>(
      std::chrono::duration_cast<std::chrono::microseconds>(d).count(), 0, 4'000'000'000));
}

// Frame errors are the client's, not the server's: logged at debug level only, so that a
// misbehaving client cannot flood the log.
void LogFrameError(const std::string& peer, const absl::Status& s) {
  spdlog::debug("frame error from {}: {}", peer, s.ToString());
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// One Stream call.
//
// Lifetime: the reactor counts references: one for gRPC (dropped in OnDone), one per frame in
// the worker pool, one per housekeeping visit. The last Unref deletes it, so a worker can still
// touch its stream after gRPC is done with the call.
//
// Locking: mu_ guards the state. Every decision to call StartRead / StartWrite / Finish /
// TryCancel is taken under mu_; the calls themselves are made after mu_ is released, under
// ops_mu_, which is taken before mu_ is let go. So the calls reach gRPC in the order they were
// decided and none comes after Finish. (Reactions are not run inline by gRPC for non-inlineable
// reactors, so holding ops_mu_ across the calls cannot deadlock.)
class CloudCastService::StreamReactor final
    : public grpc::ServerBidiReactor<v1::StreamRequest, v1::StreamReply> {
 public:
  StreamReactor(CloudCastService* service, grpc::CallbackServerContext* context)
      : service_(service),
        context_(context),
        peer_(context->peer()),
        settings_(service->default_settings_),
        last_activity_(Clock::now()) {
    spdlog::info("stream from {} opened ({} active)", peer_, service_->active_streams());
    service_->Register(this);
    std::unique_lock<std::mutex> lock(mu_);
    if (service_->draining()) draining_ = true;
    Actions actions;
    PumpLocked(&actions);
    Perform(lock, actions);
  }

  void OnReadDone(bool ok) override {
    std::unique_lock<std::mutex> lock(mu_);
    Job* job = reading_;
    reading_ = nullptr;
    last_activity_ = Clock::now();
    if (!ok) {
      read_closed_ = true;  // the client closed its side, or the call is gone
      Release(job);
    } else if (finish_sent_ || cancelled_ || draining_) {
      Release(job);  // read after draining began: not answered
    } else {
      service_->metrics_->bytes_received.Increment(
          static_cast<double>(job->request.ByteSizeLong()));
      Accept(job);
    }
    Actions actions;
    PumpLocked(&actions);
    Perform(lock, actions);
  }

  void OnWriteDone(bool ok) override {
    std::unique_lock<std::mutex> lock(mu_);
    Job* job = writing_;
    writing_ = nullptr;
    last_activity_ = Clock::now();
    if (!ok) write_failed_ = true;  // the call is broken (cancelled or the client went away)
    --held_;
    Release(job);
    Actions actions;
    PumpLocked(&actions);
    Perform(lock, actions);
  }

  void OnCancel() override {
    std::unique_lock<std::mutex> lock(mu_);
    cancelled_ = true;
    DropPending();
    Actions actions;
    PumpLocked(&actions);
    Perform(lock, actions);
  }

  void OnDone() override {
    {
      std::lock_guard<std::mutex> lock(mu_);
      spdlog::info("stream from {} done: {} replies, {} dropped", peer_, next_write_order_,
                   dropped_);
    }
    service_->Unregister(this);
    Unref();
  }

  void Ref() { refs_.fetch_add(1, std::memory_order_relaxed); }
  void Unref() {
    if (refs_.fetch_sub(1, std::memory_order_acq_rel) == 1) delete this;
  }

  // Ends the stream if nothing moved on it for the idle timeout.
  void CheckIdle(Clock::time_point now) {
    std::unique_lock<std::mutex> lock(mu_);
    if (finish_sent_ || end_requested_ || cancel_requested_ || cancelled_ || in_work_ > 0) return;
    if (now - last_activity_ < service_->options_.idle_timeout) return;
    const double seconds = Seconds(service_->options_.idle_timeout);
    spdlog::info("stream from {} idle for {} s: ending it", peer_, seconds);
    service_->metrics_->streams_idle_timeout.Increment();
    Actions actions;
    if (writing_ != nullptr) {
      // The client neither sends nor takes our reply; a Finish must wait for the write, which
      // will not complete, so cancel the call instead.
      cancel_requested_ = true;
      actions.cancel = true;
    } else {
      end_requested_ = true;
      end_status_ = grpc::Status(grpc::StatusCode::DEADLINE_EXCEEDED,
                                 absl::StrCat("stream idle: nothing received or sent for ", seconds,
                                              " s (the server's idle timeout, --idle-timeout)"));
      PumpLocked(&actions);
    }
    Perform(lock, actions);
  }

  // Stops reading; the frames already held are answered, then the stream ends (UNAVAILABLE).
  void BeginDrain() {
    std::unique_lock<std::mutex> lock(mu_);
    draining_ = true;
    Actions actions;
    PumpLocked(&actions);
    Perform(lock, actions);
  }

 private:
  // A request slot: what is read into it, and the reply it turns into.
  struct Job {
    enum class Kind { kFrame, kReply } kind = Kind::kFrame;
    v1::StreamRequest request;
    v1::StreamReply reply;
    // The CloudReply last used by this job, kept out of `reply` between frames so that its
    // draco buffer keeps its capacity (a oneof member is freed when the oneof is cleared).
    std::unique_ptr<v1::CloudReply> spare_cloud;
    std::shared_ptr<const StreamSettings> settings;
    std::uint64_t order = 0;            // position among this stream's replies
    Clock::time_point received;         // for the queue and total latencies
    std::int64_t received_unix_ns = 0;  // echoed as receive_time_unix_ns
  };

  struct Actions {
    Job* write = nullptr;
    Job* read = nullptr;
    bool cancel = false;
    bool finish = false;
    grpc::Status status;
  };

  ~StreamReactor() override = default;

  // Hands the decided calls to gRPC. `lock` holds mu_ and is released here.
  void Perform(std::unique_lock<std::mutex>& lock, Actions& a) {
    if (a.write == nullptr && a.read == nullptr && !a.cancel && !a.finish) {
      lock.unlock();
      return;
    }
    std::lock_guard<std::mutex> ops(ops_mu_);
    lock.unlock();
    if (a.write != nullptr) StartWrite(&a.write->reply);
    if (a.read != nullptr) StartRead(&a.read->request);
    if (a.cancel) context_->TryCancel();
    if (a.finish) Finish(std::move(a.status));
  }

  Job* Acquire() {
    if (free_.empty()) {
      jobs_.push_back(std::make_unique<Job>());
      return jobs_.back().get();
    }
    Job* job = free_.back();
    free_.pop_back();
    return job;
  }

  // Frees the request's pixels now (so a free slot costs no memory) and keeps the reply's cloud
  // buffer for the next frame.
  void Release(Job* job) {
    job->request.Clear();
    if (job->reply.has_cloud()) job->spare_cloud.reset(job->reply.release_cloud());
    job->reply.Clear();
    job->settings.reset();
    free_.push_back(job);
  }

  // A message arrived: a config takes effect at once; a frame or an error reply joins pending_.
  void Accept(Job* job) {
    switch (job->request.kind_case()) {
      case v1::StreamRequest::kConfig: {
        auto settings = ResolveStreamConfig(job->request.config(), service_->options_);
        if (settings.ok()) {
          settings_ = std::make_shared<const StreamSettings>(*std::move(settings));
          spdlog::debug("stream from {}: new config, delivery {}", peer_,
                        Name(settings_->delivery));
          Release(job);
          return;
        }
        // The previous config stays; the client hears why in order with its frames.
        QueueError(job, 0, "", v1::ERROR_KIND_CONFIG, settings.status());
        return;
      }
      case v1::StreamRequest::kFrame: {
        job->kind = Job::Kind::kFrame;
        job->settings = settings_;
        job->received = last_activity_;
        job->received_unix_ns = UnixNanos();
        if (settings_->delivery == Delivery::kLatest) DropWaitingLatestFrames();
        pending_.push_back(job);
        ++held_;
        service_->NoteQueued(held_);
        return;
      }
      default:
        QueueError(job, 0, "", v1::ERROR_KIND_REQUEST,
                   absl::InvalidArgumentError(
                       "request: a StreamRequest must hold a config or a frame; it held neither"));
        return;
    }
  }

  void QueueError(Job* job, std::uint64_t sequence, const std::string& frame_id,
                  v1::ErrorKind kind, const absl::Status& status) {
    LogFrameError(peer_, status);
    service_->metrics_->FrameErrors(status.code()).Increment();
    job->request.Clear();
    job->kind = Job::Kind::kReply;
    v1::FrameError* error = job->reply.mutable_error();
    error->set_sequence(sequence);
    error->set_frame_id(frame_id);
    error->set_code(static_cast<int>(status.code()));
    error->set_message(std::string(status.message()));
    error->set_kind(kind);
    error->set_server_instance(service_->instance_);
    pending_.push_back(job);
    ++held_;
    service_->NoteQueued(held_);
  }

  // DELIVERY_LATEST: the frame that just arrived replaces the ones still waiting.
  void DropWaitingLatestFrames() {
    for (auto it = pending_.begin(); it != pending_.end();) {
      Job* j = *it;
      if (j->kind == Job::Kind::kFrame && j->settings->delivery == Delivery::kLatest) {
        it = pending_.erase(it);
        --held_;
        ++dropped_;
        service_->metrics_->frames_dropped.Increment();
        Release(j);
      } else {
        ++it;
      }
    }
  }

  void DropPending() {
    for (Job* j : pending_) {
      --held_;
      Release(j);
    }
    pending_.clear();
  }

  bool CanDispatch(const Job& job) const {
    if (job.settings->delivery == Delivery::kAll) return true;
    // DELIVERY_LATEST: one frame in work, and none started while a finished reply waits for the
    // writer (a slow reader then gets drops rather than a growing backlog).
    return in_work_ == 0 && completed_waiting_ == 0;
  }

  bool CanRead() const {
    const std::uint32_t limit = service_->options_.max_queued_frames;
    if (settings_->delivery == Delivery::kAll) return held_ < limit;
    // DELIVERY_LATEST keeps reading so that the newest frame is the one waiting; a waiting frame
    // will be replaced, so it does not count. Error replies and unwritten clouds do, so that a
    // client that sends bad configs and reads nothing cannot grow the queue.
    std::uint32_t replaceable = 0;
    for (const Job* j : pending_) {
      if (j->kind == Job::Kind::kFrame && j->settings->delivery == Delivery::kLatest) ++replaceable;
    }
    return held_ - replaceable < std::max<std::uint32_t>(limit, 3);
  }

  // Decides what to do next; the caller performs it (Perform).
  void PumpLocked(Actions* a) {
    // A reply that is ready goes out first: in DELIVERY_LATEST the next frame may start only
    // once no finished reply waits, so processing it then overlaps this write.
    TryWriteLocked(a);
    DispatchLocked();
    TryWriteLocked(a);  // an error reply queued behind the frames may be next
    // End the call when its time has come (never with a write outstanding).
    if (!finish_sent_ && writing_ == nullptr) {
      const bool all_answered = in_work_ == 0 && pending_.empty() && reorder_.empty();
      if (cancelled_ || write_failed_) {
        a->status = grpc::Status(grpc::StatusCode::CANCELLED, "stream cancelled");
        a->finish = true;
      } else if (end_requested_) {
        a->status = end_status_;
        a->finish = true;
      } else if (all_answered && read_closed_) {
        a->status = grpc::Status::OK;
        a->finish = true;
      } else if (all_answered && draining_) {
        a->status = grpc::Status(grpc::StatusCode::UNAVAILABLE,
                                 "the server is shutting down; frames received before were "
                                 "answered");
        a->finish = true;
      }
      if (a->finish) finish_sent_ = true;
    }
    // Read the next message when there is room for it.
    if (reading_ == nullptr && !finish_sent_ && !read_closed_ && !draining_ && !cancelled_ &&
        !write_failed_ && !end_requested_ && !cancel_requested_ && CanRead()) {
      reading_ = Acquire();
      a->read = reading_;
    }
  }

  // Starts what can start, in arrival order: error replies take their place in the reply order
  // at once, frames go to the worker pool.
  void DispatchLocked() {
    while (!pending_.empty() && !cancelled_ && !write_failed_) {
      Job* job = pending_.front();
      if (job->kind == Job::Kind::kReply) {
        pending_.pop_front();
        job->order = next_order_++;
        reorder_.push_back(job);
        ++completed_waiting_;
        continue;
      }
      if (!CanDispatch(*job)) break;
      pending_.pop_front();
      job->order = next_order_++;
      reorder_.push_back(nullptr);  // its slot, filled when the worker is done
      ++in_work_;
      Ref();
      const bool submitted =
          service_->pool_.Submit([this, job](std::size_t worker) { Work(job, worker); });
      if (!submitted) {
        // The pool is stopping: the server is past its grace period.
        --in_work_;
        Unref();  // never the last reference: gRPC still holds one
        reorder_.pop_back();
        --next_order_;
        --held_;
        Release(job);
        cancelled_ = true;
      }
    }
  }

  // Hands the next reply in order to the writer, if it is done and no write is outstanding.
  void TryWriteLocked(Actions* a) {
    if (writing_ != nullptr || finish_sent_ || cancelled_ || write_failed_ || reorder_.empty() ||
        reorder_.front() == nullptr) {
      return;
    }
    Job* job = reorder_.front();
    reorder_.pop_front();
    --completed_waiting_;
    ++next_write_order_;
    writing_ = job;
    const std::int64_t now_ns = UnixNanos();
    if (job->reply.has_cloud()) {
      v1::CloudReply* cloud = job->reply.mutable_cloud();
      cloud->set_frames_dropped(dropped_);
      cloud->set_send_time_unix_ns(now_ns);
      service_->metrics_->total_seconds.Observe(Seconds(Clock::now() - job->received));
    } else {
      job->reply.mutable_error()->set_frames_dropped(dropped_);
    }
    service_->metrics_->bytes_sent.Increment(static_cast<double>(job->reply.ByteSizeLong()));
    a->write = job;
  }

  // On a worker thread; this job holds a reference to the reactor.
  void Work(Job* job, std::size_t worker) {
    const Clock::time_point start = Clock::now();
    Metrics& metrics = *service_->metrics_;
    metrics.queue_seconds.Observe(Seconds(start - job->received));
    bool skip;
    {
      std::lock_guard<std::mutex> lock(mu_);
      skip = cancelled_ || write_failed_ || finish_sent_;
    }
    if (!skip) {
      const double cpu0 = ThreadCpuSeconds();
      v1::CloudReply* cloud = job->spare_cloud ? job->spare_cloud.release() : new v1::CloudReply;
      cloud->Clear();  // keeps the draco buffer's capacity
      job->reply.set_allocated_cloud(cloud);
      FrameCosts costs;
      const v1::Frame& frame = job->request.frame();
      const absl::Status status =
          service_->processors_[worker]->Process(frame, *job->settings, cloud, &costs);
      if (status.ok()) {
        cloud->mutable_times()->set_queue_us(Micros(start - job->received));
        cloud->set_receive_time_unix_ns(job->received_unix_ns);
        cloud->set_server_instance(service_->instance_);
        metrics.frames_processed.Increment();
        metrics.pipeline_seconds.Observe(costs.pipeline_seconds);
        metrics.encode_seconds.Observe(costs.encode_seconds);
        if (costs.decoded) metrics.decode_seconds.Observe(costs.decode_seconds);
      } else {
        const std::uint64_t sequence = frame.sequence();
        const std::string frame_id = frame.frame_id();
        job->spare_cloud.reset(job->reply.release_cloud());
        LogFrameError(peer_, status);
        metrics.FrameErrors(status.code()).Increment();
        v1::FrameError* error = job->reply.mutable_error();
        error->set_sequence(sequence);
        error->set_frame_id(frame_id);
        error->set_code(static_cast<int>(status.code()));
        error->set_message(std::string(status.message()));
        error->set_kind(v1::ERROR_KIND_FRAME);
        error->set_server_instance(service_->instance_);
      }
      metrics.core_cpu_seconds.Increment(costs.core_cpu_seconds);
      // The pixels are no longer needed; free them before the reply waits for the writer.
      job->request.Clear();
      metrics.worker_cpu_seconds.Increment(ThreadCpuSeconds() - cpu0);
    }
    {
      std::unique_lock<std::mutex> lock(mu_);
      --in_work_;
      last_activity_ = Clock::now();
      if (cancelled_ || write_failed_ || finish_sent_ || skip) {
        // Nobody will write it; its reorder slot is dropped with the call.
        --held_;
        reorder_[job->order - next_write_order_] = nullptr;
        Release(job);
        DropUnwritableSlots();
      } else {
        reorder_[job->order - next_write_order_] = job;
        ++completed_waiting_;
      }
      Actions actions;
      PumpLocked(&actions);
      Perform(lock, actions);
    }
    Unref();  // last: may delete this
  }

  // Once the call cannot be written to, the slots of finished jobs are cleared; when nothing is
  // in work any more the reorder buffer is emptied so that the finish condition holds.
  void DropUnwritableSlots() {
    if (in_work_ > 0) return;
    for (Job* j : reorder_) {
      if (j != nullptr) {
        --held_;
        Release(j);
      }
    }
    reorder_.clear();
    completed_waiting_ = 0;
  }

  CloudCastService* const service_;
  grpc::CallbackServerContext* const context_;
  const std::string peer_;
  std::atomic<int> refs_{1};

  std::mutex ops_mu_;  // see the class comment
  std::mutex mu_;
  std::vector<std::unique_ptr<Job>> jobs_;  // every slot this stream ever needed
  std::vector<Job*> free_;
  std::shared_ptr<const StreamSettings> settings_;
  std::deque<Job*> pending_;  // received, not started: frames, and error replies to keep in order
  std::deque<Job*> reorder_;  // [i] has order next_write_order_ + i; nullptr while in work
  std::uint64_t next_order_ = 0;
  std::uint64_t next_write_order_ = 0;
  Job* reading_ = nullptr;
  Job* writing_ = nullptr;
  int in_work_ = 0;
  int completed_waiting_ = 0;  // done, in reorder_, not yet being written
  std::uint32_t held_ = 0;     // pending + in work + done but not yet written (incl. writing)
  std::uint64_t dropped_ = 0;
  bool read_closed_ = false;
  bool draining_ = false;
  bool cancelled_ = false;
  bool write_failed_ = false;
  bool end_requested_ = false;
  bool cancel_requested_ = false;
  bool finish_sent_ = false;
  grpc::Status end_status_;
  Clock::time_point last_activity_;
};

// Ends a call at once: over the stream limit, or while shutting down.
class RejectedStream final : public grpc::ServerBidiReactor<v1::StreamRequest, v1::StreamReply> {
 public:
  explicit RejectedStream(grpc::Status status) { Finish(std::move(status)); }
  void OnDone() override { delete this; }
};

// ---------------------------------------------------------------------------------------------

CloudCastService::CloudCastService(const ServerOptions& options, Metrics* metrics)
    : options_(options),
      instance_(options.ResolvedInstance()),
      default_settings_(std::make_shared<const StreamSettings>(DefaultSettings(options))),
      metrics_(metrics),
      processors_([&] {
        std::vector<std::unique_ptr<FrameProcessor>> p;
        for (int i = 0; i < options.ResolvedThreads(); ++i) {
          p.push_back(std::make_unique<FrameProcessor>());
        }
        return p;
      }()),
      pool_(options.ResolvedThreads()) {
  housekeeping_ = std::thread([this] { Housekeeping(); });
}

CloudCastService::~CloudCastService() { StopWorkers(); }

grpc::ServerBidiReactor<v1::StreamRequest, v1::StreamReply>* CloudCastService::Stream(
    grpc::CallbackServerContext* context) {
  if (draining_.load()) {
    metrics_->streams_rejected_shutdown.Increment();
    return new RejectedStream(
        grpc::Status(grpc::StatusCode::UNAVAILABLE, "the server is shutting down"));
  }
  if (active_streams_.fetch_add(1) >= static_cast<int>(options_.max_streams)) {
    active_streams_.fetch_sub(1);
    metrics_->streams_rejected_limit.Increment();
    spdlog::warn("stream from {} refused: {} streams open, the limit", context->peer(),
                 options_.max_streams);
    return new RejectedStream(
        grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                     absl::StrCat("too many concurrent streams: the server's limit is ",
                                  options_.max_streams, " (max_streams, --max-streams)")));
  }
  metrics_->streams_accepted.Increment();
  metrics_->active_streams.Increment();
  return new StreamReactor(this, context);
}

grpc::ServerUnaryReactor* CloudCastService::Process(grpc::CallbackServerContext* context,
                                                    const v1::ProcessRequest* request,
                                                    v1::CloudReply* reply) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  const Clock::time_point received = Clock::now();
  const std::int64_t received_ns = UnixNanos();
  metrics_->bytes_received.Increment(static_cast<double>(request->ByteSizeLong()));
  if (draining_.load()) {
    reactor->Finish(grpc::Status(grpc::StatusCode::UNAVAILABLE, "the server is shutting down"));
    return reactor;
  }
  auto settings = ResolveStreamConfig(request->config(), options_);
  if (!settings.ok()) {
    metrics_->FrameErrors(settings.status().code()).Increment();
    reactor->Finish(ToGrpc(settings.status()));
    return reactor;
  }
  // Each call holds its frame until a worker is done with it; bound them like streams.
  if (active_process_calls_.fetch_add(1) >= static_cast<int>(options_.max_streams)) {
    active_process_calls_.fetch_sub(1);
    reactor->Finish(
        grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                     absl::StrCat("too many Process calls in flight: the server's limit is ",
                                  options_.max_streams, " (max_streams, --max-streams)")));
    return reactor;
  }
  auto shared_settings = std::make_shared<const StreamSettings>(*std::move(settings));
  const bool submitted = pool_.Submit(
      [this, reactor, request, reply, received, received_ns, shared_settings](std::size_t worker) {
        const Clock::time_point start = Clock::now();
        metrics_->queue_seconds.Observe(Seconds(start - received));
        const double cpu0 = ThreadCpuSeconds();
        FrameCosts costs;
        const absl::Status status =
            processors_[worker]->Process(request->frame(), *shared_settings, reply, &costs);
        metrics_->core_cpu_seconds.Increment(costs.core_cpu_seconds);
        grpc::Status result;
        if (status.ok()) {
          reply->mutable_times()->set_queue_us(Micros(start - received));
          reply->set_receive_time_unix_ns(received_ns);
          reply->set_send_time_unix_ns(UnixNanos());
          reply->set_server_instance(instance_);
          metrics_->frames_processed.Increment();
          metrics_->pipeline_seconds.Observe(costs.pipeline_seconds);
          metrics_->encode_seconds.Observe(costs.encode_seconds);
          if (costs.decoded) metrics_->decode_seconds.Observe(costs.decode_seconds);
          metrics_->total_seconds.Observe(Seconds(Clock::now() - received));
          metrics_->bytes_sent.Increment(static_cast<double>(reply->ByteSizeLong()));
        } else {
          metrics_->FrameErrors(status.code()).Increment();
          result = ToGrpc(status);
        }
        metrics_->worker_cpu_seconds.Increment(ThreadCpuSeconds() - cpu0);
        active_process_calls_.fetch_sub(1);
        reactor->Finish(std::move(result));
      });
  if (!submitted) {
    active_process_calls_.fetch_sub(1);
    reactor->Finish(grpc::Status(grpc::StatusCode::UNAVAILABLE, "the server is shutting down"));
  }
  return reactor;
}

grpc::ServerUnaryReactor* CloudCastService::GetInfo(grpc::CallbackServerContext* context,
                                                    const v1::GetInfoRequest* /*request*/,
                                                    v1::ServerInfo* info) {
  info->set_version(CLOUDCAST_VERSION);
  v1::ServerLimits* limits = info->mutable_limits();
  limits->set_max_message_bytes(options_.max_message_bytes);
  limits->set_max_side(options_.limits.max_side);
  limits->set_max_pixels(options_.limits.max_pixels);
  limits->set_max_streams(options_.max_streams);
  const auto idle_ms = options_.idle_timeout.count();
  limits->set_idle_timeout_seconds(static_cast<std::uint32_t>((idle_ms + 999) / 1000));
  limits->set_max_queued_frames(options_.max_queued_frames);
  *info->mutable_defaults() = DefaultStreamConfig(options_);
  for (auto e : {v1::DISPARITY_U8, v1::DISPARITY_U16, v1::DISPARITY_F32}) {
    info->add_disparity_encodings(e);
  }
  for (auto e : {v1::COLOR_BGR8, v1::COLOR_RGB8, v1::COLOR_RGBA8, v1::COLOR_MONO8}) {
    info->add_color_encodings(e);
  }
  // What core/image_io decodes through OpenCV's imgcodecs.
  for (const char* f : {"png", "jpeg", "tiff", "pnm", "pfm"}) info->add_image_formats(f);
  info->set_worker_threads(static_cast<std::uint32_t>(pool_.size()));
  info->set_draco_version(draco::kDracoVersion);
  info->set_instance(instance_);
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  reactor->Finish(grpc::Status::OK);
  return reactor;
}

void CloudCastService::NoteQueued(std::uint32_t held) {
  std::uint32_t seen = queued_high_water_.load(std::memory_order_relaxed);
  while (held > seen && !queued_high_water_.compare_exchange_weak(seen, held)) {
  }
}

void CloudCastService::Register(StreamReactor* stream) {
  std::lock_guard<std::mutex> lock(streams_mu_);
  streams_.insert(stream);
}

void CloudCastService::Unregister(StreamReactor* stream) {
  {
    std::lock_guard<std::mutex> lock(streams_mu_);
    streams_.erase(stream);
  }
  active_streams_.fetch_sub(1);
  metrics_->active_streams.Decrement();
  streams_cv_.notify_all();
}

void CloudCastService::StartDraining() {
  draining_.store(true);
  std::vector<StreamReactor*> streams;
  {
    std::lock_guard<std::mutex> lock(streams_mu_);
    for (StreamReactor* s : streams_) {
      s->Ref();
      streams.push_back(s);
    }
  }
  spdlog::info("draining {} open streams", streams.size());
  for (StreamReactor* s : streams) {
    s->BeginDrain();
    s->Unref();
  }
}

bool CloudCastService::WaitForStreams(Clock::time_point deadline) {
  std::unique_lock<std::mutex> lock(streams_mu_);
  return streams_cv_.wait_until(lock, deadline, [this] { return streams_.empty(); });
}

void CloudCastService::StopWorkers() {
  std::call_once(stop_once_, [this] {
    {
      std::lock_guard<std::mutex> lock(streams_mu_);
      stop_housekeeping_ = true;
    }
    streams_cv_.notify_all();
    if (housekeeping_.joinable()) housekeeping_.join();
    pool_.Stop();
  });
}

void CloudCastService::Housekeeping() {
  // Checks often enough that a stream ends within about a tenth of the timeout of going idle.
  const auto tick = std::clamp<std::chrono::milliseconds>(
      options_.idle_timeout / 10, std::chrono::milliseconds(10), std::chrono::milliseconds(1000));
  std::unique_lock<std::mutex> lock(streams_mu_);
  while (!stop_housekeeping_) {
    streams_cv_.wait_for(lock, tick, [this] { return stop_housekeeping_; });
    if (stop_housekeeping_) break;
    std::vector<StreamReactor*> streams;
    for (StreamReactor* s : streams_) {
      s->Ref();
      streams.push_back(s);
    }
    lock.unlock();
    const Clock::time_point now = Clock::now();
    for (StreamReactor* s : streams) {
      s->CheckIdle(now);
      s->Unref();
    }
    lock.lock();
  }
}

}  // namespace cloudcast::server
