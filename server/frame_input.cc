#include "frame_input.h"

#include <algorithm>
#include <cctype>
#include <string>

#include "absl/strings/str_cat.h"

namespace cloudcast::server {
namespace {

constexpr char kSupportedImageFormats[] = "png, jpeg, tiff, pnm, pfm";

std::uint32_t BigEndian32(const unsigned char* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) |
         std::uint32_t{p[3]};
}
std::uint32_t BigEndian16(const unsigned char* p) {
  return (std::uint32_t{p[0]} << 8) | std::uint32_t{p[1]};
}

// Size limits are RESOURCE_EXHAUSTED: the frame is well formed, only too big for this server.
absl::Status CheckSizeLimits(const std::string& field, std::uint32_t w, std::uint32_t h,
                             const Limits& limits) {
  if (w > limits.max_side || h > limits.max_side) {
    return absl::ResourceExhaustedError(absl::StrCat(field, " is ", w, "x", h, "; the limit is ",
                                                     limits.max_side, " pixels per side"));
  }
  const std::uint64_t pixels = std::uint64_t{w} * h;
  if (pixels > limits.max_pixels) {
    return absl::ResourceExhaustedError(absl::StrCat(field, " is ", w, "x", h, " = ", pixels,
                                                     " pixels; the limit is ", limits.max_pixels,
                                                     " pixels (width x height)"));
  }
  return absl::OkStatus();
}

bool ToCore(v1::DisparityEncoding e, DisparityEncoding* out) {
  switch (e) {
    case v1::DISPARITY_U8:
      *out = DisparityEncoding::kU8;
      return true;
    case v1::DISPARITY_U16:
      *out = DisparityEncoding::kU16;
      return true;
    case v1::DISPARITY_F32:
      *out = DisparityEncoding::kF32;
      return true;
    default:
      return false;
  }
}

bool ToCore(v1::ColorEncoding e, ColorEncoding* out) {
  switch (e) {
    case v1::COLOR_BGR8:
      *out = ColorEncoding::kBGR8;
      return true;
    case v1::COLOR_RGB8:
      *out = ColorEncoding::kRGB8;
      return true;
    case v1::COLOR_RGBA8:
      *out = ColorEncoding::kRGBA8;
      return true;
    case v1::COLOR_MONO8:
      *out = ColorEncoding::kMono8;
      return true;
    default:
      return false;
  }
}

std::string EncodingName(v1::DisparityEncoding e) {
  const std::string& name = v1::DisparityEncoding_Name(e);
  return name.empty() ? std::to_string(static_cast<int>(e)) : name;
}
std::string EncodingName(v1::ColorEncoding e) {
  const std::string& name = v1::ColorEncoding_Name(e);
  return name.empty() ? std::to_string(static_cast<int>(e)) : name;
}

// RawDisparity and RawColor have the same fields; `field` is e.g. "frame.disparity.raw".
template <typename Raw, typename CoreEncoding>
absl::Status ViewRaw(const Raw& raw, const std::string& field, const std::string& known,
                     const Limits& limits, ImageView<CoreEncoding>* view) {
  CoreEncoding encoding;
  if (!ToCore(raw.encoding(), &encoding)) {
    return absl::InvalidArgumentError(absl::StrCat(
        field, ".encoding is ", EncodingName(raw.encoding()), "; it must be one of ", known));
  }
  if (raw.width() == 0 || raw.height() == 0) {
    return absl::InvalidArgumentError(absl::StrCat(field, ".",
                                                   raw.width() == 0 ? "width" : "height",
                                                   " is 0; an image has at least 1x1 pixels"));
  }
  if (auto s = CheckSizeLimits(field, raw.width(), raw.height(), limits); !s.ok()) return s;
  const std::uint64_t bpp = BytesPerPixel(encoding);
  const std::uint64_t row_bytes = raw.width() * bpp;
  std::uint64_t stride = raw.row_stride();
  if (stride == 0) {
    stride = row_bytes;
  } else if (stride < row_bytes) {
    return absl::InvalidArgumentError(absl::StrCat(field, ".row_stride is ", stride,
                                                   ", less than width x ", bpp, " = ", row_bytes));
  }
  const std::uint64_t needed = stride * (raw.height() - 1) + row_bytes;
  if (raw.pixels().size() < needed) {
    return absl::InvalidArgumentError(absl::StrCat(
        field, ".pixels holds ", raw.pixels().size(), " bytes; ", raw.width(), "x", raw.height(),
        " ", EncodingName(raw.encoding()), " with row_stride ", stride, " needs ", needed));
  }
  view->data = raw.pixels().data();
  view->size_bytes = raw.pixels().size();
  view->width = raw.width();
  view->height = raw.height();
  view->stride_bytes = static_cast<std::size_t>(stride);
  view->encoding = encoding;
  return absl::OkStatus();
}

// The core names its input "disparity bytes" / "colour bytes"; the client knows the field.
absl::Status Rename(const absl::Status& s, const std::string& core_name, const std::string& field) {
  std::string message(s.message());
  if (message.rfind(core_name, 0) == 0) {
    message.replace(0, core_name.size(), field);
  } else {
    message = absl::StrCat(field, ": ", message);
  }
  return absl::Status(s.code(), message);
}

// Checks the header's size before a decoder allocates anything for it.
absl::Status CheckEncodedSize(std::string_view bytes, const std::string& field,
                              const Limits& limits) {
  if (bytes.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(field, " is empty"));
  }
  std::uint32_t w = 0, h = 0;
  const char* format = nullptr;
  if (!SniffImageSize(bytes, &w, &h, &format)) {
    // A decoder would allocate whatever an unchecked header claims (OpenCV allows 2^30 pixels),
    // so only formats whose size is known beforehand are decoded.
    return absl::InvalidArgumentError(
        absl::StrCat(field, " is not a PNG, JPEG, TIFF, PNM or PFM image (", kSupportedImageFormats,
                     "), or its header is cut short"));
  }
  if (w == 0 || h == 0) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, " is a ", format, " of ", w, "x", h, " pixels"));
  }
  return CheckSizeLimits(absl::StrCat(field, " (", format, ")"), w, h, limits);
}

}  // namespace

