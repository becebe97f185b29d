#include "frame_builder.h"

#include <chrono>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <type_traits>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/limits.h"

namespace cloudcast::client {

std::int64_t UnixNanosNow() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

namespace internal {
namespace {

// The protocol's 16- and 32-bit samples are little endian; raw rows are sent as they lie in
// memory, which is only right on a little-endian host.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__,
              "raw U16/F32 disparities are sent as in memory; the protocol wants little endian");

// Only memory safety is checked here, so sizes and limits stay the server's one judgement.
constexpr Limits kNoLimits{std::numeric_limits<std::uint32_t>::max(),
                           std::numeric_limits<std::uint64_t>::max()};

// Copies `height` rows of `row_bytes` from `src` (rows `stride` apart) into `out`, packed.
void CopyRows(const void* src, std::size_t stride, std::size_t row_bytes, std::uint32_t height,
              std::string* out) {
  const std::size_t total = row_bytes * height;
  // Same-size frames keep the size, so resize() neither allocates nor zero-fills after the first.
  out->resize(total);
  char* dst = out->data();
  const char* s = static_cast<const char*>(src);
  if (stride == row_bytes) {
    std::memcpy(dst, s, total);
    return;
  }
  for (std::uint32_t v = 0; v < height; ++v) {
    std::memcpy(dst + v * row_bytes, s + v * stride, row_bytes);
  }
}

v1::DisparityEncoding ToProto(DisparityEncoding e) {
  switch (e) {
    case DisparityEncoding::kU8: return v1::DISPARITY_U8;
    case DisparityEncoding::kU16: return v1::DISPARITY_U16;
    case DisparityEncoding::kF32: return v1::DISPARITY_F32;
  }
  return v1::DISPARITY_ENCODING_UNSPECIFIED;
}

v1::ColorEncoding ToProto(ColorEncoding e) {
  switch (e) {
    case ColorEncoding::kBGR8: return v1::COLOR_BGR8;
    case ColorEncoding::kRGB8: return v1::COLOR_RGB8;
    case ColorEncoding::kRGBA8: return v1::COLOR_RGBA8;
    case ColorEncoding::kMono8: return v1::COLOR_MONO8;
  }
  return v1::COLOR_ENCODING_UNSPECIFIED;
}

template <typename View, typename Raw>
absl::Status FillRaw(const View& view, const char* field, Raw* raw) {
  if (absl::Status s = ValidateView(view, kNoLimits, field); !s.ok()) return s;
  raw->set_encoding(ToProto(view.encoding));
  raw->set_width(view.width);
  raw->set_height(view.height);
  raw->set_row_stride(0);
  CopyRows(view.data, view.stride_bytes, std::size_t{view.width} * BytesPerPixel(view.encoding),
           view.height, raw->mutable_pixels());
  return absl::OkStatus();
}

absl::Status FillBgra(const BgraView& view, v1::RawColor* raw) {
  if (view.width == 0 || view.height == 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("colour is empty: width=", view.width, " height=", view.height));
  }
  if (view.data == nullptr) return absl::InvalidArgumentError("colour.data is null");
  const std::uint64_t row_bytes = std::uint64_t{view.width} * 4;
  if (view.stride_bytes < row_bytes) {
    return absl::InvalidArgumentError(absl::StrCat("colour.stride_bytes is ", view.stride_bytes,
                                                   ", less than width x 4 = ", row_bytes));
  }
  const std::uint64_t needed = std::uint64_t{view.stride_bytes} * (view.height - 1) + row_bytes;
  if (view.size_bytes < needed) {
    return absl::InvalidArgumentError(
        absl::StrCat("colour buffer holds ", view.size_bytes, " bytes; ", view.width, "x",
                     view.height, " bgra8 with stride ", view.stride_bytes, " needs ", needed));
  }
  raw->set_encoding(v1::COLOR_BGR8);
  raw->set_width(view.width);
  raw->set_height(view.height);
  raw->set_row_stride(0);
  std::string* out = raw->mutable_pixels();
  out->resize(std::size_t{view.width} * 3 * view.height);
  auto* dst = reinterpret_cast<std::uint8_t*>(out->data());
  for (std::uint32_t v = 0; v < view.height; ++v) {
    const auto* src = static_cast<const std::uint8_t*>(view.data) + v * view.stride_bytes;
    for (std::uint32_t u = 0; u < view.width; ++u, src += 4, dst += 3) {
      dst[0] = src[0];
      dst[1] = src[1];
      dst[2] = src[2];
    }
  }
  return absl::OkStatus();
}

absl::Status CheckEncoded(const EncodedImage& image, const char* field) {
  if (image.bytes.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(field, " encoded image holds no bytes"));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status FillImages(const DisparityInput& disparity, const ColorInput& colour,
                        v1::Frame* frame) {
  v1::DisparityImage* d = frame->mutable_disparity();
  if (const auto* view = std::get_if<DisparityView>(&disparity)) {
    if (absl::Status s = FillRaw(*view, "disparity", d->mutable_raw()); !s.ok()) return s;
  } else {
    const auto& encoded = std::get<EncodedImage>(disparity);
    if (absl::Status s = CheckEncoded(encoded, "disparity"); !s.ok()) return s;
    d->set_encoded(encoded.bytes.data(), encoded.bytes.size());
  }

  v1::ColorImage* c = frame->mutable_colour();
  if (const auto* view = std::get_if<ColorView>(&colour)) {
    return FillRaw(*view, "colour", c->mutable_raw());
  }
  if (const auto* view = std::get_if<BgraView>(&colour)) {
    return FillBgra(*view, c->mutable_raw());
  }
  const auto& encoded = std::get<EncodedImage>(colour);
  if (absl::Status s = CheckEncoded(encoded, "colour"); !s.ok()) return s;
  c->set_encoded(encoded.bytes.data(), encoded.bytes.size());
  return absl::OkStatus();
}

void FillMeta(const FrameMeta& meta, std::uint64_t sequence, v1::Frame* frame) {
  frame->set_sequence(sequence);
  frame->set_capture_time_unix_ns(meta.capture_time_unix_ns != 0 ? meta.capture_time_unix_ns
                                                                 : UnixNanosNow());
  frame->set_frame_id(meta.frame_id);
}

}  // namespace internal
}  // namespace cloudcast::client
