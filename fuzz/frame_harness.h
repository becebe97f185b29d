// What the server does with a request's bytes, without sockets: the harnesses of
// stream_request_fuzzer.cc and process_request_fuzzer.cc run their messages through the same
// calls the service makes (RequestReader, convert::Resolve, FramePixels, FrameRunner::Run,
// convert::FillError, the reply's serialization).
#pragma once

#include <grpcpp/support/byte_buffer.h>

#include <cstddef>
#include <cstdint>
#include <memory>

#include "cloudcast/proto/convert.h"
#include "cloudcast/v1/cloudcast.pb.h"
#include "frame_processor.h"
#include "metrics.h"
#include "request_reader.h"
#include "video_input.h"

namespace cloudcast::fuzz {

// The bytes as gRPC hands them to the service: in slices, here of 1 to 64 bytes in turn, so that
// fields and rows fall across slice boundaries (gRPC's are 16 KB).
grpc::ByteBuffer ToByteBuffer(const std::uint8_t* data, std::size_t size);

// Parses the bytes as the service does (RequestReader) and checks it against protobuf's own
// parse of them: both accept or both refuse, and with the pixels put back the messages are
// equal. A difference aborts, so the fuzzer reports it.
template <typename Request>
bool ParseChecked(const std::uint8_t* data, std::size_t size, server::RequestReader* reader,
                  Request* request);

class FrameHarness {
 public:
  FrameHarness();

  // The server's defaults, with limits small enough that one input costs milliseconds: sizes up
  // to 256 x 256 pixels (the checks are the same at any limit; the engine's cost is not).
  const convert::StreamSettings& defaults() const { return defaults_; }

  // What a worker does with a frame (StreamReactor::Work, Process): FrameRunner::Run into a
  // CloudReply, a FrameError on failure, then the reply serialized. A frame with video pictures
  // has them decoded first, as a stream's reading path does (VideoDecoders, fresh for each
  // frame: a one-picture stream, so that an input replays alike), charged to a budget that must
  // be whole again once the decoders are gone. A cloud that was produced
  // must decode with libdraco to point_count points (the server's own output: anything else
  // aborts, so the fuzzer reports it).
  void RunFrame(const v1::Frame& frame, const server::InPlacePixels* in_place,
                const FrameSettings& settings);

 private:
  server::Metrics metrics_;
  server::FrameRunner runner_;
  convert::StreamSettings defaults_;
  v1::StreamReply reply_;  // kept, as a stream keeps its reply buffers
  server::DecodedVideo video_;
  PointCloud decoded_;
};

}  // namespace cloudcast::fuzz
