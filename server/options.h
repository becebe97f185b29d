// The server's options, with their documented defaults, and the translation of a client's
// StreamConfig into the core's stage options.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/core/draco_codec.h"
#include "cloudcast/core/filters.h"
#include "cloudcast/core/limits.h"
#include "cloudcast/core/pipeline.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace cloudcast::server {

// How a stream treats frames that arrive faster than they are processed (proto DeliveryMode).
enum class Delivery : std::uint8_t {
  kLatest,  // real time: a newer frame replaces an older one still waiting
  kAll,     // lossless: gRPC flow control slows the client down
};
const char* Name(Delivery delivery);  // "latest" / "all"
bool ParseDelivery(const std::string& name, Delivery* out);

// The stage parameters a stream gets for every StreamConfig field it leaves unset. The defaults
// are the paper's: PCL's conversion with focal 615, passthrough z in [3, 12], 3 cm voxels.
struct StageDefaults {
  double focal = 615.0;  // fx and fy, pixels
  Axis axis = Axis::kZ;  // passthrough axis
  float min = 3.0f;      // passthrough limits, inclusive
  float max = 12.0f;
  float leaf = 0.03f;  // voxel leaf on x, y and z; 0 switches the voxel grid off
  int draco_bits = DracoOptions{}.position_bits;  // 11
  int draco_speed = DracoOptions{}.encode_speed;  // 10, for encoding and decoding
  Delivery delivery = Delivery::kLatest;
};

struct ServerOptions {
  // host:port to serve gRPC on; port 0 picks a free port (Server::port() reports it).
  std::string listen = "0.0.0.0:50051";
  // Worker threads that process frames; 0 means one per core (std::thread::hardware_concurrency).
  int threads = 0;
  // Largest request message gRPC accepts. A raw 640x480 frame (8-bit disparity, RGB colour) is
  // 1.2 MiB; one at the pixel limit (2^24 pixels) is 64 MiB plus a few bytes, so serving frames
  // that large needs this raised.
  std::uint64_t max_message_bytes = std::uint64_t{64} << 20;
  // Largest image side and width x height (the core's limits).
  Limits limits;
  // Concurrent Stream calls; the next one gets RESOURCE_EXHAUSTED.
  std::uint32_t max_streams = 64;
  // A stream on which nothing moved this long is ended with DEADLINE_EXCEEDED.
  std::chrono::milliseconds idle_timeout{60'000};
  // Frames held per stream in DELIVERY_ALL mode (waiting + in work + replies not yet written).
  std::uint32_t max_queued_frames = 4;
  // On shutdown, how long frames in flight may take before their calls are cancelled.
  std::chrono::milliseconds shutdown_grace{5'000};
  // host:port for Prometheus' /metrics; empty switches the HTTP exporter off.
  std::string metrics_listen = "0.0.0.0:9464";
  // This replica's name, sent in every reply and in GetInfo. Empty: the host name.
  std::string instance;
  StageDefaults defaults;

  // Everything in range: threads >= 0, positive limits, max_queued_frames >= 1, sane defaults.
  // Errors name the command-line flag.
  absl::Status Validate() const;
  // `threads`, or the number of cores when it is 0 (at least 1).
  int ResolvedThreads() const;
  // `instance`, or the host name when it is empty.
  std::string ResolvedInstance() const;
};

// A StreamConfig resolved against the server defaults and validated: everything a frame needs.
struct StreamSettings {
  // cx and cy are only meaningful when set; otherwise they follow each frame's size.
  CameraModel camera;
  bool has_cx = false;
  bool has_cy = false;
  PassThroughParams passthrough;
  VoxelGridParams voxel;
  DracoOptions draco;
  Delivery delivery = Delivery::kLatest;
  Limits limits;

  // The pipeline options for a width x height frame: the principal point defaults to
  // (width / 2, height / 2) in integer division, as PCL puts it.
  PipelineOptions ForFrame(std::uint32_t width, std::uint32_t height) const;
};

// The settings of a stream that has sent no StreamConfig.
StreamSettings DefaultSettings(const ServerOptions& options);

// Resolves `config` field by field: a set field wins, an unset one takes the server default.
// Every value is checked; an error is INVALID_ARGUMENT and names the field by its proto path
// under `prefix` (e.g. "config.voxel_grid.leaf must be finite and > 0, got 0").
absl::StatusOr<StreamSettings> ResolveStreamConfig(const v1::StreamConfig& config,
                                                   const ServerOptions& options,
                                                   const std::string& prefix = "config");

// Every field of a StreamConfig filled with the server's default (GetInfo's `defaults`). The
// camera's cx and cy stay unset: they follow the image size.
v1::StreamConfig DefaultStreamConfig(const ServerOptions& options);

}  // namespace cloudcast::server
