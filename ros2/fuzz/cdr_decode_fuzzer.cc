// The ROS 2 bridge's decoding of what arrives on its topics: bytes as a DDS reader gets them
// (encapsulation header first) through Cyclone's check and read (DeserializeCdr: normalization,
// then the sample), for each of the bridge's message types (the first byte picks the type), and
// the inputs' samples further through the shared conversions into frames (the views, the layout
// and camera checks, the disparity masking). Nothing may crash, leak or read out of bounds; a
// sample that decodes must re-encode to bytes that decode again to the same encoding.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "frame_conversions.h"
#include "message_types.h"
#include "sample_views.h"

using namespace cloudcast;
using namespace cloudcast::ros2_bridge;

namespace {

// The inputs' samples through the shared conversions, with a well-formed partner message.
void Convert(const MessageType& type, const void* sample) {
  static std::vector<float> masked;
  sensor_msgs_msg_dds__CameraInfo_ info{};
  info.width = 4;
  info.height = 4;
  info.p[0] = info.p[5] = 2.0;
  info.p[2] = info.p[6] = 1.0;
  ros_bridge::OutgoingFrame frame;
  if (&type == &kDisparityImageType) {
    const auto& d = *static_cast<const stereo_msgs_msg_dds__DisparityImage_*>(sample);
    (void)ros_bridge::ToFrame(View(d), View(d.image), View(info), &masked, &frame);
  } else if (&type == &kImageType) {
    const auto& image = *static_cast<const sensor_msgs_msg_dds__Image_*>(sample);
    (void)ros_bridge::ToDepthFrame(View(image), View(image), View(info), std::nullopt, &frame);
    (void)ros_bridge::ToStereoFrame(View(image), View(image), View(info), View(info), &frame);
  } else if (&type == &kCameraInfoType) {
    const auto& ci = *static_cast<const sensor_msgs_msg_dds__CameraInfo_*>(sample);
    (void)ros_bridge::CameraFromStereo(View(ci), View(ci), ci.width, ci.height);
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const auto& types = AllMessageTypes();
  const MessageType& type = *types[data[0] % types.size()];
  std::vector<std::uint64_t> storage((type.descriptor->m_size + 7) / 8 + 1, 0);
  void* sample = storage.data();
  if (!DeserializeCdr(type, {data + 1, size - 1}, sample).ok()) return 0;
  Convert(type, sample);
  const std::vector<std::uint8_t> again = SerializeCdr(type, sample);
  std::vector<std::uint64_t> storage2((type.descriptor->m_size + 7) / 8 + 1, 0);
  if (!DeserializeCdr(type, again, storage2.data()).ok()) {
    std::fprintf(stderr, "%s: a decoded sample's encoding does not decode\n", type.ros_name);
    std::abort();
  }
  if (SerializeCdr(type, storage2.data()) != again) {
    std::fprintf(stderr, "%s: re-encoding is not stable\n", type.ros_name);
    std::abort();
  }
  FreeSample(type, storage2.data());
  FreeSample(type, sample);
  return 0;
}
