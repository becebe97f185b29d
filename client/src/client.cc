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
#include <string>
#include <thread>
#include <utility>

#include "absl/strings/str_cat.h"
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

// What the reader needs to know about a frame in flight.
struct Pending {
  std::uint64_t sequence = 0;
  std::int64_t capture_time_unix_ns = 0;
  Clock::time_point send;
  std::int64_t send_unix_ns = 0;
};

}  // namespace

// ---------------------------------------------------------------------------------------------
// Stream

struct Stream::Impl {
  std::shared_ptr<Stub> stub;  // shared with the Client: a stream may outlive it
  std::string target;
  bool decode_clouds = true;
  StreamOptions options;
  grpc::ClientContext context;
  std::unique_ptr<grpc::ClientReaderWriter<v1::StreamRequest, v1::StreamReply>> rpc;

  // Writer side. Frames and configs use separate messages: switching one message's oneof from
  // frame to config would free the frame's pixel buffers, which Send reuses.
  std::mutex write_mu;
  v1::StreamRequest frame_request;
  v1::StreamRequest config_request;
  bool writes_closed = false;
  bool write_failed = false;
  std::uint64_t next_sequence = 0;
  std::atomic<std::uint64_t> frames_sent{0};

  // Frames sent and not answered yet, in send order. Replies come in the same order; frames the
  // server skipped (DELIVERY_LATEST) are passed over when a later reply arrives.
  std::mutex pending_mu;
  std::deque<Pending> pending;

  // Reader side.
  std::mutex read_mu;
  v1::StreamReply reply;
  bool read_done = false;
  std::thread receiver;

  std::mutex finish_mu;
  bool finished = false;
  absl::Status final_status;

  std::string What() const { return absl::StrCat("stream to ", target); }

  absl::Status Write(const v1::StreamRequest& request) {
    if (writes_closed) {
      return absl::FailedPreconditionError(absl::StrCat(What(), ": already closed by CloseSend"));
    }
    if (write_failed || !rpc->Write(request)) {
      write_failed = true;
      return absl::UnavailableError(
          absl::StrCat(What(), " has ended; Stream::Finish() returns the reason"));
    }
    return absl::OkStatus();
  }

  // Takes the send record of `sequence` (and of any skipped frames before it).
  bool TakePending(std::uint64_t sequence, Pending* out) {
    std::lock_guard<std::mutex> lock(pending_mu);
    auto it = std::find_if(pending.begin(), pending.end(),
                           [&](const Pending& p) { return p.sequence == sequence; });
    if (it == pending.end()) return false;
    *out = *it;
    pending.erase(pending.begin(), it + 1);
    return true;
  }

