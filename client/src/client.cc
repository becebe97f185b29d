#include "cloudcast/client/client.h"

#include <grpcpp/grpcpp.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <climits>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "cloudcast/client/resend_ledger.h"
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

// How a resilient stream knows its call was lost rather than refused: UNAVAILABLE (the replica
// was killed, drained, sent GOAWAY, or cannot be reached), or CANCELLED when the stream itself
// did not cancel it (a server that stops while a call is opening cancels that call).
bool EndedByTheServerSide(const absl::Status& ended) {
  return ended.code() == absl::StatusCode::kUnavailable ||
         ended.code() == absl::StatusCode::kCancelled;
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

// What the stream keeps of a frame sent and not answered yet. `bytes` are kept only where a
// resilient stream may have to send it again (DELIVERY_ALL): they share the slices gRPC wrote, so
// keeping them copies nothing.
struct Pending {
  std::string frame_id;
  std::int64_t capture_time_unix_ns = 0;
  Clock::time_point send;
  std::int64_t send_unix_ns = 0;
  std::optional<grpc::ByteBuffer> bytes;
};

// Stream calls write bytes the client serialized itself (internal::RequestWriter) and read typed
// replies. The generated stub only writes StreamRequest messages, so the call is made as the
// generated code makes it, with ByteBuffer for the message type.
using StreamRpc = grpc::ClientReaderWriter<grpc::ByteBuffer, v1::StreamReply>;

const char* StreamMethodName() {
  static const std::string name = absl::StrCat("/", v1::CloudCast::service_full_name(), "/Stream");
  return name.c_str();
}

grpc::ByteBuffer Serialized(const google::protobuf::Message& message) {
  grpc::ByteBuffer bytes;
  bool own;
  (void)grpc::SerializationTraits<google::protobuf::Message>::Serialize(message, &bytes, &own);
  return bytes;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Stream
//
// Locks, always taken in this order: finish_mu, read_mu, write_mu, then pending_mu or call_mu
// (each held briefly). The reading side ends a call and opens the next one (a resilient
// reconnect) while it holds write_mu, so no Send writes meanwhile.

struct Stream::Impl {
  std::shared_ptr<grpc::Channel> channel;
  std::optional<grpc::internal::RpcMethod> stream_method;  // on `channel`
  std::string target;
  bool decode_clouds = true;
  bool wait_for_ready = false;
  StreamOptions options;

  // The current call; replaced on reconnect. Cancel() reaches it through call_mu from any thread.
  struct Call {
    grpc::ClientContext context;
    std::unique_ptr<StreamRpc> rpc;
  };
  std::mutex call_mu;
  std::unique_ptr<Call> call;
  bool cancelled = false;  // under call_mu

  // Writer side.
  std::timed_mutex write_mu;
  v1::StreamRequest config_request;  // the stream's config, sent again on each new call
  internal::RequestWriter frames;    // serializes each frame
  bool writes_closed = false;
  bool write_failed = false;  // the current call refused a write; the reader learns why
  std::uint64_t next_sequence = 0;
  std::atomic<std::uint64_t> frames_sent{0};
  std::atomic<std::uint64_t> image_bytes_sent{0};

  // Frames sent and not answered yet (resend_ledger.h: replies in send order, frames the server
  // skipped passed over, what a new call sends again).
  std::mutex pending_mu;
  ResendLedger<Pending> pending;

  // Reader side.
  std::mutex read_mu;
  v1::StreamReply reply;
  bool read_done = false;
  std::deque<Result> lost;  // frames given up on, handed out before the stream ends
  std::optional<Clock::time_point> failing_since;  // calls failing, no reply since
  std::uint64_t dropped_before = 0;                // drops on earlier calls of this stream
  std::uint64_t dropped_this_call = 0;
  std::string last_instance;
  std::thread receiver;
  std::atomic<int> reconnects{0};
  std::atomic<std::uint64_t> frames_resent{0};

  std::mutex finish_mu;
  bool finished = false;
  absl::Status final_status;

  std::string What() const { return absl::StrCat("stream to ", target); }

  absl::Status Ended() const {
    return absl::UnavailableError(
        absl::StrCat(What(), " has ended; Stream::Finish() returns the reason"));
  }

  // Frames are kept for a resend unless the stream says DELIVERY_LATEST (whose unanswered frames
  // would be dropped anyway). An unset delivery may be the server's DELIVERY_ALL.
  bool KeepsFrames() const {
    return options.resilient && config_request.config().delivery() != v1::DELIVERY_LATEST;
  }

  std::unique_ptr<Call> StartCall() {
    auto c = std::make_unique<Call>();
    // A new call after a failure waits for a replica to be ready (bounded by the caller).
    c->context.set_wait_for_ready(wait_for_ready || failing_since.has_value());
    c->rpc.reset(
        grpc::internal::ClientReaderWriterFactory<grpc::ByteBuffer, v1::StreamReply>::Create(
            channel.get(), *stream_method, &c->context));
    return c;
  }

  static bool WriteConfig(StreamRpc* rpc, const v1::StreamRequest& config) {
    return rpc->Write(Serialized(config));
  }

  // Books the reply to `sequence`: its send record, or that the reply is a duplicate.
  ResendLedger<Pending>::Reply TakePending(std::uint64_t sequence) {
    std::lock_guard<std::mutex> lock(pending_mu);
    return pending.Answer(sequence);
  }

  absl::Status Send(const FrameInput& input, const FrameMeta& meta) {
    std::lock_guard<std::timed_mutex> lock(write_mu);
    if (writes_closed) {
      return absl::FailedPreconditionError(
          absl::StrCat(What(), ": Send after CloseSend or Finish"));
    }
    const std::uint64_t sequence = meta.sequence.value_or(next_sequence);
    grpc::ByteBuffer bytes;
    if (absl::Status s = frames.Write(input, meta, sequence, &bytes); !s.ok()) {
      return s;
    }
    const std::uint64_t image_bytes = frames.image_bytes();
    {
      // Recorded before the write: the reply may arrive before Write returns.
      Pending p{meta.frame_id, frames.frame().capture_time_unix_ns(), Clock::now(), UnixNanosNow(),
                std::nullopt};
      const bool keep = KeepsFrames();
      if (keep) p.bytes = bytes;  // shares the slices
      std::lock_guard<std::mutex> plock(pending_mu);
      pending.Sent(sequence, std::move(p), keep);
    }
    next_sequence = sequence + 1;
    if (!write_failed && !call->rpc->Write(bytes)) write_failed = true;
    if (write_failed && !options.resilient) return Ended();
    // A resilient stream sends the frame again on its next call (or reports it lost).
    frames_sent.fetch_add(1, std::memory_order_relaxed);
    image_bytes_sent.fetch_add(image_bytes, std::memory_order_relaxed);
    return absl::OkStatus();
  }

  absl::Status Reconfigure(const StreamConfig& config) {
    std::lock_guard<std::timed_mutex> lock(write_mu);
    if (writes_closed) {
      return absl::FailedPreconditionError(absl::StrCat(What(), ": already closed by CloseSend"));
    }
    *config_request.mutable_config() = config;
    if (!write_failed && !WriteConfig(call->rpc.get(), config_request)) write_failed = true;
    return write_failed && !options.resilient ? Ended() : absl::OkStatus();
  }

  absl::Status CloseSend() {
    std::lock_guard<std::timed_mutex> lock(write_mu);
    if (writes_closed) return absl::OkStatus();
    writes_closed = true;
    if (write_failed) return absl::OkStatus();  // nothing to close; Finish reports why
    if (!call->rpc->WritesDone()) {
      write_failed = true;
      if (!options.resilient) return Ended();
    }
    return absl::OkStatus();
  }

  // The current call's reads have ended: takes write_mu from the writers. A Write blocked on an
  // ended call fails by itself once gRPC sees the end (trailers, RST_STREAM or a dead
  // connection); if one still holds on after a while, the call is cancelled, which would turn
  // an OK ending into CANCELLED, so it is the last resort.
  std::unique_lock<std::timed_mutex> TakeWriters() {
    std::unique_lock<std::timed_mutex> writers(write_mu, std::defer_lock);
    if (!writers.try_lock_for(std::chrono::seconds(2))) {
      {
        std::lock_guard<std::mutex> lock(call_mu);
        call->context.TryCancel();
      }
      writers.lock();
    }
    return writers;
  }

  // Opens a new call after `cause` ended the last one and sends it the config and (DELIVERY_ALL)
  // every unanswered frame. Holds write_mu. False once reconnect_timeout has passed since the
  // calls started failing, or on Cancel.
  bool Reconnect(const absl::Status& cause, Reconnect* event) {
    const Clock::time_point start = Clock::now();
    if (!failing_since) failing_since = start;
    const Clock::time_point give_up = *failing_since + options.reconnect_timeout;
    event->cause = cause;
    event->old_instance = last_instance;
    {
      // DELIVERY_LATEST frames are not sent again: the server would have dropped them anyway.
      std::lock_guard<std::mutex> lock(pending_mu);
      event->frames_dropped = pending.CallLost();
    }
    dropped_before += dropped_this_call + event->frames_dropped;
    dropped_this_call = 0;
    auto backoff = std::chrono::milliseconds(20);
    while (Clock::now() < give_up) {
      {
        std::lock_guard<std::mutex> lock(call_mu);
        if (cancelled) return false;
      }
      // Bounded waits, so that a Cancel or the deadline is noticed.
      const auto wait_until = std::min(give_up, Clock::now() + std::chrono::seconds(1));
      if (!channel->WaitForConnected(std::chrono::system_clock::now() +
                                     (wait_until - Clock::now()))) {
        continue;
      }
      std::unique_ptr<Call> next = StartCall();
      bool ok = next->rpc != nullptr && WriteConfig(next->rpc.get(), config_request);
      std::uint64_t resent = 0;
      {
        std::lock_guard<std::mutex> lock(pending_mu);
        while (ok) {
          const ResendLedger<Pending>::Entry* again = pending.NextResend();
          if (again == nullptr) break;
          ok = next->rpc->Write(*again->record.bytes);
          ++resent;
        }
        if (!ok) pending.CallLost();  // what this attempt resent goes again on the next
      }
      if (ok && writes_closed) ok = next->rpc->WritesDone();
      if (ok) {
        std::lock_guard<std::mutex> lock(call_mu);
        if (cancelled) next->context.TryCancel();
        call = std::move(next);
        write_failed = false;
        event->attempt = reconnects.fetch_add(1) + 1;
        event->frames_resent = resent;
        event->took =
            std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - *failing_since);
        frames_resent.fetch_add(resent);
        return true;
      }
      if (next->rpc != nullptr) next->rpc->Finish().IgnoreError();
      std::this_thread::sleep_until(std::min(give_up, Clock::now() + backoff));
      backoff = std::min<std::chrono::milliseconds>(backoff * 2, std::chrono::seconds(1));
    }
    return false;
  }

  // The stream is over: `why` is its final status. A resilient stream reports every frame still
  // unanswered as lost.
  void GiveUp(absl::Status why) {
    read_done = true;
    final_status = std::move(why);
    if (!options.resilient) return;
    std::lock_guard<std::mutex> lock(pending_mu);
    for (ResendLedger<Pending>::Entry& e : pending.TakeUnanswered()) {
      Result r;
      r.status = absl::UnavailableError(absl::StrCat(
          "frame ", e.sequence, " was sent but never answered: ", final_status.message()));
      r.sequence = e.sequence;
      r.frame_id = std::move(e.record.frame_id);
      r.capture_time_unix_ns = e.record.capture_time_unix_ns;
      r.times.send = e.record.send;
      r.times.send_unix_ns = e.record.send_unix_ns;
      r.frames_dropped = dropped_before + dropped_this_call;
      lost.push_back(std::move(r));
    }
  }

  // The next reply, or false once the stream has ended (its status then in final_status).
  bool ReadOne(Result* result, bool decode) {
    std::lock_guard<std::mutex> lock(read_mu);
    for (;;) {
      if (!lost.empty()) {
        *result = std::move(lost.front());
        lost.pop_front();
        return true;
      }
      if (read_done) return false;
      if (call->rpc->Read(&reply)) {
        failing_since.reset();
        if (!Fill(result, decode)) continue;  // a second answer to a resent frame
        return true;
      }
      std::unique_lock<std::timed_mutex> writers = TakeWriters();
      const absl::Status ended = FromGrpc(call->rpc->Finish(), What());
      bool is_cancelled;
      {
        std::lock_guard<std::mutex> c(call_mu);
        is_cancelled = cancelled;
      }
      if (options.resilient && !is_cancelled && EndedByTheServerSide(ended)) {
        ::cloudcast::client::Reconnect event;
        if (Reconnect(ended, &event)) {
          writers.unlock();
          if (options.on_reconnect) options.on_reconnect(event);
          continue;
        }
        GiveUp(absl::UnavailableError(absl::StrCat(
            What(), " lost its call (", ended.message(), ") and could not open a new one within ",
            options.reconnect_timeout.count(), " ms (StreamOptions::reconnect_timeout)")));
        continue;
      }
      GiveUp(ended);
    }
  }

  // Fills `result` from `reply`. False for a reply that answers a frame already answered (each
  // frame is answered once), which is not handed out.
  bool Fill(Result* result, bool decode) {
    result->times = ClientTimes{};
    result->times.receive = Clock::now();
    result->times.receive_unix_ns = UnixNanosNow();
    result->status = absl::OkStatus();
    result->config_rejected = false;
    bool answers_frame = true;
    std::uint64_t dropped = 0;
    switch (reply.kind_case()) {
      case v1::StreamReply::kCloud:
        // Swapped, not copied: the Draco bytes move into the result.
        result->reply.Swap(reply.mutable_cloud());
        result->sequence = result->reply.sequence();
        result->frame_id = result->reply.frame_id();
        result->capture_time_unix_ns = result->reply.capture_time_unix_ns();
        result->server_instance = result->reply.server_instance();
        dropped = result->reply.frames_dropped();
        break;
      case v1::StreamReply::kError: {
        const v1::FrameError& error = reply.error();
        result->status = convert::ToStatus(error);
        result->reply.Clear();
        result->sequence = error.sequence();
        result->frame_id = error.frame_id();
        result->capture_time_unix_ns = 0;
        result->server_instance = error.server_instance();
        dropped = error.frames_dropped();
        if (convert::AnswersNoFrame(error)) {
          answers_frame = false;
          result->config_rejected = error.kind() == v1::ERROR_KIND_CONFIG;
        }
        break;
      }
      case v1::StreamReply::KIND_NOT_SET:
        answers_frame = false;
        result->status = absl::InternalError(
            absl::StrCat(What(), ": the server sent a reply with neither a cloud nor an error"));
        result->reply.Clear();
        result->sequence = 0;
        result->frame_id.clear();
        result->capture_time_unix_ns = 0;
        result->server_instance.clear();
        break;
    }
    if (!result->server_instance.empty()) last_instance = result->server_instance;
    dropped_this_call = std::max(dropped_this_call, dropped);
    result->frames_dropped = dropped_before + dropped_this_call;
    if (answers_frame) {
      const ResendLedger<Pending>::Reply booked = TakePending(result->sequence);
      if (booked.match == ResendLedger<Pending>::Match::kDuplicate) return false;
      if (booked.entry) {
        const Pending& p = booked.entry->record;
        result->times.send = p.send;
        result->times.send_unix_ns = p.send_unix_ns;
        // FrameError does not echo the capture time; the client knows what it sent.
        if (result->capture_time_unix_ns == 0) {
          result->capture_time_unix_ns = p.capture_time_unix_ns;
        }
      }
    }
    if (result->status.ok()) {
      DecodeInto(decode, result);
    } else {
      result->cloud.ResizeUnorganized(0);
    }
    return true;
  }

  absl::Status Finish() {
    std::lock_guard<std::mutex> lock(finish_mu);
    if (finished) return final_status;
    CloseSend().IgnoreError();  // a dead call still finishes below, with its real status
    if (receiver.joinable()) {
      receiver.join();
    } else {
      // The call's status follows its last read: drain what nobody will read, undecoded.
      Result discard;
      while (ReadOne(&discard, /*decode=*/false)) {
      }
    }
    finished = true;
    return final_status;
  }

  void Cancel() {
    std::lock_guard<std::mutex> lock(call_mu);
    cancelled = true;
    if (call != nullptr) call->context.TryCancel();
  }
};

Stream::Stream(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

Stream::~Stream() {
  if (impl_ == nullptr) return;
  {
    std::lock_guard<std::mutex> lock(impl_->finish_mu);
    if (!impl_->finished) impl_->Cancel();
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
  return impl_->ReadOne(result, impl_->decode_clouds);
}

absl::Status Stream::CloseSend() { return impl_->CloseSend(); }

absl::Status Stream::Finish() { return impl_->Finish(); }

void Stream::Cancel() { impl_->Cancel(); }

std::uint64_t Stream::image_bytes_sent() const {
  return impl_->image_bytes_sent.load(std::memory_order_relaxed);
}

std::uint64_t Stream::frames_sent() const {
  return impl_->frames_sent.load(std::memory_order_relaxed);
}

int Stream::reconnects() const { return impl_->reconnects.load(); }

std::uint64_t Stream::frames_resent() const { return impl_->frames_resent.load(); }

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
  impl->channel = impl_->channel;
  impl->stream_method.emplace(StreamMethodName(), grpc::internal::RpcMethod::BIDI_STREAMING,
                              impl->channel);
  impl->target = impl_->target;
  impl->decode_clouds = impl_->options.decode_clouds;
  impl->wait_for_ready = impl_->options.wait_for_ready;
  impl->options = std::move(options);
  *impl->config_request.mutable_config() = config;
  impl->call = impl->StartCall();
  if (impl->call->rpc == nullptr) {
    return absl::InternalError(absl::StrCat("cannot start a stream to ", impl_->target));
  }
  if (!Stream::Impl::WriteConfig(impl->call->rpc.get(), impl->config_request)) {
    // The call is dead before it began; its status says why (e.g. UNAVAILABLE).
    absl::Status s = FromGrpc(impl->call->rpc->Finish(), impl->What());
    impl->finished = true;  // the destructor must not Finish twice
    impl->final_status = s;
    if (s.ok()) s = absl::UnavailableError(absl::StrCat(impl->What(), ": ended at once"));
    return s;
  }
  Stream::Impl* raw = impl.get();
  if (raw->options.on_result) {
    raw->receiver = std::thread([raw] {
      Result result;
      while (raw->ReadOne(&result, raw->decode_clouds)) raw->options.on_result(std::move(result));
    });
  }
  return std::unique_ptr<Stream>(new Stream(std::move(impl)));
}

const std::string& Client::target() const { return impl_->target; }
const ClientOptions& Client::options() const { return impl_->options; }

}  // namespace cloudcast::client
