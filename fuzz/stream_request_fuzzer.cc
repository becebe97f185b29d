// One message of a Stream call, as the bytes gRPC reads: parsed as the service parses it, then
// a config resolved against the server's defaults (as StreamReactor::Accept does), a frame run
// through the worker's path (FrameRunner::Run: image decoding, validation, pipeline, Draco), or
// the error reply for a request holding neither.
#include <cstddef>
#include <cstdint>

#include "frame_harness.h"
#include "service.h"

using namespace cloudcast;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static fuzz::FrameHarness* harness = new fuzz::FrameHarness;
  grpc::ByteBuffer bytes = fuzz::ToByteBuffer(data, size);
  v1::StreamRequest request;
  if (!server::ParseRequest(&bytes, &request)) return 0;  // the stream ends: nothing else runs
  switch (request.kind_case()) {
    case v1::StreamRequest::kConfig: {
      auto settings = convert::Resolve(request.config(), harness->defaults());
      v1::FrameError error;
      if (!settings.ok())
        convert::FillError(settings.status(), v1::ERROR_KIND_CONFIG, 0, "", &error);
      break;
    }
    case v1::StreamRequest::kFrame:
      harness->RunFrame(request.frame(), harness->defaults().frame);
      break;
    default:
      break;
  }
  return 0;
}