  bool ReadOne(Result* result, bool decode) {
    std::lock_guard<std::mutex> lock(read_mu);
    if (read_done) return false;
    if (!rpc->Read(&reply)) {
      read_done = true;
      return false;
    }
    result->times = ClientTimes{};
    result->times.receive = Clock::now();
    result->times.receive_unix_ns = UnixNanosNow();
    result->status = absl::OkStatus();
    result->config_rejected = false;
    bool answers_frame = true;
    switch (reply.kind_case()) {
      case v1::StreamReply::kCloud:
        // Swapped, not copied: the Draco bytes move into the result.
        result->reply.Swap(reply.mutable_cloud());
        result->sequence = result->reply.sequence();
        result->frame_id = result->reply.frame_id();
        result->capture_time_unix_ns = result->reply.capture_time_unix_ns();
        result->frames_dropped = result->reply.frames_dropped();
        break;
      case v1::StreamReply::kError: {
        const v1::FrameError& error = reply.error();
        result->status = convert::ToStatus(error);
        result->reply.Clear();
        result->sequence = error.sequence();
        result->frame_id = error.frame_id();
        result->capture_time_unix_ns = 0;
        result->frames_dropped = error.frames_dropped();
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
        result->frames_dropped = 0;
        break;
    }
    if (Pending p; answers_frame && TakePending(result->sequence, &p)) {
      result->times.send = p.send;
      result->times.send_unix_ns = p.send_unix_ns;
      // FrameError does not echo the capture time; the client knows what it sent.
      if (result->capture_time_unix_ns == 0) result->capture_time_unix_ns = p.capture_time_unix_ns;
    }
    if (result->status.ok()) {
      DecodeInto(decode, result);
    } else {
      result->cloud.ResizeUnorganized(0);
    }
    return true;
  }

  absl::Status CloseSend() {
    std::lock_guard<std::mutex> lock(write_mu);
    if (writes_closed) return absl::OkStatus();
    writes_closed = true;
    if (write_failed) return absl::OkStatus();  // nothing to close; Finish reports why
    if (!rpc->WritesDone()) {
      write_failed = true;
      return absl::UnavailableError(
          absl::StrCat(What(), " has ended; Stream::Finish() returns the reason"));
    }
    return absl::OkStatus();
  }

  absl::Status Finish() {
    std::lock_guard<std::mutex> lock(finish_mu);
    if (finished) return final_status;
    CloseSend().IgnoreError();  // a dead call still finishes below, with its real status
    if (receiver.joinable()) {
      receiver.join();
    } else {
      // gRPC's Finish must follow the last Read: drain what nobody will read, undecoded.
      Result discard;
      while (ReadOne(&discard, /*decode=*/false)) {
      }
    }
    final_status = FromGrpc(rpc->Finish(), What());
    finished = true;
    return final_status;
  }
};

Stream::Stream(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

Stream::~Stream() {
  if (impl_ == nullptr) return;
  {
    std::lock_guard<std::mutex> lock(impl_->finish_mu);
    if (!impl_->finished) impl_->context.TryCancel();
  }
  impl_->Finish().IgnoreError();
}

absl::Status Stream::Send(const DisparityInput& disparity, const ColorInput& colour,
                          const FrameMeta& meta) {
  std::lock_guard<std::mutex> lock(impl_->write_mu);
  if (impl_->writes_closed) {
    return absl::FailedPreconditionError(
        absl::StrCat(impl_->What(), ": Send after CloseSend or Finish"));
  }
  v1::Frame* frame = impl_->frame_request.mutable_frame();
  if (absl::Status s = internal::FillImages(disparity, colour, frame); !s.ok()) return s;
  const std::uint64_t sequence = meta.sequence.value_or(impl_->next_sequence);
  internal::FillMeta(meta, sequence, frame);

  Pending pending;
  pending.sequence = sequence;
  pending.capture_time_unix_ns = frame->capture_time_unix_ns();
  pending.send = Clock::now();
  pending.send_unix_ns = UnixNanosNow();
  {
    // Recorded before the write: the reply may arrive before Write returns.
    std::lock_guard<std::mutex> plock(impl_->pending_mu);
    impl_->pending.push_back(pending);
  }
  if (absl::Status s = impl_->Write(impl_->frame_request); !s.ok()) return s;
  impl_->next_sequence = sequence + 1;
  impl_->frames_sent.fetch_add(1, std::memory_order_relaxed);
  return absl::OkStatus();
}

absl::Status Stream::Reconfigure(const StreamConfig& config) {
  std::lock_guard<std::mutex> lock(impl_->write_mu);
  *impl_->config_request.mutable_config() = config;
  return impl_->Write(impl_->config_request);
}

bool Stream::Read(Result* result) {
  if (impl_->options.on_result) return false;
  return impl_->ReadOne(result, impl_->decode_clouds);
}

absl::Status Stream::CloseSend() { return impl_->CloseSend(); }

absl::Status Stream::Finish() { return impl_->Finish(); }

void Stream::Cancel() { impl_->context.TryCancel(); }

std::uint64_t Stream::frames_sent() const {
  return impl_->frames_sent.load(std::memory_order_relaxed);
}

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
  args.SetMaxReceiveMessageSize(ClampToInt(options.max_message_bytes));
  args.SetMaxSendMessageSize(ClampToInt(options.max_message_bytes));
  if (options.max_reconnect_backoff.count() > 0) {
    args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS,
                static_cast<int>(options.max_reconnect_backoff.count()));
  }
  std::shared_ptr<grpc::ChannelCredentials> credentials =
      options.credentials != nullptr ? options.credentials : grpc::InsecureChannelCredentials();
  std::shared_ptr<grpc::Channel> channel = grpc::CreateCustomChannel(target, credentials, args);
  if (channel == nullptr) {
    return absl::InternalError(absl::StrCat("cannot create a gRPC channel to ", target));
  }
  if (options.connect_timeout.count() > 0 &&
      !channel->WaitForConnected(std::chrono::system_clock::now() + options.connect_timeout)) {
    return absl::UnavailableError(absl::StrCat(
        "cannot connect to the cloudcast server at ", target, " within ",
        options.connect_timeout.count(), " ms (channel ", StateName(channel->GetState(false)),
        "); is the server running, and are the address and port right?"));
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
  v1::ProcessRequest request;
  if (absl::Status s = internal::FillImages(disparity, colour, request.mutable_frame()); !s.ok()) {
    return s;
  }
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
  impl->stub = impl_->stub;
  impl->target = impl_->target;
  impl->decode_clouds = impl_->options.decode_clouds;
  impl->options = std::move(options);
  impl->context.set_wait_for_ready(impl_->options.wait_for_ready);
  impl->rpc = impl->stub->Stream(&impl->context);
  if (impl->rpc == nullptr) {
    return absl::InternalError(absl::StrCat("cannot start a stream to ", impl_->target));
  }
  *impl->config_request.mutable_config() = config;
  if (!impl->rpc->Write(impl->config_request)) {
    // The call is dead before it began; its status says why (e.g. UNAVAILABLE).
    absl::Status s = FromGrpc(impl->rpc->Finish(), impl->What());
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
