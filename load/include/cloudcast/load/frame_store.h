// The frames a load run sends, prepared once before it starts so that the generator's own cost
// (loading, encoding, serializing 1.2 MB) stays off the measurement.
//
// Each distinct frame is serialized once, as the tail of a StreamRequest{frame}: the Frame's
// frame_id and images, without its sequence and capture time. A send writes a few header bytes
// (the StreamRequest tag and length, then Frame.sequence and Frame.capture_time_unix_ns, fields 1
// and 2, which the wire format lets stand before the others) and points at the shared tail, so
// nothing large is copied or re-serialized per send.
#pragma once

#include <grpcpp/support/byte_buffer.h>
#include <grpcpp/support/slice.h>

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace cloudcast::load {

// kZstd: both images compressed losslessly (row deltas + zstd), float disparities included.
enum class Uplink { kRaw, kPng, kJpeg, kZstd };
bool ParseUplink(const std::string& name, Uplink* out);
const char* Name(Uplink uplink);

struct FrameSourceOptions {
  // One of these three (checked by the caller's flags); all empty: New Tsukuba when present,
  // else the synthetic scene at 640x480.
  std::string tsukuba_dir;
  std::string illumination = "daylight";
  std::string disparity_glob, colour_glob;
  std::uint32_t synthetic_width = 0, synthetic_height = 0;
  int synthetic_frames = 10;  // distinct synthetic frames (the camera moves from one to the next)
  Uplink uplink = Uplink::kRaw;
  int jpeg_quality = 90;
  int png_compression = 1;
};

class FrameStore {
 public:
  // Loads, encodes and serializes every frame. Errors name the flag or the file.
  static absl::StatusOr<FrameStore> Prepare(const FrameSourceOptions& options);

  // Frames made by the caller (tests): each serialized as it is, sequence and time ignored.
  static FrameStore FromFrames(const std::vector<v1::Frame>& frames, const CameraModel& camera,
                               const std::string& description);

  std::size_t size() const { return tails_.size(); }
  // The bytes of frame `index % size()` on the wire, sequence and time patched in. Only a small
  // header slice is new; the image bytes are shared with every other send of that frame.
  grpc::ByteBuffer Request(std::size_t index, std::uint64_t sequence,
                           std::int64_t capture_time_unix_ns) const;
  // The request's size in bytes (about the same for every send of that frame).
  std::size_t RequestBytes(std::size_t index) const;
  double MeanRequestBytes() const;

  // The camera the frames were made with (the StreamConfig's camera section).
  const CameraModel& camera() const { return camera_; }
  // e.g. "New Tsukuba (10 frames, 640x480), raw".
  const std::string& description() const { return description_; }

 private:
  FrameStore() = default;
  void AddTail(const v1::Frame& frame);

  // Owned strings, so their slices can be static (no refcount, no copy) for the store's life.
  std::vector<std::shared_ptr<const std::string>> tails_;
  CameraModel camera_;
  std::string description_;
};

// The wire bytes of a StreamRequest holding `config` (the first message of every stream).
grpc::ByteBuffer SerializeConfig(const v1::StreamConfig& config);

}  // namespace cloudcast::load
