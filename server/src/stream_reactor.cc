#include "stream_reactor.h"

#include <algorithm>
#include <utility>

#include "absl/strings/str_cat.h"
#include "call_helpers.h"
#include "request_reader.h"
#include "spdlog/spdlog.h"

namespace cloudcast::server {
namespace {

// The bitstreams that need an IDR, as they stood after this frame's pictures, on its reply.
template <typename Reply>
void SetKeyframeNeeded(const DecodedVideo& video, Reply* reply) {
  reply->clear_keyframe_needed();
  for (v1::VideoBitstream b : video.keyframe_needed) reply->add_keyframe_needed(b);
}

grpc::Status Draining() {
  return grpc::Status(grpc::StatusCode::UNAVAILABLE,
                      "the server is shutting down; frames received before were answered");
}

}  // namespace

// A request slot: what is read into it, and the reply it turns into.
struct StreamReactor::Job : StreamSlot {
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
  // Its video pictures, decoded when it was read (video_input.h), and how that went.
  DecodedVideo video;
  absl::Status video_status;
};

// The calls decided under mu_, made by Pump after it is released.
struct StreamReactor::Ops {
  Job* write = nullptr;
  Job* read = nullptr;
  bool cancel = false;
  std::optional<grpc::Status> finish;
};

StreamReactor::StreamReactor(const StreamServices& services, grpc::CallbackServerContext* context,
                             AdmittedCall call)
    : services_(services),
      ticket_(std::move(call.ticket)),
      context_(context),
      caller_(std::move(call.caller)),
      call_key_(call.call_key),
      settings_(caller_.defaults),
      queue_(services.options->max_queued_frames),
      last_activity_(Clock::now()),
      last_frame_(last_activity_) {
  services_.metrics->streams_accepted.Increment();
  services_.metrics->active_streams.Increment();
  services_.log->Log(spdlog::level::info, "stream from {} opened ({} active)", caller_.label,
                     services_.admitter->open(Admission::Kind::kStream));
  services_.streams->Add(this);
  std::unique_lock<std::mutex> lock(mu_);
  // After Add: a drain that began since admission either sees this stream or is seen here.
  if (services_.admitter->draining()) lifecycle_.Close(Draining());
  Pump(lock);
}

StreamReactor::~StreamReactor() = default;

void StreamReactor::OnReadDone(bool ok) {
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
    if (parsed) DecodeVideo(job);
  }
  std::unique_lock<std::mutex> lock(mu_);
  reading_ = nullptr;
  last_activity_ = Clock::now();
  if (ok) ++messages_read_;
  if (!ok) {
    lifecycle_.HalfClose();  // the client closed its side, or the call is gone
    Release(job);
  } else if (!lifecycle_.answers_read()) {
    Release(job);  // read after the stream began to end: not answered
  } else if (!parsed) {
    // The stream cannot be trusted past bytes it cannot parse: answer what it holds, then end.
    services_.metrics->stream_requests_unparsable.Increment();
    spdlog::debug("stream from {}: {} bytes do not parse as a StreamRequest", caller_.label,
                  bytes);
    lifecycle_.Close(Unparsable("StreamRequest", bytes));
    Release(job);
  } else {
    services_.metrics->bytes_received.Increment(static_cast<double>(bytes));
    bytes_received_ += bytes;
    Accept(job, bytes);
  }
  Pump(lock);
}

void StreamReactor::OnWriteDone(bool ok) {
  std::unique_lock<std::mutex> lock(mu_);
  Job* job = writing_;
  writing_ = nullptr;
  last_activity_ = Clock::now();
  queue_.Written();
  Release(job);
  if (!ok) Break();  // cancelled, or the client went away
  Pump(lock);
  if (!ok) Abandon();
}

void StreamReactor::OnCancel() {
  // Every member is read under mu_, the first thing each reaction takes: gRPC orders a
  // reaction after the constructor, but through its own (uninstrumented) locks, so only mu_
  // shows TSan that order (it reported a member read here as a race with the constructor).
  std::unique_lock<std::mutex> lock(mu_);
  services_.metrics->streams_cancelled.Increment();
  Break();
  Pump(lock);
  Abandon();
}

void StreamReactor::OnDone() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    services_.log->Log(spdlog::level::info, "stream from {} done: {} replies, {} dropped",
                       caller_.label, queue_.written(), queue_.dropped());
    ticket_.Release();  // already released where Finish was decided, unless none was
  }
  services_.streams->Remove(this);
  services_.metrics->active_streams.Decrement();
  services_.calls_changed->Notify();
  Unref();
}

