#include "service.h"

#include <algorithm>
#include <string>
#include <utility>

#include "call_helpers.h"
#include "draco/core/draco_version.h"
#include "memory_housekeeping.h"
#include "request_reader.h"
#include "video_input.h"
#include "spdlog/spdlog.h"

#ifndef CLOUDCAST_VERSION
#define CLOUDCAST_VERSION "unknown"
#endif

namespace cloudcast::server {
namespace {

// Ends a call at once: refused at admission.
class RejectedStream final : public grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer> {
 public:
  explicit RejectedStream(grpc::Status status) { Finish(std::move(status)); }
  void OnDone() override { delete this; }
};

}  // namespace

CloudCastService::CloudCastService(const ServerOptions& options, Metrics* metrics)
    : options_(options),
      default_settings_(std::make_shared<const StreamSettings>(options.StreamDefaults())),
      metrics_(metrics),
      call_log_(options.log_calls_per_second, &metrics->log_lines_suppressed),
      admitter_(options_, default_settings_, metrics, &call_log_),
      runner_(options.ResolvedThreads(), metrics, options.ResolvedInstance(),
              options.large_frame_pixels),
      pool_(options.ResolvedThreads(),
            WorkerPool::Limits{options.work_memory_bytes, options.large_frame_pixels}),
      stream_services_{&options_, metrics_,  &admitter_, &runner_,
                       &pool_,    &streams_, &call_log_, &calls_changed_},
      process_reads_(options.ResolvedReadingBytesPerClient()),
      process_service_(ProcessCallServices{
          &admitter_, &process_reads_, options.max_message_bytes,
          [this](ProcessCall* call, AdmittedCall admitted, const grpc::ByteBuffer& request,
                 Arrival arrival) {
            ServeProcess(call, std::move(admitted), request, arrival);
          }}) {
  housekeeping_ = std::thread([this] { Housekeeping(); });
}

CloudCastService::~CloudCastService() { StopWorkers(); }

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* CloudCastService::Stream(
    grpc::CallbackServerContext* context) {
  auto call = admitter_.AdmitCall(Admission::Kind::kStream, context, [this](const Caller& c) {
    return streams_.ShedQuietest(c, options_.shed_quiet_after, options_.max_streams, metrics_,
                                 &call_log_);
  });
  if (!call.ok()) return new RejectedStream(ToGrpc(call.status()));
  return new StreamReactor(stream_services_, context, *std::move(call));
}

void CloudCastService::ServeProcess(ProcessCall* process, AdmittedCall admitted,
                                    const grpc::ByteBuffer& request_bytes, Arrival arrival) {
  // The request and its reply live until the worker is done with them.
  struct Call {
    RequestReader reader;  // holds the raw pixels in gRPC's slices until the worker is done
    v1::ProcessRequest request;
    v1::CloudReply reply;
    std::shared_ptr<const StreamSettings> settings;
    Admission::Ticket ticket;
    FrameCharge charge;
    DecodedVideo video;  // a frame of video pictures: one IDR each (a stream of one frame)
  };
  auto call = std::make_shared<Call>();
  call->ticket = std::move(admitted.ticket);
  // The place goes before the status: a client that has it may call again at once.
  auto fail = [&](grpc::Status status) {
    call->ticket.Release();
    process->Fail(std::move(status));
  };
  const std::size_t bytes = request_bytes.Length();
  grpc::ByteBuffer copy(request_bytes);  // shares the slices
  if (!call->reader.Parse(&copy, &call->request)) {
    metrics_->process_requests_unparsable.Increment();
    return fail(Unparsable("ProcessRequest", bytes));
  }
  metrics_->bytes_received.Increment(static_cast<double>(bytes));
  // Resolved before the frame is weighed, as a stream's config is: a stereo pair's matcher
  // memory depends on its settings.
  auto settings = convert::Resolve(call->request.config(), *admitted.caller.defaults);
  if (!settings.ok()) {
    metrics_->FrameErrors(settings.status().code()).Increment();
    return fail(RequestError(settings.status(), "config"));
  }
  call->settings = std::make_shared<const StreamSettings>(*std::move(settings));
  bool for_memory = false;
  auto charge = admitter_.AdmitFrame(admitted.caller, call->request.frame(), bytes,
                                     call->settings->frame.stereo, &for_memory);
  if (!charge.ok()) {
    metrics_->FrameErrors(charge.status().code()).Increment();
    if (!for_memory) return fail(RequestError(charge.status(), "frame"));
    RefuseLater(process, std::make_shared<Admission::Ticket>(std::move(call->ticket)),
                RequestError(charge.status(), "frame"));
    return;
  }
  call->charge = *std::move(charge);
  ProcessStarted();
  const bool submitted = pool_.Submit(
      [this, process, arrival, call](std::size_t worker) {
        const v1::Frame& frame = call->request.frame();
        absl::Status status;
        const bool video = VideoDecoders::HasVideo(frame);
        if (video) {
          // Decoders for this call alone, their memory charged as a stream's and given back
          // when they go (at the end of this block).
          VideoDecoders decoders(
              call->settings->frame.pipeline.limits,
              [this](std::uint64_t bytes) { return admitter_.ChargeVideoDecoder(bytes); },
              [this](std::uint64_t bytes) { admitter_.ReleaseVideoDecoder(bytes); });
          status = decoders.Decode(frame, &call->video);
          if (!status.ok()) metrics_->FrameErrors(status.code()).Increment();
        }
        if (status.ok()) {
          status = runner_.Run(worker, frame, &call->reader.pixels(), call->settings->frame,
                               arrival, &call->reply, video ? &call->video : nullptr);
        }
        call->video = DecodedVideo{};
        call->reader.Clear();
        call->charge.Release();
        call->ticket.Release();
        if (status.ok()) {
          call->reply.set_send_time_unix_ns(UnixNanos());
          metrics_->total_seconds.Observe(Seconds(Clock::now() - arrival.time));
          metrics_->bytes_sent.Increment(static_cast<double>(process->Reply(call->reply)));
        } else {
          process->Fail(RequestError(status, "frame"));
        }
        ProcessDone();
      },
      admitted.caller.fair_key, admitted.call_key, call->charge.pixels(),
      call->charge.work_bytes());
  if (!submitted) {
    fail(grpc::Status(grpc::StatusCode::UNAVAILABLE, "the server is shutting down"));
    ProcessDone();
  }
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
  info->set_contract_revision(convert::kContractRevision);
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
  for (v1::VideoCodec c : DecodedVideoCodecs()) info->add_video_codecs(c);
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

void CloudCastService::RefuseLater(ProcessCall* call, std::shared_ptr<Admission::Ticket> ticket,
                                   grpc::Status status) {
  if (options_.refusal_delay.count() == 0 || admitter_.draining()) {
    ticket->Release();
    call->Fail(std::move(status));
    return;
  }
  ProcessStarted();
  delayed_.RunAt(Clock::now() + options_.refusal_delay, [this, call, ticket, status] {
    ticket->Release();
    call->Fail(status);
    ProcessDone();
  });
}

void CloudCastService::StartDraining(std::chrono::milliseconds read_wait) {
  admitter_.StartDraining();
  delayed_.Flush();  // refusals waiting out their delay are answered now
  {
    const OpenStreams::Snapshot streams = streams_.Take();
    spdlog::info("draining {} open streams", streams.size());
    for (StreamReactor* s : streams) s->BeginDrain();
  }
  // The housekeeping thread ends the wait for the reads started.
  {
    std::lock_guard<std::mutex> lock(housekeeping_mu_);
    drain_reads_until_ = Clock::now() + read_wait;
  }
  housekeeping_cv_.notify_all();
}

bool CloudCastService::WaitForCalls(Clock::time_point deadline) {
  return calls_changed_.WaitUntil(deadline, [this] {
    if (process_calls_.load() > 0) return false;
    const OpenStreams::Snapshot streams = streams_.Take();
    return std::all_of(streams.begin(), streams.end(),
                       [](StreamReactor* s) { return s->Settled(); });
  });
}

std::pair<int, int> CloudCastService::CallsInFlight() {
  const OpenStreams::Snapshot streams = streams_.Take();
  const auto unsettled =
      std::count_if(streams.begin(), streams.end(), [](StreamReactor* s) { return !s->Settled(); });
  return {static_cast<int>(unsettled), process_calls_.load()};
}

void CloudCastService::ProcessStarted() {
  process_calls_.fetch_add(1);
  streams_.ProcessStarted();
}

void CloudCastService::ProcessDone() {
  process_calls_.fetch_sub(1);
  streams_.ProcessDone();
  calls_changed_.Notify();
}

void CloudCastService::StopWorkers() {
  std::call_once(stop_once_, [this] {
    {
      std::lock_guard<std::mutex> lock(housekeeping_mu_);
      stop_housekeeping_ = true;
    }
    housekeeping_cv_.notify_all();
    if (housekeeping_.joinable()) housekeeping_.join();
    pool_.Stop();
  });
}

void CloudCastService::Housekeeping() {
  // Checks often enough that a stream ends within about a tenth of its timeout.
  const auto tick = std::clamp<std::chrono::milliseconds>(
      std::min(options_.idle_timeout, options_.first_message_timeout) / 10,
      std::chrono::milliseconds(10), std::chrono::milliseconds(1000));
  MemoryHousekeeping memory([this] { runner_.ReleaseIdleScratch(); });
  std::unique_lock<std::mutex> lock(housekeeping_mu_);
  Clock::time_point next_tick = Clock::now() + tick;
  while (!stop_housekeeping_) {
    const Clock::time_point now = Clock::now();
    if (drain_reads_until_ && now >= *drain_reads_until_) {
      // The drain waits no longer for the reads its streams had started.
      drain_reads_until_.reset();
      lock.unlock();
      {
        const OpenStreams::Snapshot streams = streams_.Take();
        for (StreamReactor* s : streams) s->StopAwaitingRead();
      }
      lock.lock();
      continue;
    }
    if (now >= next_tick) {
      next_tick = now + tick;
      lock.unlock();
      {
        const bool idle = streams_.idle();
        const OpenStreams::Snapshot streams = streams_.Take();
        memory.Tick(idle, tick);
        for (StreamReactor* s : streams) s->CheckIdle(now);
      }
      lock.lock();
      continue;
    }
    // Woken early to stop, and when a drain begins.
    housekeeping_cv_.wait_until(
        lock, drain_reads_until_ ? std::min(next_tick, *drain_reads_until_) : next_tick);
  }
}

}  // namespace cloudcast::server
