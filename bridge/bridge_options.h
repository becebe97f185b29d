// The bridges' settings, read from the node's parameters (ROS 1: ~server, ~input, ...; ROS 2:
// server, input, voxel.leaf, ...) through a ParamReader of either transport, and the one table of
// those parameters that --help, docs/ros.md and docs/ros2.md print.
#pragma once

#include <chrono>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "cloudcast/client/config.h"
#include "cloudcast/client/options.h"
#include "cloudcast/video/h264_settings.h"

namespace cloudcast::ros_bridge {

// What the robot's camera gives: a disparity map (stereo_image_proc's), a depth image (a depth
// camera's, REP 118) or a rectified stereo pair that the server matches.
enum class InputKind { kDisparity, kDepth, kStereo };
std::string_view Name(InputKind kind);  // "disparity", "depth", "stereo"

// How the images travel to the server (~encoding; the programs' --encoding): raw pixels, zstd
// (lossless: row deltas + zstd, about a third of raw), h264 (the colour image, or both views of
// a stereo pair, as H.264 pictures of one encoder per bitstream kept across frames; a disparity or
// depth map stays lossless and goes zstd-compressed) or jpeg (the colour image, or both views of
// a pair, as JPEG through client::AdaptiveJpegCoder: at ~jpeg/quality, or under ~rate_control at
// the quality the controller's target carries, with a half-resolution floor; a disparity or depth
// map stays lossless, zstd).
enum class Uplink { kRaw, kZstd, kH264, kJpeg };
std::string_view Name(Uplink uplink);  // "raw", "zstd", "h264", "jpeg"
// Whether this build has the video encoder (cloudcast_video_frames: FFmpeg); without it (the
// client-only arm64 build) ~encoding h264 is refused.
bool HasVideoEncoder();
// Whether this build has the JPEG coder (cloudcast_client_opencv: OpenCV); without it ~encoding
// jpeg is refused.
bool HasJpegEncoder();

// ~encoding jpeg: client::AdaptiveJpegOptions as parameters (~jpeg/*). Without ~rate_control
// every frame goes at `quality`, full resolution (the coder has no target to follow); with it,
// `quality` is where a stream starts and the rest is the controller's.
struct JpegSettings {
  int quality = 90;         // ~jpeg/quality, 1..100 (cloudcast-client's --jpeg-quality)
  int min_quality = 10;     // ~jpeg/min_quality, rate_control only
  int max_quality = 95;     // ~jpeg/max_quality, rate_control only
  bool half_resolution = true;  // ~jpeg/half_resolution, rate_control only, not for stereo
  double fps = 30;          // ~jpeg/fps: the camera's rate (a frame's budget), rate_control only
};

// How the input topics are paired into frames (message_filters).
struct SyncOptions {
  int queue_size = 5;             // the synchronizer's queue, per topic
  bool approximate_sync = false;  // ApproximateTime instead of ExactTime
};

struct BridgeOptions {
  std::string server = "127.0.0.1:50051";  // gRPC target
  InputKind input = InputKind::kDisparity;
  SyncOptions sync;
  // Connection: timeouts, TLS and the bearer token (ClientOptions::security).
  client::ClientOptions client;
  bool resilient = true;  // StreamOptions::resilient
  bool rate_control = false;  // StreamOptions::rate_control, with delivery latest
  // The controller's settings (rate/*: target_delay_ms, start_mbps, min_mbps, max_mbps, as
  // cloudcast-client's --rate-* flags); the library's defaults when unset.
  client::RateControlOptions rate;
  std::chrono::milliseconds reconnect_timeout{30000};
  // The stream's passthrough, voxel grid, Draco, delivery and (~input stereo) matcher; the camera
  // is added per frame. Unset fields take the server's defaults.
  client::StreamConfig config;
  // ~input depth: the unit of a raw depth value (~depth_scale); unset, REP 118's.
  std::optional<double> depth_scale;
  // ~input stereo: publish the server's disparity map as a stereo_msgs/DisparityImage
  // (~stereo/publish_disparity; sets config.stereo.return_disparity).
  bool publish_disparity = false;
  Uplink uplink = Uplink::kRaw;  // ~encoding (~compress true: zstd)
  // ~encoding h264: the encoder's settings (~h264/*: the programs' --h264-* flags, with their
  // defaults and rules), made into the stream's coder (StreamOptionsFor in cloud_link.h) for
  // frames at ~h264/fps.
  video::H264Settings h264;
  double h264_fps = 30;
  // ~encoding jpeg: the coder's settings (~jpeg/*), made into the stream's coder with the
  // stream's camera (StreamOptionsFor in cloud_link.h).
  JpegSettings jpeg;
  double diagnostics_period_s = 1.0;
};

// One parameter as --help and docs/ros.md describe it.
struct ParamDoc {
  std::string name;  // without the "~"
  std::string type;  // "string", "int", "double", "bool"
  std::string default_value;
  std::string help;
};
const std::vector<ParamDoc>& ParamDocs();

// `text` in lines of at most `width` characters, each after `indent` (for --help).
std::string WrapText(const std::string& text, std::size_t width, const std::string& indent);

// The node's parameters on one transport, by the names of ParamDocs ("voxel/leaf").
class ParamReader {
 public:
  virtual ~ParamReader() = default;
  // Unset: nullopt. Set with another type: INVALID_ARGUMENT naming the parameter. Double takes an
  // integer too ("leaf: 1" in YAML).
  virtual absl::StatusOr<std::optional<std::string>> String(const std::string& name) const = 0;
  virtual absl::StatusOr<std::optional<bool>> Bool(const std::string& name) const = 0;
  virtual absl::StatusOr<std::optional<int>> Int(const std::string& name) const = 0;
  virtual absl::StatusOr<std::optional<double>> Double(const std::string& name) const = 0;
  // Every parameter the node was given, by the names of ParamDocs (known or not).
  virtual std::vector<std::string> Names() const = 0;
  // The name as the user wrote it, for errors: "~voxel/leaf" (ROS 1), "voxel.leaf" (ROS 2).
  virtual std::string Display(const std::string& name) const = 0;
};

// Reads the parameters. Parameters of the wrong type, out of range or naming files that cannot
// be read give INVALID_ARGUMENT naming the parameter, e.g. "~voxel/leaf is -0.5; must be finite
// and > 0". Parameters the bridge does not know (a typo, "~voxel/leafsize") are errors too, so
// that a setting is never silently ignored; `program` names the bridge in that error.
absl::StatusOr<BridgeOptions> ReadBridgeOptions(const ParamReader& params,
                                                const std::string& program);

}  // namespace cloudcast::ros_bridge
