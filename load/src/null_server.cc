#include "cloudcast/load/null_server.h"

#include <google/protobuf/io/coded_stream.h>
#include <grpcpp/ext/health_check_service_server_builder_option.h>
#include <grpcpp/generic/async_generic_service.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/support/proto_buffer_reader.h>

#include <deque>
#include <mutex>

#include "absl/status/status.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace cloudcast::load {
namespace {

using google::protobuf::io::CodedInputStream;
using WireFormat = std::uint32_t;

// Reads StreamRequest.frame's sequence, capture time and frame id, skipping everything else.
// False for a config or anything that is no frame.
bool PeekFrame(grpc::ByteBuffer* buffer, v1::CloudReply* reply) {
  grpc::ProtoBufferReader reader(buffer);
  CodedInputStream in(&reader);
  std::uint32_t tag = in.ReadTag();
  if (tag != ((2 << 3) | 2)) return false;  // StreamRequest.frame
  std::uint32_t length = 0;
  if (!in.ReadVarint32(&length)) return false;
  const auto limit = in.PushLimit(static_cast<int>(length));
  while ((tag = in.ReadTag()) != 0) {
    const int field = static_cast<int>(tag >> 3);
    if (field == 1 || field == 2) {
      std::uint64_t v = 0;
      if (!in.ReadVarint64(&v)) return false;
      if (field == 1) reply->set_sequence(v);
      if (field == 2) reply->set_capture_time_unix_ns(static_cast<std::int64_t>(v));
    } else if (field == 3 && (tag & 7) == 2) {
      std::string id;
      std::uint32_t n = 0;
      if (!in.ReadVarint32(&n) || !in.ReadString(&id, static_cast<int>(n))) return false;
      reply->set_frame_id(id);
    } else if ((tag & 7) == 2) {
      std::uint32_t n = 0;
      if (!in.ReadVarint32(&n) || !in.Skip(static_cast<int>(n))) return false;
    } else if ((tag & 7) == 0) {
      std::uint64_t v;
      if (!in.ReadVarint64(&v)) return false;
    } else {
      return false;
    }
  }
  in.PopLimit(limit);
  return true;
}

}  // namespace

class NullServer::Service : public grpc::CallbackGenericService {
 public:
  explicit Service(std::string instance) : instance_(std::move(instance)) {}

  grpc::ServerGenericBidiReactor* CreateReactor(grpc::GenericCallbackServerContext* ctx) override {
    if (ctx->method() != "/cloudcast.v1.CloudCast/Stream") {
      return grpc::CallbackGenericService::CreateReactor(ctx);  // UNIMPLEMENTED
    }
    return new Stream(instance_);
  }

 private:
  // Reads a frame, writes its reply, reads the next: at most one reply waiting, so a slow
  // reader slows the sender through flow control, as a real server would.
  class Stream : public grpc::ServerGenericBidiReactor {
   public:
    explicit Stream(const std::string& instance) : instance_(instance) { StartRead(&in_); }
    void OnReadDone(bool ok) override {
      if (!ok) {
        Finish(grpc::Status::OK);
        return;
      }
      v1::StreamReply reply;
      v1::CloudReply* cloud = reply.mutable_cloud();
      if (!PeekFrame(&in_, cloud)) {  // a config: no reply
        in_.Clear();
        StartRead(&in_);
        return;
      }
      in_.Clear();
      cloud->set_server_instance(instance_);
      const std::string bytes = reply.SerializeAsString();
      grpc::Slice slice(bytes.data(), bytes.size());
      out_ = grpc::ByteBuffer(&slice, 1);
      StartWrite(&out_);
    }
    void OnWriteDone(bool ok) override {
      if (!ok) {
        Finish(grpc::Status(grpc::StatusCode::CANCELLED, "write failed"));
        return;
      }
      StartRead(&in_);
    }
    void OnDone() override { delete this; }

   private:
    const std::string& instance_;
    grpc::ByteBuffer in_, out_;
  };

  const std::string instance_;
};

NullServer::NullServer() = default;
NullServer::~NullServer() { Shutdown(); }

absl::StatusOr<std::unique_ptr<NullServer>> NullServer::Start(const std::string& listen,
                                                              const std::string& instance) {
  std::unique_ptr<NullServer> s(new NullServer());
  s->service_ = std::make_unique<Service>(instance);
  grpc::EnableDefaultHealthCheckService(true);
  grpc::ServerBuilder builder;
  int port = 0;
  builder.AddListeningPort(listen, grpc::InsecureServerCredentials(), &port);
  builder.SetMaxReceiveMessageSize(-1);
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  builder.RegisterCallbackGenericService(s->service_.get());
  s->server_ = builder.BuildAndStart();
  if (!s->server_ || port == 0) {
    return absl::UnavailableError("cannot listen on " + listen);
  }
  s->server_->GetHealthCheckService()->SetServingStatus("cloudcast.v1.CloudCast", true);
  s->address_ = listen.substr(0, listen.rfind(':') + 1) + std::to_string(port);
  return s;
}

void NullServer::Shutdown() {
  if (server_) {
    server_->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(1));
    server_->Wait();
    server_.reset();
  }
}

}  // namespace cloudcast::load