bool SniffImageSize(std::string_view bytes, std::uint32_t* width, std::uint32_t* height,
                    const char** format) {
  const auto* p = reinterpret_cast<const unsigned char*>(bytes.data());
  const std::size_t n = bytes.size();
  static const unsigned char kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  if (n >= 24 && std::equal(kPng, kPng + 8, p)) {
    // The first chunk must be IHDR: length (4), "IHDR", width (4), height (4), big endian.
    if (std::string_view(bytes.data() + 12, 4) != "IHDR") return false;
    *width = BigEndian32(p + 16);
    *height = BigEndian32(p + 20);
    *format = "PNG";
    return true;
  }
  if (n >= 4 && p[0] == 0xFF && p[1] == 0xD8) {
    // Walk the marker segments up to the first start-of-frame, which holds the size.
    std::size_t i = 2;
    while (i + 4 <= n) {
      if (p[i] != 0xFF) return false;
      const unsigned char marker = p[i + 1];
      if (marker == 0xFF) {  // fill byte
        ++i;
        continue;
      }
      if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD9)) {  // no length field
        i += 2;
        continue;
      }
      const std::uint32_t length = BigEndian16(p + i + 2);
      const bool sof =
          marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
      if (sof) {
        if (i + 9 > n) return false;
        *height = BigEndian16(p + i + 5);
        *width = BigEndian16(p + i + 7);
        *format = "JPEG";
        return true;
      }
      if (length < 2) return false;
      i += 2 + length;
    }
    return false;
  }
  const bool tiff_le = n >= 8 && p[0] == 'I' && p[1] == 'I' && p[2] == 42 && p[3] == 0;
  const bool tiff_be = n >= 8 && p[0] == 'M' && p[1] == 'M' && p[2] == 0 && p[3] == 42;
  if (tiff_le || tiff_be) {
    // The first image file directory: a count, then 12-byte entries (tag, type, count, value);
    // ImageWidth is tag 256, ImageLength tag 257, each a SHORT (3) or LONG (4).
    auto u16 = [&](std::size_t i) {
      return tiff_le ? std::uint32_t{p[i]} | std::uint32_t{p[i + 1]} << 8 : BigEndian16(p + i);
    };
    auto u32 = [&](std::size_t i) {
      return tiff_le ? u16(i) | u16(i + 2) << 16 : BigEndian32(p + i);
    };
    const std::size_t ifd = u32(4);
    if (ifd + 2 > n) return false;
    const std::size_t entries = u16(ifd);
    bool have_width = false, have_height = false;
    for (std::size_t e = 0; e < entries; ++e) {
      const std::size_t at = ifd + 2 + 12 * e;
      if (at + 12 > n) return false;
      const std::uint32_t tag = u16(at);
      const std::uint32_t type = u16(at + 2);
      if (tag != 256 && tag != 257) continue;
      if (type != 3 && type != 4) return false;
      const std::uint32_t value = type == 3 ? u16(at + 8) : u32(at + 8);
      if (tag == 256) {
        *width = value;
        have_width = true;
      } else {
        *height = value;
        have_height = true;
      }
    }
    if (!have_width || !have_height) return false;
    *format = "TIFF";
    return true;
  }
  if (n >= 3 && p[0] == 'P' && ((p[1] >= '1' && p[1] <= '6') || p[1] == 'f' || p[1] == 'F')) {
    // Netpbm and PFM: the magic, then width and height in ASCII, with # comments in between.
    std::size_t i = 2;
    auto number = [&](std::uint32_t* out) {
      for (;;) {
        while (i < n && std::isspace(p[i])) ++i;
        if (i < n && p[i] == '#') {
          while (i < n && p[i] != '\n') ++i;
          continue;
        }
        break;
      }
      if (i >= n || !std::isdigit(p[i])) return false;
      std::uint64_t v = 0;
      while (i < n && std::isdigit(p[i])) {
        v = v * 10 + (p[i++] - '0');
        if (v > 0xFFFFFFFFu) return false;
      }
      *out = static_cast<std::uint32_t>(v);
      return true;
    };
    if (!std::isspace(p[2]) && p[2] != '#') return false;
    if (!number(width) || !number(height)) return false;
    *format = p[1] == 'f' || p[1] == 'F' ? "PFM" : "PNM";
    return true;
  }
  return false;
}

