// One kind of camera input: its subscribers, their time synchronization, and the conversion of
// each synchronized set of messages into a frame for the client library (frame_conversions.h).
// ROS 1's are ros/src/{disparity,depth,stereo}_input.h (message_filters), ROS 2's
// ros2/src/ros2_inputs.h (DDS readers).
#pragma once


#include <functional>
#include <string>

#include "absl/status/status.h"
#include "bridge_options.h"
#include "cloudcast/client/frame.h"
#include "cloudcast/core/camera.h"
#include "message_views.h"

namespace cloudcast::ros_bridge {

// A frame ready for Stream::Send. The views point into the messages (or a buffer of the
// input), valid during the sink call only.
struct OutgoingFrame {
  client::FrameInput images;  // a DisparityFrame, DepthFrame or StereoFrame
  CameraModel camera;         // this frame's camera, in cloudcast's model
  MessageHeader header;       // the stamp and frame_id the cloud gets
};

class InputSource {
 public:
  // Called for each synchronized frame, on the ROS callback thread.
  using Sink = std::function<void(const OutgoingFrame&)>;
  // Called for each set of messages that cannot become a frame; the status names the topic and
  // the field (e.g. "disparity.image.encoding is '16UC1'; must be 32FC1").
  using ErrorSink = std::function<void(const absl::Status&)>;

  virtual ~InputSource() = default;
  // The resolved topics it subscribes to, for the log.
  virtual std::string Describe() const = 0;
};

}  // namespace cloudcast::ros_bridge
