#include "frame_harness.h"

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "cloudcast/core/draco_codec.h"
#include "cloudcast/server/options.h"

namespace cloudcast::fuzz {
namespace {

convert::StreamSettings SmallDefaults() {
  server::ServerOptions options;
  options.limits.max_side = 256;
  options.limits.max_pixels = 256 * 256;
  return options.StreamDefaults();
}

}  // namespace

grpc::ByteBuffer ToByteBuffer(const std::uint8_t* data, std::size_t size) {
  grpc::Slice slice(data, size);
  return grpc::ByteBuffer(&slice, 1);
}

FrameHarness::FrameHarness() : runner_(1, &metrics_, "fuzz"), defaults_(SmallDefaults()) {}

void FrameHarness::RunFrame(const v1::Frame& frame, const FrameSettings& settings) {
  // The worker pool's weight for the frame, read before anything is checked.
  (void)server::FramePixels(frame);
  const server::Arrival arrival{std::chrono::steady_clock::now(), 0};
  reply_.Clear();
  v1::CloudReply* cloud = reply_.mutable_cloud();
  const absl::Status status = runner_.Run(0, frame, settings, arrival, cloud);
  if (status.ok()) {
    if (absl::Status d = DecodeDraco(cloud->draco(), &decoded_); !d.ok()) {
      std::fprintf(stderr, "the server's own cloud does not decode: %s\n",
                   std::string(d.message()).c_str());
      std::abort();
    }
    if (decoded_.size() != cloud->point_count()) {
      std::fprintf(stderr, "the cloud decodes to %zu points; the reply says %u\n", decoded_.size(),
                   cloud->point_count());
      std::abort();
    }
  } else {
    convert::FillError(status, v1::ERROR_KIND_FRAME, frame.sequence(), frame.frame_id(),
                       reply_.mutable_error());
  }
  std::string bytes;
  reply_.SerializeToString(&bytes);
}

}  // namespace cloudcast::fuzz
