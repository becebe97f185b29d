// Subscribers to N ROS 1 topics, synchronized by message_filters (the ROS 1 inputs' half of
// input_source.h).
#pragma once

#include <message_filters/subscriber.h>
#include <message_filters/sync_policies/approximate_time.h>
#include <message_filters/sync_policies/exact_time.h>
#include <message_filters/synchronizer.h>
#include <ros/ros.h>

#include <array>
#include <functional>
#include <memory>
#include <string>
#include <tuple>
#include <utility>

#include "bridge_options.h"

namespace cloudcast::ros_bridge {

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