bool StreamReactor::Settled() {
  if (abandoned()) return true;
  std::lock_guard<std::mutex> lock(mu_);
  return lifecycle_.finished() && messages_read_ == 0;
}

void StreamReactor::Abandon() {
  abandoned_.store(true, std::memory_order_release);
  services_.calls_changed->Notify();
}

void StreamReactor::CheckIdle(Clock::time_point now) {
  std::unique_lock<std::mutex> lock(mu_);
  if (!lifecycle_.may_end() || queue_.in_work() > 0) return;
  const ServerOptions& o = *services_.options;
  // A stream that has sent nothing at all gets a shorter time: it holds a slot for nothing.
  const bool silent = messages_read_ == 0 && o.first_message_timeout < o.idle_timeout;
  const auto timeout = silent ? o.first_message_timeout : o.idle_timeout;
  if (now - last_activity_ < timeout) return;
  const double seconds = Seconds(timeout);
  spdlog::info("stream from {} {} for {} s: ending it", caller_.label,
               silent ? "sent nothing" : "idle", seconds);
  services_.metrics->streams_idle_timeout.Increment();
  lifecycle_.End(grpc::Status(
      grpc::StatusCode::DEADLINE_EXCEEDED,
      silent ? absl::StrCat("stream idle: it sent nothing within ", seconds,
                            " s of opening (the server's --first-message-timeout)")
             : absl::StrCat("stream idle: nothing received or sent for ", seconds,
                            " s (the server's idle timeout, --idle-timeout)")));
  // A Finish must wait for an outstanding write, which a client that takes nothing never
  // completes: cancel the call instead.
  Pump(lock, /*cancel=*/writing_ != nullptr);
}

void StreamReactor::BeginDrain() {
  std::unique_lock<std::mutex> lock(mu_);
  lifecycle_.Drain(Draining());
  Pump(lock);
}

void StreamReactor::StopAwaitingRead() {
  std::unique_lock<std::mutex> lock(mu_);
  lifecycle_.StopAwaitingRead();
  Pump(lock);
}

std::optional<Clock::duration> StreamReactor::QuietFor(Clock::time_point now) {
  std::lock_guard<std::mutex> lock(mu_);
  if (!lifecycle_.sheddable() || !queue_.Empty()) return std::nullopt;
  return now - last_frame_;
}

bool StreamReactor::Shed(grpc::Status status) {
  std::unique_lock<std::mutex> lock(mu_);
  if (!lifecycle_.End(std::move(status))) return false;
  Pump(lock, /*cancel=*/writing_ != nullptr);
  return true;
}

void StreamReactor::Pump(std::unique_lock<std::mutex>& lock, bool cancel) {
  Ops ops;
  ops.cancel = cancel;
  // A reply that is ready goes out first: in DELIVERY_LATEST the next frame may start only
  // once no finished reply waits, so processing it then overlaps this write.
  StartWriteIfReady(&ops);
  Dispatch();
  StartWriteIfReady(&ops);  // an error reply queued behind the frames may be next
  // End the call when its time has come (never with a write outstanding).
  if (!lifecycle_.finished() && writing_ == nullptr) {
    bool cancelled = false;
    ops.finish =
        lifecycle_.Finish(queue_.Empty(), &cancelled, /*read_started=*/reading_ != nullptr);
    // The stream's place is free once its end is decided: a client that has its status and
    // opens the next stream at once must not be refused for this one (OnDone, where the ticket
    // went before, may run after the client already holds the status). A stream the client
    // cancelled keeps its place until gRPC is done with it (OnDone): nobody waits for its
    // status, and a client that resets streams as fast as it opens them (rapid reset) must not
    // have more of them alive than its share. gRPC may report a reset as a failed read before
    // it calls OnCancel, so a stream that ends having read nothing keeps its place too (a rapid
    // reset held 10,233 streams against --max-streams 64 so), and so does one gRPC already knows
    // is cancelled; a client that sent nothing waits for no status worth a place.
    if (ops.finish && !cancelled && messages_read_ > 0 && !context_->IsCancelled()) {
      ticket_.Release();
    }
  }
  // Read the next message when there is room for it.
  if (reading_ == nullptr && lifecycle_.reading() && queue_.CanRead(settings_->delivery)) {
    reading_ = Acquire();
    ops.read = reading_;
  }
  if (ops.write == nullptr && ops.read == nullptr && !ops.cancel && !ops.finish) {
    lock.unlock();
    return;
  }
  const bool settles = ops.finish && messages_read_ == 0;  // see Settled()
  {
    std::lock_guard<std::mutex> order(ops_mu_);
    lock.unlock();
    if (ops.write != nullptr) StartWrite(&ops.write->out);
    if (ops.read != nullptr) StartRead(&ops.read->in);
    if (ops.cancel) context_->TryCancel();
    if (ops.finish) Finish(*std::move(ops.finish));
  }
  if (settles) services_.calls_changed->Notify();  // without ops_mu_: Settled() takes mu_
}

