#include "depth_input.h"

#include <sensor_msgs/image_encodings.h>

#include <utility>

#include "absl/strings/str_cat.h"

namespace cloudcast::ros_bridge {
namespace {

namespace enc = sensor_msgs::image_encodings;

absl::Status Invalid(const std::string& message) { return absl::InvalidArgumentError(message); }

}  // namespace

absl::StatusOr<CameraModel> CameraFromDepth(const sensor_msgs::Image& depth,
                                            const sensor_msgs::CameraInfo& info,
                                            std::optional<double> depth_scale) {
  auto pinhole = PinholeFromInfo(info, kDepthInfoTopic, depth.width, depth.height, kDepthTopic,
                                 IntrinsicsFrom::kPOrK);
  if (!pinhole.ok()) return pinhole.status();
  CameraModel camera;
  camera.fx = pinhole->fx;
  camera.fy = pinhole->fy;
  camera.cx = pinhole->cx;
  camera.cy = pinhole->cy;
  // The disparity members do not apply to depth images; an empty invalid list keeps the stream
  // config free of PCL's disparity values.
  camera.invalid_disparities = {};
  camera.depth_scale = depth_scale;
  if (absl::Status s = camera.Validate("depth camera"); !s.ok()) return s;
  return camera;
}

absl::StatusOr<DepthView> DepthFromImage(const sensor_msgs::Image& depth) {
  DepthEncoding encoding;
  if (depth.encoding == enc::TYPE_16UC1) {
    encoding = DepthEncoding::kU16;
  } else if (depth.encoding == enc::TYPE_32FC1) {
    encoding = DepthEncoding::kF32;
  } else {
    return Invalid(absl::StrCat(kDepthTopic, ".encoding is '", depth.encoding,
                                "'; must be 16UC1 (millimetres) or 32FC1 (metres), REP 118"));
  }
  if (depth.is_bigendian) {
    return Invalid(
        absl::StrCat(kDepthTopic, ".is_bigendian is 1; the bridge takes little-endian pixels"));
  }
  if (absl::Status s = CheckLayout(depth, BytesPerPixel(encoding), kDepthTopic); !s.ok()) return s;
  DepthView view;
  view.data = depth.data.data();
  view.size_bytes = depth.data.size();
  view.width = depth.width;
  view.height = depth.height;
  view.stride_bytes = depth.step;
  view.encoding = encoding;
  return view;
}

absl::Status ToDepthFrame(const sensor_msgs::Image& depth, const sensor_msgs::Image& colour,
                          const sensor_msgs::CameraInfo& info, std::optional<double> depth_scale,
                          OutgoingFrame* frame) {
  auto camera = CameraFromDepth(depth, info, depth_scale);
  if (!camera.ok()) return camera.status();
  auto view = DepthFromImage(depth);
  if (!view.ok()) return view.status();
  if (absl::Status s = CheckSameSize(depth, kDepthTopic, colour, kDepthColourTopic); !s.ok()) {
    return s;
  }
  // A depth image registered to the colour camera is in that camera's frame; another frame_id
  // means the colours would land on the wrong points.
  if (depth.header.frame_id != colour.header.frame_id) {
    return Invalid(absl::StrCat(kDepthColourTopic, ".header.frame_id is '", colour.header.frame_id,
                                "' but ", kDepthTopic, "'s is '", depth.header.frame_id,
                                "'; the depth image must be registered to the colour camera"));
  }
  auto colour_view = ColourFromImage(colour, kDepthColourTopic);
  if (!colour_view.ok()) return colour_view.status();
  frame->camera = *std::move(camera);
  frame->images = client::DepthFrame{*view, *colour_view};
  frame->header = depth.header;
  return absl::OkStatus();
}

DepthInput::DepthInput(ros::NodeHandle& nh, const SyncOptions& sync,
                       std::optional<double> depth_scale, Sink sink, ErrorSink error_sink)
    : depth_scale_(depth_scale),
      sink_(std::move(sink)),
      error_sink_(std::move(error_sink)),
      sync_(nh, {kDepthTopic, kDepthColourTopic, kDepthInfoTopic}, sync,
            [this](const auto& d, const auto& c, const auto& i) { OnMessages(d, c, i); }) {}

void DepthInput::OnMessages(const sensor_msgs::Image::ConstPtr& depth,
                            const sensor_msgs::Image::ConstPtr& colour,
                            const sensor_msgs::CameraInfo::ConstPtr& info) {
  OutgoingFrame frame;
  if (absl::Status s = ToDepthFrame(*depth, *colour, *info, depth_scale_, &frame); !s.ok()) {
    error_sink_(s);
    return;
  }
  sink_(frame);
}

}  // namespace cloudcast::ros_bridge
