#include "service.h"

#include <malloc.h>

#include <algorithm>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>
#include <utility>

#include "absl/strings/str_cat.h"
#include "call_helpers.h"
#include "draco/core/draco_version.h"
#include "spdlog/spdlog.h"
#include "request_reader.h"
#include "stream_queue.h"

#ifndef CLOUDCAST_VERSION
#define CLOUDCAST_VERSION "unknown"
#endif

namespace cloudcast::server {
// ---------------------------------------------------------------------------------------------
// One Stream call: gRPC's op sequencing around the stream's StreamQueue.
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
    : public grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer> {
 public:
  StreamReactor(CloudCastService* service, grpc::CallbackServerContext* context,
                AdmittedCall call)
      : service_(service),
        ticket_(std::move(call.ticket)),
        context_(context),
        caller_(std::move(call.caller)),
        peer_(caller_.label),
        client_key_(caller_.fair_key),
        call_key_(call.call_key),
        settings_(caller_.defaults),
        queue_(service->options_.max_queued_frames),
        last_activity_(Clock::now()),
        last_frame_(last_activity_) {
    service_->call_log_.Log(spdlog::level::info, "stream from {} opened ({} active)", peer_,
                            service_->active_streams());
    service_->Register(this);
    std::unique_lock<std::mutex> lock(mu_);
    if (service_->draining()) closing_ = Draining();
    Pump(lock);
  }

  void OnReadDone(bool ok) override {
    Job* job;
    {
      std::lock_guard<std::mutex> lock(mu_);
      job = reading_;
    }
    // Parsed outside the lock: a frame is a megabyte or more.
    std::size_t bytes = 0;
    bool parsed = false;
    if (ok) {
      bytes = job->in.Length();
      parsed = job->reader.Parse(&job->in, &job->request);
      job->in.Clear();  // the reader keeps the slices that hold the pixels
    }
    std::unique_lock<std::mutex> lock(mu_);
    reading_ = nullptr;
    last_activity_ = Clock::now();
    if (ok) got_message_ = true;
    if (!ok) {
      read_open_ = false;  // the client closed its side, or the call is gone
      Release(job);
    } else if (finished_ || broken_ || closing_) {
      Release(job);  // read after the stream began to close: not answered
    } else if (!parsed) {
      // The stream cannot be trusted past bytes it cannot parse: answer what it holds, then end.
      service_->metrics_->stream_requests_unparsable.Increment();
      spdlog::debug("stream from {}: {} bytes do not parse as a StreamRequest", peer_, bytes);
      closing_ = Unparsable("StreamRequest", bytes);
      Release(job);
    } else {
      service_->metrics_->bytes_received.Increment(static_cast<double>(bytes));
      Accept(job, bytes);
    }
    Pump(lock);
  }

  void OnWriteDone(bool ok) override {
    std::unique_lock<std::mutex> lock(mu_);
    Job* job = writing_;
    writing_ = nullptr;
    last_activity_ = Clock::now();
    queue_.Written();
    Release(job);
    if (!ok) Break();  // cancelled, or the client went away
    Pump(lock);
  }

  void OnCancel() override {
    service_->metrics_->streams_cancelled.Increment();
    std::unique_lock<std::mutex> lock(mu_);
    Break();
    Pump(lock);
  }

  void OnDone() override {
    {
      std::lock_guard<std::mutex> lock(mu_);
      service_->call_log_.Log(spdlog::level::info, "stream from {} done: {} replies, {} dropped",
                              peer_, queue_.written(), queue_.dropped());
      ticket_.Release();  // already released where Finish was decided, unless none was
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
    if (finished_ || ending_ || broken_ || queue_.in_work() > 0) return;
    const ServerOptions& o = service_->options_;
    // A stream that has sent nothing at all gets a shorter time: it holds a slot for nothing.
    const bool silent = !got_message_ && o.first_message_timeout < o.idle_timeout;
    const auto timeout = silent ? o.first_message_timeout : o.idle_timeout;
    if (now - last_activity_ < timeout) return;
    const double seconds = Seconds(timeout);
    spdlog::info("stream from {} {} for {} s: ending it", peer_, silent ? "sent nothing" : "idle",
                 seconds);
    service_->metrics_->streams_idle_timeout.Increment();
    ending_ =
        grpc::Status(grpc::StatusCode::DEADLINE_EXCEEDED,
                     silent ? absl::StrCat("stream idle: it sent nothing within ", seconds,
                                           " s of opening (the server's --first-message-timeout)")
                            : absl::StrCat("stream idle: nothing received or sent for ", seconds,
                                           " s (the server's idle timeout, --idle-timeout)"));
    // A Finish must wait for an outstanding write, which a client that takes nothing never
    // completes: cancel the call instead.
    Pump(lock, /*cancel=*/writing_ != nullptr);
  }

  // Stops reading; the frames already held are answered, then the stream ends (UNAVAILABLE).
  void BeginDrain() {
    std::unique_lock<std::mutex> lock(mu_);
    if (!closing_) closing_ = Draining();
    Pump(lock);
  }

  // How long the stream has sent no frame, when it holds none either and is not ending: a
  // stream the server may shed to make room for a new client.
  std::optional<Clock::duration> QuietFor(Clock::time_point now) {
    std::lock_guard<std::mutex> lock(mu_);
    if (finished_ || ending_ || broken_ || closing_ || !queue_.Empty()) return std::nullopt;
    return now - last_frame_;
  }
  const std::string& client() const { return caller_.client.key; }

  // Ends the stream with `status` to free its place; false when it is ending already.
  bool Shed(grpc::Status status) {
    std::unique_lock<std::mutex> lock(mu_);
    if (finished_ || ending_ || broken_) return false;
    ending_ = std::move(status);
    Pump(lock, /*cancel=*/writing_ != nullptr);
    return true;
  }

 private:
  // A request slot: what is read into it, and the reply it turns into.
  struct Job : StreamSlot {
    grpc::ByteBuffer in;   // what gRPC read, until parsed into `request`
    grpc::ByteBuffer out;  // `reply` serialized, while gRPC writes it
    RequestReader reader;  // parses `in`; holds the raw pixels in gRPC's slices until processed
    v1::StreamRequest request;
    v1::StreamReply reply;
    // The CloudReply last used by this job, kept out of `reply` between frames so that its
    // draco buffer keeps its capacity (a oneof member is freed when the oneof is cleared).
    std::unique_ptr<v1::CloudReply> spare_cloud;
    std::shared_ptr<const StreamSettings> settings;
    Arrival arrival;
    FrameCharge charge;  // its memory in the server's budget, and its cost to the worker pool
  };

  // The calls decided under mu_, made by Pump after it is released.
  struct Ops {
    Job* write = nullptr;
    Job* read = nullptr;
    bool cancel = false;
    std::optional<grpc::Status> finish;
  };

  ~StreamReactor() override = default;

  static grpc::Status Draining() {
    return grpc::Status(grpc::StatusCode::UNAVAILABLE,
                        "the server is shutting down; frames received before were answered");
  }

  // Decides what can happen next and hands it to gRPC. `lock` holds mu_ and is released here.
  void Pump(std::unique_lock<std::mutex>& lock, bool cancel = false) {
    Ops ops;
    ops.cancel = cancel;
    // A reply that is ready goes out first: in DELIVERY_LATEST the next frame may start only
    // once no finished reply waits, so processing it then overlaps this write.
    StartWriteIfReady(&ops);
    Dispatch();
    StartWriteIfReady(&ops);  // an error reply queued behind the frames may be next
    // End the call when its time has come (never with a write outstanding).
    if (!finished_ && writing_ == nullptr) {
      if (broken_) {
        ops.finish = grpc::Status(grpc::StatusCode::CANCELLED, "stream cancelled");
      } else if (ending_) {
        ops.finish = *ending_;
      } else if (queue_.Empty() && closing_) {
        ops.finish = *closing_;
      } else if (queue_.Empty() && !read_open_) {
        ops.finish = grpc::Status::OK;
      }
      if (ops.finish) {
        finished_ = true;
        // The stream's place is free once its end is decided: a client that has its status and
        // opens the next stream at once must not be refused for this one (OnDone, where the
        // ticket went before, may run after the client already holds the status). A stream the
        // client cancelled keeps its place until gRPC is done with it (OnDone): nobody waits for
        // its status, and a client that resets streams as fast as it opens them (rapid reset)
        // must not have more of them alive than its share.
        if (!broken_) ticket_.Release();
      }
    }
    // Read the next message when there is room for it.
    if (reading_ == nullptr && !finished_ && read_open_ && !closing_ && !broken_ && !ending_ &&
        queue_.CanRead(settings_->delivery)) {
      reading_ = Acquire();
      ops.read = reading_;
    }
    if (ops.write == nullptr && ops.read == nullptr && !ops.cancel && !ops.finish) {
      lock.unlock();
      return;
    }
    std::lock_guard<std::mutex> order(ops_mu_);
    lock.unlock();
    if (ops.write != nullptr) StartWrite(&ops.write->out);
    if (ops.read != nullptr) StartRead(&ops.read->in);
    if (ops.cancel) context_->TryCancel();
    if (ops.finish) Finish(*std::move(ops.finish));
  }

  // The call can no longer be written to: everything it holds is let go.
  void Break() {
    if (broken_) return;
    broken_ = true;
    std::vector<StreamSlot*> released;
    queue_.Abandon(&released);
    for (StreamSlot* s : released) Release(static_cast<Job*>(s));
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
    job->charge.Release();
    job->in.Clear();
    job->out.Clear();
    job->reader.Clear();
    job->request.Clear();
    if (job->reply.has_cloud()) job->spare_cloud.reset(job->reply.release_cloud());
    job->reply.Clear();
    job->settings.reset();
    free_.push_back(job);
  }

  // A message arrived: a config takes effect at once; a frame or an error reply joins the queue.
  void Accept(Job* job, std::size_t bytes) {
    switch (job->request.kind_case()) {
      case v1::StreamRequest::kConfig: {
        auto settings = convert::Resolve(job->request.config(), *caller_.defaults);
        if (settings.ok()) {
          settings_ = std::make_shared<const StreamSettings>(*std::move(settings));
          spdlog::debug("stream from {}: new config, delivery {}", peer_,
                        convert::Name(settings_->delivery));
          Release(job);
          return;
        }
        // The previous config stays; the client hears why in order with its frames.
        QueueError(job, v1::ERROR_KIND_CONFIG, settings.status());
        return;
      }
      case v1::StreamRequest::kFrame: {
        last_frame_ = last_activity_;
        const v1::Frame& frame = job->request.frame();
        auto charge =
            service_->admitter_.AdmitFrame(caller_, frame, bytes, settings_->frame.stereo);
        if (!charge.ok()) {
          // Answered in order with the stream's other frames; the stream goes on.
          const std::uint64_t sequence = frame.sequence();
          const std::string frame_id = frame.frame_id();
          job->request.Clear();
          FillError(charge.status(), v1::ERROR_KIND_FRAME, sequence, frame_id,
                    job->reply.mutable_error());
          queue_.PushReply(job);
          service_->NoteQueued(queue_.held());
          return;
        }
        job->charge = *std::move(charge);
        job->settings = settings_;
        job->delivery = settings_->delivery;
        job->arrival = {last_activity_, UnixNanos()};
        std::vector<StreamSlot*> dropped;
        queue_.PushFrame(job, &dropped);
        for (StreamSlot* s : dropped) {
          service_->metrics_->frames_dropped.Increment();
          Release(static_cast<Job*>(s));
        }
        service_->NoteQueued(queue_.held());
        return;
      }
      default:
        QueueError(job, v1::ERROR_KIND_REQUEST,
                   absl::InvalidArgumentError(
                       "request: a StreamRequest must hold a config or a frame; it held neither"));
        return;
    }
  }

  // An error reply for a request that needs no work, in order with the frame replies.
  void QueueError(Job* job, v1::ErrorKind kind, const absl::Status& status) {
    job->request.Clear();
    FillError(status, kind, 0, "", job->reply.mutable_error());
    queue_.PushReply(job);
    service_->NoteQueued(queue_.held());
  }

  // Fills a FrameError (it is the client's error, not the server's: logged at debug level only,
  // so that a misbehaving client cannot flood the log) and counts it.
  void FillError(const absl::Status& status, v1::ErrorKind kind, std::uint64_t sequence,
                 const std::string& frame_id, v1::FrameError* error) {
    spdlog::debug("frame error from {}: {}", peer_, status.ToString());
    service_->metrics_->FrameErrors(status.code()).Increment();
    convert::FillError(status, kind, sequence, frame_id, error);
    error->set_server_instance(service_->runner_.instance());
  }

  // Hands the frames that may start to the worker pool.
  void Dispatch() {
    while (StreamSlot* slot = queue_.NextToProcess()) {
      Job* job = static_cast<Job*>(slot);
      Ref();
      // Fair between clients (weighted by pixels) and between the streams of one; the frame's
      // work memory waits for room in the pool's.
      if (!service_->pool_.Submit([this, job](std::size_t worker) { Work(job, worker); },
                                  client_key_, call_key_, job->charge.pixels(),
                                  job->charge.work_bytes())) {
        // The pool is stopping: the server is past its grace period.
        queue_.Processed(job);
        Release(job);
        Break();
        Unref();  // never the last reference: gRPC still holds one
        return;
      }
    }
  }

  // Hands the next reply in order to the writer, if it is done and no write is outstanding.
  void StartWriteIfReady(Ops* ops) {
    if (writing_ != nullptr || finished_) return;
    Job* job = static_cast<Job*>(queue_.NextToWrite());
    if (job == nullptr) return;
    writing_ = job;
    if (job->reply.has_cloud()) {
      v1::CloudReply* cloud = job->reply.mutable_cloud();
      cloud->set_frames_dropped(queue_.dropped());
      cloud->set_send_time_unix_ns(UnixNanos());
      service_->metrics_->total_seconds.Observe(Seconds(Clock::now() - job->arrival.time));
    } else {
      job->reply.mutable_error()->set_frames_dropped(queue_.dropped());
    }
    // Serialized here rather than by gRPC, so the reactor owns its bytes (the stream is raw).
    Serialize(job->reply, &job->out);
    service_->metrics_->bytes_sent.Increment(static_cast<double>(job->out.Length()));
    ops->write = job;
  }

  // On a worker thread; this job holds a reference to the reactor.
  void Work(Job* job, std::size_t worker) {
    bool skip;
    {
      std::lock_guard<std::mutex> lock(mu_);
      skip = queue_.abandoned();
    }
    if (!skip) {
      v1::CloudReply* cloud = job->spare_cloud ? job->spare_cloud.release() : new v1::CloudReply;
      cloud->Clear();  // keeps the draco buffer's capacity
      job->reply.set_allocated_cloud(cloud);
      const v1::Frame& frame = job->request.frame();
      const absl::Status status = service_->runner_.Run(worker, frame, &job->reader.pixels(),
                                                        job->settings->frame, job->arrival, cloud);
      if (!status.ok()) {
        const std::uint64_t sequence = frame.sequence();
        const std::string frame_id = frame.frame_id();
        job->spare_cloud.reset(job->reply.release_cloud());
        spdlog::debug("frame error from {}: {}", peer_, status.ToString());
        convert::FillError(status, v1::ERROR_KIND_FRAME, sequence, frame_id,
                           job->reply.mutable_error());
        job->reply.mutable_error()->set_server_instance(service_->runner_.instance());
      }
      // The pixels are no longer needed; free them before the reply waits for the writer.
      job->request.Clear();
      job->reader.Clear();
    }
    job->charge.Release();  // atomic: no lock needed
    {
      std::unique_lock<std::mutex> lock(mu_);
      last_activity_ = Clock::now();
      if (!queue_.Processed(job)) Release(job);  // nobody will write it
      Pump(lock);
    }
    Unref();  // last: may delete this
  }

  CloudCastService* const service_;
  Admission::Ticket ticket_;  // this stream's place among the server's and its client's
  grpc::CallbackServerContext* const context_;
  const Caller caller_;
  const std::string peer_;          // with the tenant, for logs
  const std::uint64_t client_key_;  // the client, for the worker pool's fairness
  const std::uint64_t call_key_;
  std::atomic<int> refs_{1};

  std::mutex ops_mu_;  // see the class comment
  std::mutex mu_;
  std::vector<std::unique_ptr<Job>> jobs_;  // every slot this stream ever needed
  std::vector<Job*> free_;
  std::shared_ptr<const StreamSettings> settings_;
  StreamQueue queue_;
  Job* reading_ = nullptr;
  Job* writing_ = nullptr;
  bool read_open_ = true;  // false once the client half-closed (or the read side failed)
  // Reading has stopped for good: answer what is held, then end with this status (the server
  // drains, or the client sent bytes that do not parse).
  std::optional<grpc::Status> closing_;
  bool broken_ = false;                 // cancelled or a write failed: nothing more is written
  std::optional<grpc::Status> ending_;  // the server ends the call (idle) with this status
  bool finished_ = false;               // Finish has been called
  bool got_message_ = false;            // any message read (for --first-message-timeout)
  Clock::time_point last_activity_;
  Clock::time_point last_frame_;  // the last frame read, or the opening (for shedding)
};

// Ends a call at once: over the stream limit, or while shutting down.
class RejectedStream final : public grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer> {
 public:
  explicit RejectedStream(grpc::Status status) { Finish(std::move(status)); }
  void OnDone() override { delete this; }
};

// ---------------------------------------------------------------------------------------------

CloudCastService::CloudCastService(const ServerOptions& options, Metrics* metrics)
    : options_(options),
      default_settings_(std::make_shared<const StreamSettings>(options.StreamDefaults())),
      metrics_(metrics),
      call_log_(options.log_calls_per_second, &metrics->log_lines_suppressed),
      admitter_(options_, default_settings_, metrics, &call_log_),
      runner_(options.ResolvedThreads(), metrics, options.ResolvedInstance(),
              options.large_frame_pixels),
      pool_(options.ResolvedThreads(),
            WorkerPool::Limits{options.work_memory_bytes, options.large_frame_pixels}) {
  housekeeping_ = std::thread([this] { Housekeeping(); });
}

CloudCastService::~CloudCastService() { StopWorkers(); }

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* CloudCastService::Stream(
    grpc::CallbackServerContext* context) {
  auto call = admitter_.AdmitCall(Admission::Kind::kStream, context, [this](const Caller& c) {
    return ShedQuietStream(c);
  });
  if (!call.ok()) return new RejectedStream(ToGrpc(call.status()));
  metrics_->streams_accepted.Increment();
  metrics_->active_streams.Increment();
  return new StreamReactor(this, context, *std::move(call));
}

grpc::ServerUnaryReactor* CloudCastService::Process(grpc::CallbackServerContext* context,
                                                    const grpc::ByteBuffer* request_bytes,
                                                    grpc::ByteBuffer* reply_bytes) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  const Arrival arrival{Clock::now(), UnixNanos()};
  auto admitted = admitter_.AdmitCall(Admission::Kind::kProcess, context);
  if (!admitted.ok()) {
    reactor->Finish(ToGrpc(admitted.status()));
    return reactor;
  }
  // The request and its reply live until the worker is done with them.
  struct Call {
    RequestReader reader;  // holds the raw pixels in gRPC's slices until the worker is done
    v1::ProcessRequest request;
    v1::CloudReply reply;
    std::shared_ptr<const StreamSettings> settings;
    Admission::Ticket ticket;
    FrameCharge charge;
  };
  auto call = std::make_shared<Call>();
  call->ticket = std::move(admitted->ticket);
  // The place goes before the status: a client that has it may call again at once.
  auto finish = [&](grpc::Status status) {
    call->ticket.Release();
    reactor->Finish(std::move(status));
    return reactor;
  };
  const std::size_t bytes = request_bytes->Length();
  grpc::ByteBuffer copy(*request_bytes);  // shares the slices
  if (!call->reader.Parse(&copy, &call->request)) {
    metrics_->process_requests_unparsable.Increment();
    return finish(Unparsable("ProcessRequest", bytes));
  }
  metrics_->bytes_received.Increment(static_cast<double>(bytes));
  // Resolved before the frame is weighed, as a stream's config is: a stereo pair's matcher
  // memory depends on its settings.
  auto settings = convert::Resolve(call->request.config(), *admitted->caller.defaults);
  if (!settings.ok()) {
    metrics_->FrameErrors(settings.status().code()).Increment();
    return finish(ToGrpc(settings.status()));
  }
  call->settings = std::make_shared<const StreamSettings>(*std::move(settings));
  bool for_memory = false;
  auto charge = admitter_.AdmitFrame(admitted->caller, call->request.frame(), bytes,
                                     call->settings->frame.stereo, &for_memory);
  if (!charge.ok()) {
    metrics_->FrameErrors(charge.status().code()).Increment();
    if (!for_memory) return finish(ToGrpc(charge.status()));
    RefuseLater(reactor, std::make_shared<Admission::Ticket>(std::move(call->ticket)),
                ToGrpc(charge.status()));
    return reactor;
  }
  call->charge = *std::move(charge);
  active_process_calls_.fetch_add(1);
  const bool submitted = pool_.Submit(
      [this, reactor, reply_bytes, arrival, call](std::size_t worker) {
        const absl::Status status =
            runner_.Run(worker, call->request.frame(), &call->reader.pixels(),
                        call->settings->frame, arrival, &call->reply);
        call->reader.Clear();
        call->charge.Release();
        grpc::Status result;
        if (status.ok()) {
          call->reply.set_send_time_unix_ns(UnixNanos());
          metrics_->total_seconds.Observe(Seconds(Clock::now() - arrival.time));
          Serialize(call->reply, reply_bytes);
          metrics_->bytes_sent.Increment(static_cast<double>(reply_bytes->Length()));
        } else {
          result = ToGrpc(status);
        }
        call->ticket.Release();
        reactor->Finish(std::move(result));
        ProcessCallDone();
      },
      admitted->caller.fair_key, admitted->call_key, call->charge.pixels(),
      call->charge.work_bytes());
  if (!submitted) {
    finish(grpc::Status(grpc::StatusCode::UNAVAILABLE, "the server is shutting down"));
    ProcessCallDone();
  }
  return reactor;
}

grpc::ServerUnaryReactor* CloudCastService::GetInfo(grpc::CallbackServerContext* context,
                                                    const v1::GetInfoRequest* /*request*/,
                                                    v1::ServerInfo* info) {
  if (auto caller = admitter_.Identify(context); !caller.ok()) {
    grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
    reactor->Finish(ToGrpc(caller.status()));
    return reactor;
  }
  info->set_version(CLOUDCAST_VERSION);
  v1::ServerLimits* limits = info->mutable_limits();
  limits->set_max_message_bytes(options_.max_message_bytes);
  limits->set_max_side(options_.limits.max_side);
  limits->set_max_pixels(options_.limits.max_pixels);
  limits->set_max_streams(options_.max_streams);
  const auto idle_ms = options_.idle_timeout.count();
  limits->set_idle_timeout_seconds(static_cast<std::uint32_t>((idle_ms + 999) / 1000));
  limits->set_max_queued_frames(options_.max_queued_frames);
  limits->set_work_memory_bytes(options_.work_memory_bytes);
  limits->set_work_bytes_per_pixel(static_cast<std::uint32_t>(kWorkBytesPerPixel));
  limits->set_max_streams_per_client(options_.ResolvedMaxStreamsPerClient());
  limits->set_max_process_per_client(options_.ResolvedMaxProcessPerClient());
  limits->set_shed_quiet_after_ms(static_cast<std::uint32_t>(options_.shed_quiet_after.count()));
  limits->set_max_stereo_volume(options_.limits.max_stereo_volume);
  *info->mutable_defaults() = convert::ToProto(*default_settings_);
  // Every encoding the core reads.
  for (auto e : {DisparityEncoding::kU8, DisparityEncoding::kU16, DisparityEncoding::kF32}) {
    info->add_disparity_encodings(convert::ToProto(e));
  }
  for (auto e :
       {ColorEncoding::kBGR8, ColorEncoding::kRGB8, ColorEncoding::kRGBA8, ColorEncoding::kMono8}) {
    info->add_color_encodings(convert::ToProto(e));
  }
  // What core/image_io decodes through OpenCV's imgcodecs.
  for (const char* f : {"png", "jpeg", "tiff", "pnm", "pfm"}) info->add_image_formats(f);
  for (v1::Compression c : convert::AcceptedCompressions()) info->add_compressions(c);
  for (auto e : {DepthEncoding::kU16, DepthEncoding::kF32}) {
    info->add_depth_encodings(convert::ToProto(e));
  }
  for (StereoMatcher m : AllStereoMatchers()) info->add_stereo_matchers(convert::ToProto(m));
  info->set_worker_threads(static_cast<std::uint32_t>(pool_.size()));
  info->set_draco_version(draco::kDracoVersion);
  info->set_instance(runner_.instance());
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  reactor->Finish(grpc::Status::OK);
  return reactor;
}

void CloudCastService::SetTenants(std::shared_ptr<const TenantDirectory> tenants) {
  admitter_.SetTenants(std::move(tenants));
}

bool CloudCastService::ShedQuietStream(const Caller& newcomer) {
  if (options_.shed_quiet_after.count() == 0) return false;
  std::vector<StreamReactor*> streams;
  {
    std::lock_guard<std::mutex> lock(streams_mu_);
    for (StreamReactor* s : streams_) {
      s->Ref();
      streams.push_back(s);
    }
  }
  // The quiet streams of each client (never the newcomer's own).
  const Clock::time_point now = Clock::now();
  std::unordered_map<std::string, int> per_client;
  struct Quiet {
    StreamReactor* stream;
    Clock::duration quiet;
  };
  std::vector<Quiet> quiet;
  for (StreamReactor* s : streams) {
    if (s->client() == newcomer.client.key) continue;
    ++per_client[s->client()];
    if (auto q = s->QuietFor(now); q && *q >= options_.shed_quiet_after) quiet.push_back({s, *q});
  }
  // The client holding the most streams gives first, its quietest stream first.
  std::sort(quiet.begin(), quiet.end(), [&](const Quiet& a, const Quiet& b) {
    const int na = per_client[a.stream->client()], nb = per_client[b.stream->client()];
    return na != nb ? na > nb : a.quiet > b.quiet;
  });
  bool shed = false;
  for (const Quiet& q : quiet) {
    const double s = Seconds(q.quiet);
    if (q.stream->Shed(grpc::Status(
            grpc::StatusCode::UNAVAILABLE,
            absl::StrCat("the server is full (--max-streams ", options_.max_streams,
                         ") and this stream sent no frame for ", static_cast<int>(s),
                         " s: ended to make room for another client (--shed-quiet-after)")))) {
      metrics_->streams_shed.Increment();
      call_log_.Log(spdlog::level::info, "stream of {} shed after {} s without a frame, for {}",
                    q.stream->client(), s, newcomer.label);
      shed = true;
      break;
    }
  }
  for (StreamReactor* s : streams) s->Unref();
  return shed;
}

void CloudCastService::RefuseLater(grpc::ServerUnaryReactor* reactor,
                                   std::shared_ptr<Admission::Ticket> ticket,
                                   grpc::Status status) {
  if (options_.refusal_delay.count() == 0 || admitter_.draining()) {
    ticket->Release();
    reactor->Finish(std::move(status));
    return;
  }
  active_process_calls_.fetch_add(1);
  delayed_.RunAt(Clock::now() + options_.refusal_delay, [this, reactor, ticket, status] {
    ticket->Release();
    reactor->Finish(status);
    ProcessCallDone();
  });
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
  metrics_->active_streams.Decrement();
  streams_cv_.notify_all();
}

void CloudCastService::StartDraining() {
  admitter_.StartDraining();
  delayed_.Flush();  // refusals waiting out their delay are answered now
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

bool CloudCastService::WaitForCalls(Clock::time_point deadline) {
  std::unique_lock<std::mutex> lock(streams_mu_);
  return streams_cv_.wait_until(
      lock, deadline, [this] { return streams_.empty() && active_process_calls_.load() == 0; });
}

void CloudCastService::ProcessCallDone() {
  active_process_calls_.fetch_sub(1);
  // Taken so that a waiter cannot miss the wake-up between its check and its wait.
  std::lock_guard<std::mutex> lock(streams_mu_);
  streams_cv_.notify_all();
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
  // Checks often enough that a stream ends within about a tenth of its timeout.
  const auto tick = std::clamp<std::chrono::milliseconds>(
      std::min(options_.idle_timeout, options_.first_message_timeout) / 10,
      std::chrono::milliseconds(10), std::chrono::milliseconds(1000));
  bool trimmed = true;
  std::size_t free_at_trim = 0;
  int idle_ticks = 0;
  bool scratch_released = true;  // nothing to give back before the first frame
  std::unique_lock<std::mutex> lock(streams_mu_);
  while (!stop_housekeeping_) {
    streams_cv_.wait_for(lock, tick, [this] { return stop_housekeeping_; });
    if (stop_housekeeping_) break;
    std::vector<StreamReactor*> streams;
    for (StreamReactor* s : streams_) {
      s->Ref();
      streams.push_back(s);
    }
    const bool idle = streams.empty() && active_process_calls_.load() == 0;
    lock.unlock();
    // Once a burst is over, give the allocator's free pages back to the OS: frame buffers stay
    // on the heap (main.cc), and glibc keeps freed pages in its arenas. Idle is no call open, but
    // a departed stream's buffers may still be freed after that (its connection's transport
    // buffers go with the connection), so while idle it trims again whenever the arenas' free
    // bytes have grown by a megabyte since the last trim. Trimming does not shrink that figure
    // (the pages stay on the free lists, only unmapped), so an idle server trims once and rests.
    // A server idle for a second gives its workers' scratch back first: after a burst of big
    // frames (each at most --large-frame-pixels keeps its scratch) it would stay resident.
    if (idle && ++idle_ticks * tick >= std::chrono::seconds(1) && !scratch_released) {
      runner_.ReleaseIdleScratch();
      scratch_released = true;
      trimmed = false;
    }
    if (!idle) {
      idle_ticks = 0;
      scratch_released = false;
    }
    if (idle) {
      const std::size_t free_bytes = mallinfo2().fordblks;
      if (!trimmed || free_bytes > free_at_trim + (std::size_t{1} << 20)) {
        malloc_trim(0);
        free_at_trim = free_bytes;
      }
    }
    trimmed = idle;
    const Clock::time_point now = Clock::now();
    for (StreamReactor* s : streams) {
      s->CheckIdle(now);
      s->Unref();
    }
    lock.lock();
  }
}

}  // namespace cloudcast::server
