#include "frame_harness.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "cloudcast/core/draco_codec.h"
#include "cloudcast/server/options.h"
#include "google/protobuf/util/field_comparator.h"
#include "google/protobuf/util/message_differencer.h"

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
  std::vector<grpc::Slice> slices;
  std::size_t at = 0;
  for (std::size_t n = 1; at < size; n = n % 64 + 1) {
    const std::size_t take = std::min(n, size - at);
    slices.emplace_back(data + at, take);
    at += take;
  }
  return grpc::ByteBuffer(slices.data(), slices.size());
}

template <typename Request>
bool ParseChecked(const std::uint8_t* data, std::size_t size, server::RequestReader* reader,
                  Request* request) {
  grpc::ByteBuffer bytes = ToByteBuffer(data, size);
  const bool parsed = reader->Parse(&bytes, request);
  Request expected;
  const bool expected_parsed = expected.ParseFromArray(data, static_cast<int>(size));
  if (parsed != expected_parsed) {
    std::fprintf(stderr, "RequestReader %s what protobuf %s\n", parsed ? "parsed" : "refused",
                 expected_parsed ? "parses" : "refuses");
    std::abort();
  }
  if (!parsed) return false;
  Request rebuilt = *request;
  if (rebuilt.has_frame()) reader->PutPixelsBack(rebuilt.mutable_frame());
  const server::InPlacePixels& left = reader->pixels();
  if (!rebuilt.has_frame() && (left.disparity.size > 0 || left.colour.size > 0)) {
    std::fprintf(stderr, "RequestReader left pixels in place for a request without a frame\n");
    std::abort();
  }
  // Field by field, NaN equal to NaN (a config may hold NaNs, and so must both parses).
  google::protobuf::util::DefaultFieldComparator comparator;
  comparator.set_treat_nan_as_equal(true);
  google::protobuf::util::MessageDifferencer differencer;
  differencer.set_field_comparator(&comparator);
  if (!differencer.Compare(rebuilt, expected)) {
    std::fprintf(stderr, "RequestReader's message differs from protobuf's:\n%s\nvs\n%s\n",
                 rebuilt.ShortDebugString().c_str(), expected.ShortDebugString().c_str());
    std::abort();
  }
  return true;
}

template bool ParseChecked(const std::uint8_t*, std::size_t, server::RequestReader*,
                           v1::StreamRequest*);
template bool ParseChecked(const std::uint8_t*, std::size_t, server::RequestReader*,
                           v1::ProcessRequest*);

FrameHarness::FrameHarness() : runner_(1, &metrics_, "fuzz"), defaults_(SmallDefaults()) {}

void FrameHarness::RunFrame(const v1::Frame& frame, const server::InPlacePixels* in_place,
                            const FrameSettings& settings) {
  // The worker pool's weight for the frame, read before anything is checked.
  (void)server::FramePixels(frame);
  const server::Arrival arrival{std::chrono::steady_clock::now(), 0};
  reply_.Clear();
  v1::CloudReply* cloud = reply_.mutable_cloud();
  absl::Status status;
  const bool video = server::VideoDecoders::HasVideo(frame);
  if (video) {
    std::int64_t charged = 0;
    {
      server::VideoDecoders decoders(
          settings.pipeline.limits,
          [&charged](std::uint64_t bytes) {
            charged += static_cast<std::int64_t>(bytes);
            return absl::OkStatus();
          },
          [&charged](std::uint64_t bytes) { charged -= static_cast<std::int64_t>(bytes); });
      status = decoders.Decode(frame, &video_);
    }
    if (charged != 0) {
      std::fprintf(stderr, "the video decoders gave back %lld bytes fewer than they took\n",
                   static_cast<long long>(charged));
      std::abort();
    }
  }
  if (status.ok()) {
    status = runner_.Run(0, frame, in_place, settings, arrival, cloud, video ? &video_ : nullptr);
  }
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
