// A gRPC server that does no work: CloudCast.Stream answers each frame at once with an empty
// CloudReply (sequence, capture time and frame id echoed). A test tool for measuring the load
// generator's own ceiling, not a model of cloudcast-server. Frames are never parsed whole: only
// the StreamRequest's first fields are read, the image bytes are skipped.
#pragma once

#include <memory>
#include <string>

#include "absl/status/statusor.h"

namespace grpc {
class Server;
}

namespace cloudcast::load {

class NullServer {
 public:
  // Listens on `listen` (port 0: a free one). Health checking answers SERVING.
  static absl::StatusOr<std::unique_ptr<NullServer>> Start(const std::string& listen,
                                                           const std::string& instance);
  ~NullServer();
  const std::string& address() const { return address_; }
  void Shutdown();

  class Service;

 private:
  NullServer();
  std::unique_ptr<Service> service_;
  std::unique_ptr<grpc::Server> server_;
  std::string address_;
};

}  // namespace cloudcast::load
