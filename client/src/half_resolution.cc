#include "cloudcast/client/half_resolution.h"

#include <cstring>
#include <variant>

#include "absl/strings/str_cat.h"

namespace cloudcast::client {
namespace {

// One half row: pixels 0, 2, 4, ... of `row`.
void SampleRow(const std::uint8_t* row, std::uint32_t half_width, std::size_t pixel_bytes,
               std::uint8_t* out) {
  for (std::uint32_t u = 0; u < half_width; ++u) {
    std::memcpy(out + u * pixel_bytes, row + 2 * u * pixel_bytes, pixel_bytes);
  }
}

// One half row: the mean of each 2x2 block of rows `a` and `b`.
void AverageRows(const std::uint8_t* a, const std::uint8_t* b, std::uint32_t half_width,
                 int channels, std::uint8_t* out) {
  const std::size_t n = static_cast<std::size_t>(half_width) * channels;
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t pixel = i / channels, channel = i % channels;
    const std::size_t left = 2 * pixel * channels + channel, right = left + channels;
    const unsigned sum = a[left] + a[right] + b[left] + b[right];
    out[i] = static_cast<std::uint8_t>((sum + 2) / 4);
  }
}

absl::Status CheckHalvable(std::uint32_t width, std::uint32_t height, const char* field) {
  if (width < 2 || height < 2) {
    return absl::InvalidArgumentError(absl::StrCat("half resolution: the ", field, " is ", width,
                                                   "x", height, ", smaller than 2x2"));
  }
  return absl::OkStatus();
}

int Channels(ColorEncoding e) { return static_cast<int>(BytesPerPixel(e)); }

}  // namespace

v1::CameraModel HalfResolutionCamera(const v1::CameraModel& stream, bool disparity) {
  v1::CameraModel half;
  half.set_fx(stream.fx() / 2);
  if (stream.has_fy()) half.set_fy(stream.fy() / 2);
  if (stream.has_cx()) half.set_cx(stream.cx() / 2);
  if (stream.has_cy()) half.set_cy(stream.cy() / 2);
  if (disparity) {
    half.set_disparity_scale((stream.has_disparity_scale() ? stream.disparity_scale() : 1.0) / 2);
    if (stream.has_disparity_offset()) half.set_disparity_offset(stream.disparity_offset() / 2);
  }
  return half;
}

void SampleHalf(const std::uint8_t* src, std::size_t src_stride, std::uint32_t width,
                std::uint32_t height, std::size_t pixel_bytes, std::uint8_t* dst,
                std::size_t dst_stride) {
  for (std::uint32_t v = 0; v < HalfSize(height); ++v) {
    SampleRow(src + 2 * v * src_stride, HalfSize(width), pixel_bytes, dst + v * dst_stride);
  }
}

void AverageHalf(const std::uint8_t* src, std::size_t src_stride, std::uint32_t width,
                 std::uint32_t height, int channels, std::uint8_t* dst, std::size_t dst_stride) {
  for (std::uint32_t v = 0; v < HalfSize(height); ++v) {
    const std::uint8_t* a = src + 2 * v * src_stride;
    AverageRows(a, a + src_stride, HalfSize(width), channels, dst + v * dst_stride);
  }
}

template <typename View>
View HalfResolutionFrame::Sample(const View& full, std::string* buffer) {
  const std::size_t pixel_bytes = BytesPerPixel(full.encoding);
  View half = full;
  half.width = HalfSize(full.width);
  half.height = HalfSize(full.height);
  half.stride_bytes = half.width * pixel_bytes;
  half.rows = nullptr;
  buffer->resize(half.stride_bytes * half.height);
  auto* out = reinterpret_cast<std::uint8_t*>(buffer->data());
  for (std::uint32_t v = 0; v < half.height; ++v) {
    SampleRow(full.row(2 * v), half.width, pixel_bytes, out + v * half.stride_bytes);
  }
  half.data = buffer->data();
  half.size_bytes = buffer->size();
  return half;
}

ColorView HalfResolutionFrame::Average(const ColorView& full) {
  const int channels = Channels(full.encoding);
  ColorView half = full;
  half.width = HalfSize(full.width);
  half.height = HalfSize(full.height);
  half.stride_bytes = static_cast<std::size_t>(half.width) * channels;
  half.rows = nullptr;
  colour_bytes_.resize(half.stride_bytes * half.height);
  auto* out = reinterpret_cast<std::uint8_t*>(colour_bytes_.data());
  for (std::uint32_t v = 0; v < half.height; ++v) {
    AverageRows(full.row(2 * v), full.row(2 * v + 1), half.width, channels,
                out + v * half.stride_bytes);
  }
  half.data = colour_bytes_.data();
  half.size_bytes = colour_bytes_.size();
  return half;
}

absl::Status HalfResolutionFrame::Make(const FrameInput& full) {
  // The views are read, so they are checked as the request would check them first.
  const Limits limits{};
  const ColorInput* colour = nullptr;
  if (const auto* f = std::get_if<DisparityFrame>(&full)) {
    const auto* d = std::get_if<DisparityView>(&f->disparity);
    if (d == nullptr) {
      return absl::InvalidArgumentError("half resolution: the disparity is not a raw view");
    }
    if (absl::Status s = ValidateView(*d, limits, "disparity"); !s.ok()) return s;
    if (absl::Status s = CheckHalvable(d->width, d->height, "disparity"); !s.ok()) return s;
    disparity_ = Sample(*d, &geometry_);
    colour = &f->colour;
  } else if (const auto* f = std::get_if<DepthFrame>(&full)) {
    const auto* d = std::get_if<DepthView>(&f->depth);
    if (d == nullptr) {
      return absl::InvalidArgumentError("half resolution: the depth is not a raw view");
    }
    if (absl::Status s = ValidateView(*d, limits, "depth"); !s.ok()) return s;
    if (absl::Status s = CheckHalvable(d->width, d->height, "depth"); !s.ok()) return s;
    depth_ = Sample(*d, &geometry_);
    colour = &f->colour;
  } else {
    return absl::InvalidArgumentError(
        "half resolution: a stereo pair cannot be halved (its calibration is the server's)");
  }
  const auto* c = std::get_if<ColorView>(colour);
  if (c == nullptr) {
    return absl::InvalidArgumentError("half resolution: the colour is not a raw view");
  }
  if (absl::Status s = ValidateView(*c, limits, "colour"); !s.ok()) return s;
  if (absl::Status s = CheckHalvable(c->width, c->height, "colour"); !s.ok()) return s;
  colour_ = Average(*c);
  return absl::OkStatus();
}

}  // namespace cloudcast::client
