// The bridges' conversions of camera messages into cloudcast frames, for the three inputs: a
// disparity map (stereo_msgs/DisparityImage) with its colour image and CameraInfo, a depth image
// with colour and CameraInfo, a rectified stereo pair with both CameraInfos. Transport-free: ROS 1
// and ROS 2 fill the views of message_views.h. Errors name the topic and field.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "cloudcast/client/frame.h"
#include "cloudcast/core/camera.h"
#include "image_checks.h"
#include "input_source.h"
#include "message_views.h"

namespace cloudcast::ros_bridge {

// The topics of each input, relative to the node's namespace (remap them to the camera's).
inline constexpr const char* kDisparityTopic = "disparity";
inline constexpr const char* kDisparityColourTopic = "left/image_rect_color";
inline constexpr const char* kDisparityInfoTopic = "left/camera_info";

// ---- ~input disparity
// The disparity input (~input disparity): stereo_msgs/DisparityImage + the left colour image +
// the left CameraInfo, as stereo_image_proc's point_cloud2 nodelet takes them, turned into
// cloudcast frames.
//
// The camera model (stereo_msgs/DisparityImage.msg: "for disparity d, the depth from the camera
// is Z = fT/d"; the disparities are pre-adjusted for the principal points' x-offset):
//   fx, fy, cx, cy   from the CameraInfo's projection matrix P (the rectified camera)
//   baseline         f * T / fx, so that cloudcast's z = fx * baseline / d is f T / d
//   x = (u - cx) z / fx, y = (v - cy) z / fy, as image_geometry's reprojection
// Invalid pixels ("any disparity less than min_disparity is invalid"; stereo_image_proc writes
// min_disparity - 1 there): values below min_disparity, NaN and infinities give no point; so does
// d <= 0 (no finite depth), as in cloudcast's model.

// The camera model of a DisparityImage and the CameraInfo of its (left, rectified) camera. Errors
// name the topic's field: an uncalibrated CameraInfo (P all zero), sizes that differ, f or T not
// finite and positive.
absl::StatusOr<CameraModel> CameraFromDisparity(const DisparityImageMsg& disparity,
                                                const CameraInfoMsg& info);

// The disparities of `disparity` (32FC1, little endian) with every invalid value (below
// min_disparity, or not finite) replaced by NaN, in `buffer` (reused from frame to frame): the one
// copy of the pixels the bridge makes before the client library's own.
absl::StatusOr<DisparityView> MaskedDisparity(const DisparityImageMsg& disparity,
                                              std::vector<float>* buffer);

// One synchronized set of messages as a frame: the camera, the masked disparities (in
// `buffer`), the colour view and the disparity's header. Errors name the topic and field.
absl::Status ToFrame(const DisparityImageMsg& disparity, const ImageMsg& colour,
                     const CameraInfoMsg& info, std::vector<float>* buffer,
                     OutgoingFrame* frame);

// ---- ~input depth
// The depth input (~input depth): a depth image registered to the colour camera + the colour
// image + its CameraInfo, the three topics of depth_image_proc's point_cloud_xyzrgb nodelet,
// turned into cloudcast frames.
//
// The image (REP 118): 16UC1 in millimetres or 32FC1 in metres (or whatever unit ~depth_scale
// says); 0, NaN and infinities are no measurement. The server computes the points by
// depth_image_proc's own formula, in its order of float operations:
//   z = D * float(s),  x = ((u - cx) * D) * float(s / fx),  y = ((v - cy) * D) * float(s / fy)
// with fx, fy, cx, cy from the CameraInfo's P (image_geometry's), or K when P is all zero.
// One difference: for a 32FC1 depth of exactly 0.0 depth_image_proc publishes a point at the
// camera's origin; REP 118 calls it no reading, and cloudcast gives no point.

// The topics, relative to the node's namespace (remap them to the camera's).
inline constexpr const char* kDepthTopic = "depth_registered/image_rect";
inline constexpr const char* kDepthColourTopic = "rgb/image_rect_color";
inline constexpr const char* kDepthInfoTopic = "rgb/camera_info";

// The camera model of a depth image and the CameraInfo of its pixels (the colour camera's, for a
// registered depth image): the intrinsics, and `depth_scale` (unset: REP 118's unit for the
// encoding). Errors name the topic's field.
absl::StatusOr<CameraModel> CameraFromDepth(const ImageMsg& depth,
                                            const CameraInfoMsg& info,
                                            std::optional<double> depth_scale);

// A view of the depth pixels in the message (16UC1 or 32FC1, little endian), no copy: the
// server reads 0, NaN and infinities as no measurement, so nothing needs masking.
absl::StatusOr<DepthView> DepthFromImage(const ImageMsg& depth);

// One synchronized set of messages as a frame: the camera, the depth and colour views and the
// depth image's header. The depth and colour images must be of the same size and frame_id (as
// depth_image_proc requires). Errors name the topic and field.
absl::Status ToDepthFrame(const ImageMsg& depth, const ImageMsg& colour,
                          const CameraInfoMsg& info, std::optional<double> depth_scale,
                          OutgoingFrame* frame);

// ---- ~input stereo
// The stereo input (~input stereo): the rectified left and right images of a stereo camera and
// both CameraInfos (the four topics stereo_image_proc's disparity nodelet takes, the left one in
// colour so that the points have it), sent as stereo pairs that the server matches
// (StreamConfig.stereo, ~stereo/... parameters).
//
// The camera model, from the rectified cameras' projection matrices (REP 104, CameraInfo.msg):
//   fx, fy, cx, cy   the left P (P[0], P[5], P[2], P[6])
//   baseline         -P_right[3] / P_right[0] (the right P's Tx = -fx' * B), so that
//                    z = fx * baseline / d is image_geometry's f T / d
// The server's matcher gives d = u_left - u_right, which is the disparity only when both
// rectified cameras have the same intrinsics: a right P with another fx, fy, cx or cy is refused
// (stereo_image_proc would shift its disparities by cx - cx'; OpenCV's stereoRectify with
// CALIB_ZERO_DISPARITY, as ROS's camera_calibration runs it, makes them equal).

// The topics, relative to the node's namespace (the camera's; remap e.g. right/image_rect to
// right/image_rect_color for a colour right image, or left/image_rect_color to left/image_rect).
inline constexpr const char* kLeftTopic = "left/image_rect_color";
inline constexpr const char* kRightTopic = "right/image_rect";
inline constexpr const char* kLeftInfoTopic = "left/camera_info";
inline constexpr const char* kRightInfoTopic = "right/camera_info";

// The camera model of a rectified pair of `width` x `height` images from its two CameraInfos.
// Errors name the topic's field.
absl::StatusOr<CameraModel> CameraFromStereo(const CameraInfoMsg& left_info,
                                             const CameraInfoMsg& right_info,
                                             std::uint32_t width, std::uint32_t height);

// One synchronized set of messages as a frame: the camera, the two image views (rgb8, bgr8,
// rgba8, bgra8 or mono8 each; the server matches their grey, the points take the left one's
// colour) and the left image's header. Errors name the topic and field.
absl::Status ToStereoFrame(const ImageMsg& left, const ImageMsg& right,
                           const CameraInfoMsg& left_info,
                           const CameraInfoMsg& right_info, OutgoingFrame* frame);

}  // namespace cloudcast::ros_bridge
