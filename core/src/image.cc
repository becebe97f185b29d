#include "cloudcast/core/image.h"

#include <string>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/checks.h"

namespace cloudcast {

std::size_t BytesPerPixel(DisparityEncoding e) {
  switch (e) {
    case DisparityEncoding::kU8:
      return 1;
    case DisparityEncoding::kU16:
      return 2;
    case DisparityEncoding::kF32:
      return 4;
  }
  return 0;
}

std::size_t BytesPerPixel(DepthEncoding e) {
  switch (e) {
    case DepthEncoding::kU16:
      return 2;
    case DepthEncoding::kF32:
      return 4;
  }
  return 0;
}

std::size_t BytesPerPixel(ColorEncoding e) {
  switch (e) {
    case ColorEncoding::kBGR8:
      return 3;
    case ColorEncoding::kRGB8:
      return 3;
    case ColorEncoding::kRGBA8:
      return 4;
    case ColorEncoding::kMono8:
      return 1;
  }
  return 0;
}

std::string_view Name(DisparityEncoding e) {
  switch (e) {
    case DisparityEncoding::kU8:
      return "u8";
    case DisparityEncoding::kU16:
      return "u16";
    case DisparityEncoding::kF32:
      return "f32";
  }
  return "?";
}

std::string_view Name(DepthEncoding e) {
  switch (e) {
    case DepthEncoding::kU16:
      return "u16";
    case DepthEncoding::kF32:
      return "f32";
  }
  return "?";
}

std::string_view Name(ColorEncoding e) {
  switch (e) {
    case ColorEncoding::kBGR8:
      return "bgr8";
    case ColorEncoding::kRGB8:
      return "rgb8";
    case ColorEncoding::kRGBA8:
      return "rgba8";
    case ColorEncoding::kMono8:
      return "mono8";
  }
  return "?";
}

bool ParseDisparityEncoding(std::string_view name, DisparityEncoding* out) {
  for (auto e : {DisparityEncoding::kU8, DisparityEncoding::kU16, DisparityEncoding::kF32}) {
    if (Name(e) == name) {
      *out = e;
      return true;
    }
  }
  return false;
}

bool ParseDepthEncoding(std::string_view name, DepthEncoding* out) {
  for (auto e : {DepthEncoding::kU16, DepthEncoding::kF32}) {
    if (Name(e) == name) {
      *out = e;
      return true;
    }
  }
  return false;
}

bool ParseColorEncoding(std::string_view name, ColorEncoding* out) {
  for (auto e :
       {ColorEncoding::kBGR8, ColorEncoding::kRGB8, ColorEncoding::kRGBA8, ColorEncoding::kMono8}) {
    if (Name(e) == name) {
      *out = e;
      return true;
    }
  }
  return false;
}

namespace {

template <typename Encoding>
absl::Status ValidateAny(const ImageView<Encoding>& v, const Limits& limits,
                         std::string_view field_name, const ImageFieldNames& names) {
  // Debian's Abseil has its own string_view, which StrCat takes; std::string converts to both.
  const std::string field(field_name);
  const std::string stride = field + "." + std::string(names.stride);
  const std::string buffer = field + "." + std::string(names.buffer);
  const std::size_t bpp = BytesPerPixel(v.encoding);
  if (bpp == 0) {
    return absl::InvalidArgumentError(absl::StrCat(field, ".encoding is not a known encoding (",
                                                   static_cast<int>(v.encoding), ")"));
  }
  if (absl::Status s = check::ImageSize(field, v.width, v.height, limits); !s.ok()) return s;
  if (v.data == nullptr) return absl::InvalidArgumentError(absl::StrCat(buffer, " is null"));
  const std::uint64_t row_bytes = std::uint64_t{v.width} * bpp;
  if (v.stride_bytes < row_bytes) {
    return absl::InvalidArgumentError(absl::StrCat(stride, " is ", v.stride_bytes,
                                                   ", less than width x ", bpp, " = ", row_bytes));
  }
  const std::uint64_t needed = std::uint64_t{v.stride_bytes} * (v.height - 1) + row_bytes;
  if (v.size_bytes < needed) {
    return absl::InvalidArgumentError(
        absl::StrCat(buffer, " holds ", v.size_bytes, " bytes; ", v.width, "x", v.height, " ",
                     std::string(names.encoding.empty() ? Name(v.encoding) : names.encoding),
                     " with ", std::string(names.stride), " ", v.stride_bytes, " needs ", needed));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status ValidateView(const DisparityView& view, const Limits& limits, std::string_view field,
                          const ImageFieldNames& names) {
  return ValidateAny(view, limits, field, names);
}

absl::Status ValidateView(const DepthView& view, const Limits& limits, std::string_view field,
                          const ImageFieldNames& names) {
  return ValidateAny(view, limits, field, names);
}

absl::Status ValidateView(const ColorView& view, const Limits& limits, std::string_view field,
                          const ImageFieldNames& names) {
  return ValidateAny(view, limits, field, names);
}

absl::Status CheckSameSize(std::uint32_t first_width, std::uint32_t first_height,
                           std::string_view first_field, std::uint32_t second_width,
                           std::uint32_t second_height, std::string_view second_field) {
  if (first_width != second_width || first_height != second_height) {
    return absl::InvalidArgumentError(
        absl::StrCat(std::string(second_field), " is ", second_width, "x", second_height, " but ",
                     std::string(first_field), " is ", first_width, "x", first_height,
                     "; they must be the same size"));
  }
  return absl::OkStatus();
}

absl::Status ValidateFrame(const DisparityView& disparity, const ColorView& colour,
                           const Limits& limits) {
  if (auto s = ValidateView(disparity, limits, "disparity"); !s.ok()) return s;
  if (auto s = ValidateView(colour, limits, "colour"); !s.ok()) return s;
  return CheckSameSize(disparity, "disparity", colour, "colour");
}

absl::Status ValidateFrame(const DepthView& depth, const ColorView& colour, const Limits& limits) {
  if (auto s = ValidateView(depth, limits, "depth"); !s.ok()) return s;
  if (auto s = ValidateView(colour, limits, "colour"); !s.ok()) return s;
  return CheckSameSize(depth, "depth", colour, "colour");
}

}  // namespace cloudcast
