#include "disparity_output.h"

#include <sensor_msgs/image_encodings.h>

#include <cstdint>
#include <cstring>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/limits.h"
#include "cloudcast/proto/convert.h"

namespace cloudcast::ros_bridge {

absl::Status ToDisparityImage(const v1::CompressedDisparity& compressed,
                              const std_msgs::Header& header, const CameraModel& camera,
                              const DisparityRange& range, PlaneDecompressor* decompressor,
                              stereo_msgs::DisparityImage* out) {
  DisparityView view;
  if (absl::Status s =
          convert::DecodeCompressed(compressed, "reply.disparity", Limits{}, decompressor, &view);
      !s.ok()) {
    return s;
  }
  if (view.encoding != DisparityEncoding::kU16) {
    return absl::InvalidArgumentError(absl::StrCat("reply.disparity is ",
                                                   std::string(Name(view.encoding)),
                                                   "; the server sends u16 in 1/16 pixel"));
  }
  out->header = header;
  out->f = static_cast<float>(camera.fx);
  out->T = static_cast<float>(camera.baseline);
  out->min_disparity = static_cast<float>(range.min_disparity);
  out->max_disparity = static_cast<float>(range.min_disparity + range.num_disparities - 1);
  out->delta_d = 1.0f / 16;
  out->valid_window.x_offset = 0;
  out->valid_window.y_offset = 0;
  out->valid_window.width = view.width;
  out->valid_window.height = view.height;
  out->valid_window.do_rectify = false;
  sensor_msgs::Image& image = out->image;
  image.header = header;
  image.width = view.width;
  image.height = view.height;
  image.encoding = sensor_msgs::image_encodings::TYPE_32FC1;
  image.is_bigendian = 0;
  image.step = view.width * sizeof(float);
  image.data.resize(std::size_t{image.step} * view.height);
  const float invalid = out->min_disparity - 1.0f;
  for (std::uint32_t v = 0; v < view.height; ++v) {
    const std::uint8_t* src = view.row(v);
    std::uint8_t* dst = image.data.data() + std::size_t{v} * image.step;
    for (std::uint32_t u = 0; u < view.width; ++u) {
      std::uint16_t raw;
      std::memcpy(&raw, src + 2 * u, sizeof raw);
      const float d = raw == 0 ? invalid : raw / 16.0f;
      std::memcpy(dst + 4 * u, &d, sizeof d);
    }
  }
  return absl::OkStatus();
}

}  // namespace cloudcast::ros_bridge
