// One Process call's request bytes: parsed as the service parses them, the config resolved
// against the server's defaults, then the frame through the worker's path (FrameRunner::Run:
// image decoding, validation, pipeline, Draco) with the settings the config gave. Unlike the
// Stream harness, config and frame arrive together, so the fuzzer explores frames under any
// camera, passthrough, voxel grid and Draco settings the server accepts.
#include <cstddef>
#include <cstdint>

#include "frame_harness.h"

using namespace cloudcast;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static fuzz::FrameHarness* harness = new fuzz::FrameHarness;
  static server::RequestReader* reader = new server::RequestReader;  // kept, as a stream's slot
  v1::ProcessRequest request;
  if (!fuzz::ParseChecked(data, size, reader, &request)) return 0;  // UNPARSABLE
  auto settings = convert::Resolve(request.config(), harness->defaults());
  if (!settings.ok()) return 0;  // the call ends with the resolve error
  harness->RunFrame(request.frame(), &reader->pixels(), settings->frame);
  return 0;
}