// The call can no longer be written to: everything it holds is let go (also after Finish: a
// cancel may come then, and the frames in work must not be written or kept).
void StreamReactor::Break() {
  lifecycle_.Break();
  if (queue_.abandoned()) return;
  std::vector<StreamSlot*> released;
  queue_.Abandon(&released);
  for (StreamSlot* s : released) Release(static_cast<Job*>(s));
}

StreamReactor::Job* StreamReactor::Acquire() {
  if (free_.empty()) {
    jobs_.push_back(std::make_unique<Job>());
    return jobs_.back().get();
  }
  Job* job = free_.back();
  free_.pop_back();
  return job;
}

// A frame's video pictures are decoded as it is read, in the order they were sent, whatever
// becomes of the frame (replaced in DELIVERY_LATEST, refused for memory): the pictures after it
// reference them. Outside mu_: reads are one at a time, and only they touch video_.
void StreamReactor::DecodeVideo(Job* job) {
  job->video_status = absl::OkStatus();
  if (!job->request.has_frame() || !VideoDecoders::HasVideo(job->request.frame())) return;
  if (video_ == nullptr) {
    CallAdmitter* admitter = services_.admitter;
    video_ = std::make_unique<VideoDecoders>(
        caller_.defaults->frame.pipeline.limits,
        [admitter](std::uint64_t bytes) { return admitter->ChargeVideoDecoder(bytes); },
        [admitter](std::uint64_t bytes) { admitter->ReleaseVideoDecoder(bytes); });
  }
  // Its time counts in the frame's decode time (FrameRunner::Run), if the frame is processed.
  job->video_status = video_->Decode(job->request.frame(), &job->video);
}

// Frees the request's pixels now (so a free slot costs no memory) and keeps the reply's cloud
// buffer for the next frame.
void StreamReactor::Release(Job* job) {
  job->charge.Release();
  job->in.Clear();
  job->out.Clear();
  job->reader.Clear();
  job->request.Clear();
  if (job->reply.has_cloud()) job->spare_cloud.reset(job->reply.release_cloud());
  job->reply.Clear();
  job->settings.reset();
  job->video = DecodedVideo{};
  job->video_status = absl::OkStatus();
  free_.push_back(job);
}

// A message arrived: a config takes effect at once; a frame or an error reply joins the queue.
void StreamReactor::Accept(Job* job, std::size_t bytes) {
  switch (job->request.kind_case()) {
    case v1::StreamRequest::kConfig: {
      auto settings = convert::Resolve(job->request.config(), *caller_.defaults);
      if (!settings.ok()) {
        // The previous config stays; the client hears why in order with its frames.
        QueueError(job, v1::ERROR_KIND_CONFIG, settings.status());
        return;
      }
      settings_ = std::make_shared<const StreamSettings>(*std::move(settings));
      spdlog::debug("stream from {}: new config, delivery {}", caller_.label,
                    convert::Name(settings_->delivery));
      Release(job);
      return;
    }
    case v1::StreamRequest::kFrame:
      AcceptFrame(job, bytes);
      return;
    default:
      QueueError(job, v1::ERROR_KIND_REQUEST,
                 absl::InvalidArgumentError(
                     "request: a StreamRequest must hold a config or a frame; it held neither"));
      return;
  }
}

