// The bridge's settings, read from its private ROS parameters (~server, ~input, ...), and the one
// table of those parameters that --help and docs/ros.md print.
#pragma once

#include <chrono>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "cloudcast/client/config.h"
#include "cloudcast/client/options.h"

namespace ros {
class NodeHandle;
}

namespace cloudcast::ros_bridge {

// What the robot's camera gives: a disparity map (stereo_image_proc's), a depth image (a depth
// camera's, REP 118) or a rectified stereo pair that the server matches.
enum class InputKind { kDisparity, kDepth, kStereo };
std::string_view Name(InputKind kind);  // "disparity", "depth", "stereo"

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
  std::chrono::milliseconds reconnect_timeout{30000};
  // The stream's passthrough, voxel grid, Draco, delivery and (~input stereo) matcher; the camera
  // is added per frame. Unset fields take the server's defaults.
  client::StreamConfig config;
  // ~input depth: the unit of a raw depth value (~depth_scale); unset, REP 118's.
  std::optional<double> depth_scale;
  // ~input stereo: publish the server's disparity map as a stereo_msgs/DisparityImage
  // (~stereo/publish_disparity; sets config.stereo.return_disparity).
  bool publish_disparity = false;
  bool compress = false;  // lossless zstd uplink (row deltas): for a thin link
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

// The text `cloudcast-ros-bridge --help` prints: usage, topics, parameters, examples.
std::string HelpText();

// Reads the private parameters of `private_nh` (a "~" handle). Parameters of the wrong type, out
// of range or naming files that cannot be read give INVALID_ARGUMENT naming the parameter, e.g.
// "~voxel/leaf is -0.5; must be finite and > 0". Parameters this bridge does not know (a typo,
// "~voxel/leafsize") are errors too, so that a setting is never silently ignored.
absl::StatusOr<BridgeOptions> ReadBridgeOptions(const ros::NodeHandle& private_nh);

}  // namespace cloudcast::ros_bridge
