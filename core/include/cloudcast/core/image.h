// Non-owning views of the input images of a frame: a disparity map or a depth image, and a colour
// image.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string_view>

#include "absl/status/status.h"
#include "cloudcast/core/limits.h"

namespace cloudcast {

enum class DisparityEncoding : std::uint8_t {
  kU8,   // 8-bit unsigned, one value per pixel
  kU16,  // 16-bit unsigned (host order), e.g. 1/16 fixed point from stereo matchers
  kF32,  // 32-bit float
};

enum class ColorEncoding : std::uint8_t {
  kBGR8,  // OpenCV's default order
  kRGB8,
  kRGBA8,  // alpha is ignored, as PCL ignores it
  kMono8,  // grey: r = g = b
};

// A depth image as ROS REP 118 has it (depth cameras: RealSense, Kinect, OAK-D). 0 (and, for
// floats, NaN or an infinity) means no measurement. The unit is the camera's depth_scale
// (camera.h): millimetres for kU16 and metres for kF32 unless it says otherwise.
enum class DepthEncoding : std::uint8_t {
  kU16,  // 16-bit unsigned (host order), ROS 16UC1
  kF32,  // 32-bit float, ROS 32FC1
};

std::size_t BytesPerPixel(DisparityEncoding e);
std::size_t BytesPerPixel(DepthEncoding e);
std::size_t BytesPerPixel(ColorEncoding e);
std::string_view Name(DisparityEncoding e);
std::string_view Name(DepthEncoding e);
std::string_view Name(ColorEncoding e);
// Parses the names above ("u8", "u16", "f32"; "u16", "f32"; "bgr8", "rgb8", "rgba8", "mono8").
bool ParseDisparityEncoding(std::string_view name, DisparityEncoding* out);
bool ParseDepthEncoding(std::string_view name, DepthEncoding* out);
bool ParseColorEncoding(std::string_view name, ColorEncoding* out);

// A view of pixel rows in memory. `stride_bytes` is the distance between row starts; `size_bytes`
// is how much memory `data` points to, so a view can be checked before it is read.
//
// `rows`, when set, says where each row is instead: row v starts at rows[v]. The server sets it
// for a frame it reads where gRPC received it, in pieces (one row may be in one network buffer
// and the next in another). `data` and `size_bytes` then describe the image as it was sent (they
// are what ValidateView checks); only row() reaches the pixels. Every row of such a view is
// followed by at least one readable byte, so a kernel may load a 3-byte pixel with 4 bytes.
template <typename Encoding>
struct ImageView {
  const void* data = nullptr;
  std::size_t size_bytes = 0;
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  std::size_t stride_bytes = 0;
  Encoding encoding{};
  const std::uint8_t* const* rows = nullptr;

  const std::uint8_t* row(std::uint32_t v) const {
    return rows != nullptr ? rows[v] : static_cast<const std::uint8_t*>(data) + v * stride_bytes;
  }
};
using DisparityView = ImageView<DisparityEncoding>;
using DepthView = ImageView<DepthEncoding>;
using ColorView = ImageView<ColorEncoding>;

// What the caller calls a view's stride, buffer and encoding in its messages: the core's names by
// default, the proto's ("row_stride", "pixels", "DISPARITY_U16") at the proto boundary.
struct ImageFieldNames {
  std::string_view stride = "stride_bytes";
  std::string_view buffer = "data";
  std::string_view encoding;  // empty: the core's Name(encoding)
};

// Checks one view: a known encoding, a size of at least 1x1 within `limits` (RESOURCE_EXHAUSTED
// beyond them), non-null data, stride >= width * bytes per pixel, and a buffer large enough for
// every row. Errors name the field under `field` (e.g. "disparity.stride_bytes").
absl::Status ValidateView(const DisparityView& view, const Limits& limits,
                          std::string_view field = "disparity", const ImageFieldNames& names = {});
absl::Status ValidateView(const DepthView& view, const Limits& limits,
                          std::string_view field = "depth", const ImageFieldNames& names = {});
absl::Status ValidateView(const ColorView& view, const Limits& limits,
                          std::string_view field = "colour", const ImageFieldNames& names = {});
// The images of a frame must have the same size: `second` is named as the one that differs.
absl::Status CheckSameSize(std::uint32_t first_width, std::uint32_t first_height,
                           std::string_view first_field, std::uint32_t second_width,
                           std::uint32_t second_height, std::string_view second_field);
template <typename A, typename B>
absl::Status CheckSameSize(const ImageView<A>& first, std::string_view first_field,
                           const ImageView<B>& second, std::string_view second_field) {
  return CheckSameSize(first.width, first.height, first_field, second.width, second.height,
                       second_field);
}
// Checks both views and that their sizes agree.
absl::Status ValidateFrame(const DisparityView& disparity, const ColorView& colour,
                           const Limits& limits);
absl::Status ValidateFrame(const DepthView& depth, const ColorView& colour, const Limits& limits);

}  // namespace cloudcast