void StreamReactor::AcceptFrame(Job* job, std::size_t bytes) {
  last_frame_ = last_activity_;
  const v1::Frame& frame = job->request.frame();
  // A picture that did not decode answers its frame; its decoding was all the work it needed.
  absl::StatusOr<FrameCharge> charge =
      job->video_status.ok()
          ? services_.admitter->AdmitFrame(caller_, frame, bytes, settings_->frame.stereo)
          : absl::StatusOr<FrameCharge>(job->video_status);
  if (!charge.ok()) {
    // Answered in order with the stream's other frames; the stream goes on.
    const std::uint64_t sequence = frame.sequence();
    const std::string frame_id = frame.frame_id();
    job->request.Clear();
    FillError(charge.status(), v1::ERROR_KIND_FRAME, sequence, frame_id,
              job->reply.mutable_error());
    SetKeyframeNeeded(job->video, job->reply.mutable_error());
    job->video = DecodedVideo{};  // its pictures are not needed while the error waits
    queue_.PushReply(job);
    services_.streams->NoteQueued(queue_.held());
    return;
  }
  job->charge = *std::move(charge);
  job->settings = settings_;
  job->delivery = settings_->delivery;
  job->arrival = {last_activity_, UnixNanos(), bytes_received_};
  std::vector<StreamSlot*> dropped;
  queue_.PushFrame(job, &dropped);
  for (StreamSlot* s : dropped) {
    services_.metrics->frames_dropped.Increment();
    Release(static_cast<Job*>(s));
  }
  services_.streams->NoteQueued(queue_.held());
}

// An error reply for a request that needs no work, in order with the frame replies.
void StreamReactor::QueueError(Job* job, v1::ErrorKind kind, const absl::Status& status) {
  job->request.Clear();
  FillError(status, kind, 0, "", job->reply.mutable_error());
  queue_.PushReply(job);
  services_.streams->NoteQueued(queue_.held());
}

// Fills a FrameError (it is the client's error, not the server's: logged at debug level only,
// so that a misbehaving client cannot flood the log) and counts it.
void StreamReactor::FillError(const absl::Status& status, v1::ErrorKind kind,
                              std::uint64_t sequence, const std::string& frame_id,
                              v1::FrameError* error) {
  spdlog::debug("frame error from {}: {}", caller_.label, status.ToString());
  services_.metrics->FrameErrors(status.code()).Increment();
  convert::FillError(status, kind, sequence, frame_id, error);
  error->set_server_instance(services_.runner->instance());
}

// Hands the frames that may start to the worker pool.
void StreamReactor::Dispatch() {
  while (StreamSlot* slot = queue_.NextToProcess()) {
    Job* job = static_cast<Job*>(slot);
    Ref();
    // Fair between clients (weighted by pixels) and between the streams of one; the frame's
    // work memory waits for room in the pool's.
    if (!services_.pool->Submit([this, job](std::size_t worker) { Work(job, worker); },
                                caller_.fair_key, call_key_, job->charge.pixels(),
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
void StreamReactor::StartWriteIfReady(Ops* ops) {
  if (writing_ != nullptr || lifecycle_.finished()) return;
  Job* job = static_cast<Job*>(queue_.NextToWrite());
  if (job == nullptr) return;
  writing_ = job;
  if (job->reply.has_cloud()) {
    v1::CloudReply* cloud = job->reply.mutable_cloud();
    cloud->set_frames_dropped(queue_.dropped());
    cloud->set_send_time_unix_ns(UnixNanos());
    services_.metrics->total_seconds.Observe(Seconds(Clock::now() - job->arrival.time));
  } else {
    job->reply.mutable_error()->set_frames_dropped(queue_.dropped());
  }
  // Serialized here rather than by gRPC, so the reactor owns its bytes (the stream is raw).
  Serialize(job->reply, &job->out);
  services_.metrics->bytes_sent.Increment(static_cast<double>(job->out.Length()));
  ops->write = job;
}

// On a worker thread; this job holds a reference to the reactor.
void StreamReactor::Work(Job* job, std::size_t worker) {
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
    const bool video = VideoDecoders::HasVideo(frame);
    const absl::Status status =
        services_.runner->Run(worker, frame, &job->reader.pixels(), job->settings->frame,
                              job->arrival, cloud, video ? &job->video : nullptr);
    if (!status.ok()) {
      const std::uint64_t sequence = frame.sequence();
      const std::string frame_id = frame.frame_id();
      job->spare_cloud.reset(job->reply.release_cloud());
      spdlog::debug("frame error from {}: {}", caller_.label, status.ToString());
      convert::FillError(status, v1::ERROR_KIND_FRAME, sequence, frame_id,
                         job->reply.mutable_error());
      job->reply.mutable_error()->set_server_instance(services_.runner->instance());
      if (video) SetKeyframeNeeded(job->video, job->reply.mutable_error());
    } else if (video) {
      SetKeyframeNeeded(job->video, cloud);
    }
    // The pixels are no longer needed; free them before the reply waits for the writer.
    job->request.Clear();
    job->reader.Clear();
    job->video = DecodedVideo{};
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

}  // namespace cloudcast::server
