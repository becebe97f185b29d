// One kind of camera input: its subscribers, their time synchronization, and the conversion of
// each synchronized set of messages into a frame for the client library. Three classes like it:
// disparity_input.h (stereo_msgs/DisparityImage), depth_input.h (a depth image) and
// stereo_input.h (a rectified stereo pair, matched on the server).
#pragma once

#include <message_filters/subscriber.h>
#include <message_filters/sync_policies/approximate_time.h>
#include <message_filters/sync_policies/exact_time.h>
#include <message_filters/synchronizer.h>
#include <ros/ros.h>
#include <std_msgs/Header.h>

#include <array>
#include <functional>
#include <memory>
#include <string>
#include <tuple>
#include <utility>

#include "absl/status/status.h"
#include "bridge_options.h"
#include "cloudcast/client/frame.h"
#include "cloudcast/core/camera.h"

namespace cloudcast::ros_bridge {

// A frame ready for Stream::Send. The views point into the ROS messages (or a buffer of the
// input), valid during the sink call only.
struct OutgoingFrame {
  client::FrameInput images;  // a DisparityFrame, DepthFrame or StereoFrame
  CameraModel camera;         // this frame's camera, in cloudcast's model
  std_msgs::Header header;    // the stamp and frame_id the cloud gets
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

// Subscribers to N topics and a message_filters synchronizer over them (ExactTime or
// ApproximateTime, by SyncOptions), calling `callback` with each matched set.
template <typename... Messages>
class TopicSync {
 public:
  using Callback = std::function<void(const boost::shared_ptr<const Messages>&...)>;

  TopicSync(ros::NodeHandle& nh, const std::array<std::string, sizeof...(Messages)>& topics,
            const SyncOptions& options, Callback callback)
      : callback_(std::move(callback)) {
    Subscribe(nh, topics, options.queue_size, std::index_sequence_for<Messages...>{});
    auto connect = [&](auto& sync) {
      std::apply([&](auto&... subs) { sync->connectInput(subs...); }, subscribers_);
      sync->registerCallback(&TopicSync::Deliver, this);
    };
    if (options.approximate_sync) {
      approximate_ = std::make_unique<ApproximateSync>(ApproximatePolicy(options.queue_size));
      connect(approximate_);
    } else {
      exact_ = std::make_unique<ExactSync>(ExactPolicy(options.queue_size));
      connect(exact_);
    }
  }
  TopicSync(const TopicSync&) = delete;
  TopicSync& operator=(const TopicSync&) = delete;

  // "/stereo/disparity, /stereo/left/image_rect_color, ..."
  std::string Describe() const {
    std::string out;
    std::apply(
        [&](const auto&... subs) { ((out += (out.empty() ? "" : ", ") + subs.getTopic()), ...); },
        subscribers_);
    return out;
  }

 private:
  using ExactPolicy = message_filters::sync_policies::ExactTime<Messages...>;
  using ApproximatePolicy = message_filters::sync_policies::ApproximateTime<Messages...>;
  using ExactSync = message_filters::Synchronizer<ExactPolicy>;
  using ApproximateSync = message_filters::Synchronizer<ApproximatePolicy>;

  template <std::size_t... I>
  void Subscribe(ros::NodeHandle& nh, const std::array<std::string, sizeof...(Messages)>& topics,
                 int queue_size, std::index_sequence<I...>) {
    // The synchronizer's queue is the one that matters; each subscriber keeps as many.
    (std::get<I>(subscribers_).subscribe(nh, topics[I], static_cast<std::uint32_t>(queue_size)),
     ...);
  }

  void Deliver(const boost::shared_ptr<const Messages>&... messages) { callback_(messages...); }

  Callback callback_;
  std::tuple<message_filters::Subscriber<Messages>...> subscribers_;
  std::unique_ptr<ExactSync> exact_;
  std::unique_ptr<ApproximateSync> approximate_;
};

}  // namespace cloudcast::ros_bridge