absl::Status PrepareFrameImages(const v1::Frame& frame, const Limits& limits,
                                DecodeScratch* scratch, FrameImages* out) {
  out->decoded = false;
  switch (frame.disparity().data_case()) {
    case v1::DisparityImage::kRaw:
      if (auto s = ViewRaw(frame.disparity().raw(), "frame.disparity.raw",
                           "DISPARITY_U8, DISPARITY_U16, DISPARITY_F32", limits, &out->disparity);
          !s.ok()) {
        return s;
      }
      break;
    case v1::DisparityImage::kEncoded: {
      const std::string field = "frame.disparity.encoded";
      if (auto s = CheckEncodedSize(frame.disparity().encoded(), field, limits); !s.ok()) return s;
      auto decoded = DecodeDisparity(frame.disparity().encoded());
      if (!decoded.ok()) return Rename(decoded.status(), "disparity bytes", field);
      scratch->disparity = *std::move(decoded);
      out->disparity = scratch->disparity.view();
      out->decoded = true;
      // Formats the header check cannot read (TIFF, ...) are checked once decoded.
      if (auto s = CheckSizeLimits(field, out->disparity.width, out->disparity.height, limits);
          !s.ok()) {
        return s;
      }
      break;
    }
    default:
      return absl::InvalidArgumentError(
          "frame.disparity is missing: set frame.disparity.raw or frame.disparity.encoded");
  }
  switch (frame.colour().data_case()) {
    case v1::ColorImage::kRaw:
      if (auto s =
              ViewRaw(frame.colour().raw(), "frame.colour.raw",
                      "COLOR_BGR8, COLOR_RGB8, COLOR_RGBA8, COLOR_MONO8", limits, &out->colour);
          !s.ok()) {
        return s;
      }
      break;
    case v1::ColorImage::kEncoded: {
      const std::string field = "frame.colour.encoded";
      if (auto s = CheckEncodedSize(frame.colour().encoded(), field, limits); !s.ok()) return s;
      auto decoded = DecodeColor(frame.colour().encoded());
      if (!decoded.ok()) return Rename(decoded.status(), "colour bytes", field);
      scratch->colour = *std::move(decoded);
      out->colour = scratch->colour.view();
      out->decoded = true;
      if (auto s = CheckSizeLimits(field, out->colour.width, out->colour.height, limits); !s.ok()) {
        return s;
      }
      break;
    }
    default:
      return absl::InvalidArgumentError(
          "frame.colour is missing: set frame.colour.raw or frame.colour.encoded");
  }
  if (out->disparity.width != out->colour.width || out->disparity.height != out->colour.height) {
    return absl::InvalidArgumentError(absl::StrCat(
        "frame.colour is ", out->colour.width, "x", out->colour.height, " but frame.disparity is ",
        out->disparity.width, "x", out->disparity.height, "; they must be the same size"));
  }
  return absl::OkStatus();
}

}  // namespace cloudcast::server
