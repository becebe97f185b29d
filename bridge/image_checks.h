// What the three inputs share about camera messages (either ROS's; message_views.h): the layout
// check of a sensor_msgs/Image, the colour view of one, and the pinhole camera of a CameraInfo. Errors name the
// topic and field (e.g. "rgb/image_rect_color.step is 100, less than width x 3 = 1920").
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/client/frame.h"
#include "message_views.h"

namespace cloudcast::ros_bridge {

// Width and height of at least 1x1, a step of at least a row of `bytes_per_pixel` pixels and data
// for every row. `field` names the image in the errors.
absl::Status CheckLayout(const ImageMsg& image, std::size_t bytes_per_pixel,
                         const std::string& field);

// A view of a colour image (rgb8, bgr8, rgba8, bgra8, mono8); other encodings are
// INVALID_ARGUMENT naming `topic`'s encoding field. The view points into `image`.
absl::StatusOr<client::ColorInput> ColourFromImage(const ImageMsg& image,
                                                   const std::string& topic);

// Both images of a frame must have the same pixel grid; `second` is named as the one that
// differs ("rgb/image_rect_color is 320x240 but depth_registered/image_rect is 640x480").
absl::Status CheckSameSize(const ImageMsg& first, const std::string& first_topic,
                           const ImageMsg& second, const std::string& second_topic);

// The intrinsics of a rectified image (image_geometry's fx(), fy(), cx(), cy()).
struct Pinhole {
  double fx = 0, fy = 0, cx = 0, cy = 0;
};

// Which matrix of the CameraInfo gives the intrinsics.
enum class IntrinsicsFrom {
  kP,     // the projection matrix only (stereo: the rectified cameras)
  kPOrK,  // P, or K when P is all zero (a depth camera's driver may fill K only)
};

// The intrinsics of `info` (topic `topic`) for an image of `width` x `height` (`image_topic`):
// finite, positive focal lengths, a finite principal point; refused when the camera is not
// calibrated (the matrix all zero), binned or cropped (binning, roi), or of another size than the
// image (a CameraInfo of size 0 is taken as the image's).
absl::StatusOr<Pinhole> PinholeFromInfo(const CameraInfoMsg& info,
                                        const std::string& topic, std::uint32_t width,
                                        std::uint32_t height, const std::string& image_topic,
                                        IntrinsicsFrom from = IntrinsicsFrom::kP);

}  // namespace cloudcast::ros_bridge
