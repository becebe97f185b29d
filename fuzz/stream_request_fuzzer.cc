// One message of a Stream call, as the bytes gRPC reads: parsed as the service parses it
// (RequestReader, checked against protobuf's own parse), then
// a config resolved against the server's defaults (as StreamReactor::Accept does), a frame run
// through the worker's path (FrameRunner::Run: image decoding, validation, pipeline, Draco), or
// the error reply for a request holding neither.
#include <cstddef>
#include <cstdint>

#include "frame_harness.h"

using namespace cloudcast;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static fuzz::FrameHarness* harness = new fuzz::FrameHarness;
  static server::RequestReader* reader = new server::RequestReader;  // kept, as a stream's slot
  v1::StreamRequest request;
  if (!fuzz::ParseChecked(data, size, reader, &request))
    return 0;  // the stream ends: nothing else runs
  switch (request.kind_case()) {
    case v1::StreamRequest::kConfig: {
      auto settings = convert::Resolve(request.config(), harness->defaults());
      v1::FrameError error;
      if (!settings.ok())
        convert::FillError(settings.status(), v1::ERROR_KIND_CONFIG, 0, "", &error);
      break;
    }
    case v1::StreamRequest::kFrame:
      harness->RunFrame(request.frame(), &reader->pixels(), harness->defaults().frame);
      break;
    default:
      break;
  }
  return 0;
}
