// Frame images from files or encoded bytes, through OpenCV's imgcodecs.
//
// Everything is decoded with IMREAD_UNCHANGED and converted here rather than by IMREAD_GRAYSCALE /
// IMREAD_COLOR, because those would silently squash a 16-bit or float disparity map to 8 bits and
// turn a colour file into a plausible-looking disparity map; converting here lets every rejection
// name its file and its reason.
#include "cloudcast/io/image_io.h"

#include <cctype>
#include <climits>
#include <cstring>
#include <exception>
#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <string>
#include <system_error>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/checks.h"
#include "cloudcast/core/limits.h"
#include "pfm.h"

namespace cloudcast {
namespace {

constexpr char kSupportedImageFormats[] = "png, jpeg, tiff, pnm, pfm";

std::uint32_t BigEndian32(const unsigned char* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) |
         std::uint32_t{p[3]};
}
std::uint32_t BigEndian16(const unsigned char* p) {
  return (std::uint32_t{p[0]} << 8) | std::uint32_t{p[1]};
}

std::string DepthName(int depth) {
  switch (depth) {
    case CV_8U:
      return "8-bit unsigned";
    case CV_8S:
      return "8-bit signed";
    case CV_16U:
      return "16-bit unsigned";
    case CV_16S:
      return "16-bit signed";
    case CV_32S:
      return "32-bit integer";
    case CV_32F:
      return "32-bit float";
    case CV_64F:
      return "64-bit float";
    case CV_16F:
      return "16-bit float";
  }
  return absl::StrCat("depth ", depth);
}

// `what` names the source in every message: "disparity file 'a.png'" or "colour bytes".
absl::StatusOr<cv::Mat> ReadFile(const std::string& path, const std::string& what) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(status)) {
    return absl::NotFoundError(absl::StrCat(what, ": no such file"));
  }
  if (std::filesystem::is_directory(status)) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": is a directory, not an image"));
  }
  cv::Mat image;
  try {
    image = cv::imread(path, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    return absl::InvalidArgumentError(
        absl::StrCat(what, ": cannot be decoded as an image: ", e.what()));
  }
  if (image.empty()) {
    // imread says nothing about why: unreadable, empty, truncated or an unknown format.
    return absl::InvalidArgumentError(absl::StrCat(
        what, ": cannot be read or decoded as an image (PNG, JPEG, TIFF, PNM, PFM are supported)"));
  }
  return image;
}

absl::StatusOr<cv::Mat> DecodeBytes(std::string_view bytes, const std::string& what) {
  if (bytes.empty()) return absl::InvalidArgumentError(absl::StrCat(what, ": no bytes"));
  if (bytes.size() > static_cast<std::size_t>(INT_MAX)) {
    return absl::InvalidArgumentError(
        absl::StrCat(what, ": ", bytes.size(), " bytes is more than OpenCV can decode"));
  }
  if (pfm::LooksLikePfm(bytes)) {  // not through imdecode, which writes PFM bytes to /tmp
    std::string problem;
    std::optional<cv::Mat> decoded = pfm::Decode(bytes, &problem);
    if (!decoded) {
      return absl::InvalidArgumentError(absl::StrCat(what, ": a PFM image that ", problem));
    }
    return *std::move(decoded);
  }
  // imdecode only reads the buffer; the const_cast is what cv::Mat's constructor needs.
  const cv::Mat buffer(1, static_cast<int>(bytes.size()), CV_8U, const_cast<char*>(bytes.data()));
  cv::Mat image;
  try {
    image = cv::imdecode(buffer, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    return absl::InvalidArgumentError(
        absl::StrCat(what, ": cannot be decoded as an image: ", e.what()));
  }
  if (image.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(
        what, ": cannot be decoded as an image (PNG, JPEG, TIFF, PNM, PFM are supported)"));
  }
  return image;
}

// The decoder has already allocated the pixels, but checking here gives an error that names
// the file instead of one from deep inside the pipeline.
absl::Status CheckSize(const cv::Mat& image, const std::string& what) {
  if (image.dims != 2 || image.cols <= 0 || image.rows <= 0) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": is not a 2-D image"));
  }
  return check::ImageSize(what, static_cast<std::uint32_t>(image.cols),
                          static_cast<std::uint32_t>(image.rows), Limits{});
}

template <typename Encoding>
OwnedImage<Encoding> CopyPacked(const cv::Mat& image, Encoding encoding) {
  OwnedImage<Encoding> out;
  out.width = static_cast<std::uint32_t>(image.cols);
  out.height = static_cast<std::uint32_t>(image.rows);
  out.encoding = encoding;
  const std::size_t row_bytes = static_cast<std::size_t>(image.cols) * image.elemSize();
  out.pixels.resize(row_bytes * image.rows);
  // Row by row: a decoded Mat is normally continuous, a converted one need not be.
  for (int v = 0; v < image.rows; ++v) {
    std::memcpy(out.pixels.data() + row_bytes * v, image.ptr(v), row_bytes);
  }
  return out;
}

absl::StatusOr<OwnedDisparity> ToDisparity(const cv::Mat& image, const std::string& what) {
  if (auto s = CheckSize(image, what); !s.ok()) return s;
  if (image.channels() != 1) {
    return absl::InvalidArgumentError(
        absl::StrCat(what, ": has ", image.channels(),
                     " channels; a disparity map must have one (save it as grey, not colour)"));
  }
  switch (image.depth()) {
    case CV_8U:
      return CopyPacked(image, DisparityEncoding::kU8);
    case CV_16U:
      return CopyPacked(image, DisparityEncoding::kU16);
    case CV_32F:
      return CopyPacked(image, DisparityEncoding::kF32);
  }
  return absl::InvalidArgumentError(
      absl::StrCat(what, ": is ", DepthName(image.depth()),
                   "; a disparity map must be 8-bit, 16-bit unsigned or 32-bit float"));
}

absl::StatusOr<OwnedDepth> ToDepth(const cv::Mat& image, const std::string& what) {
  if (auto s = CheckSize(image, what); !s.ok()) return s;
  if (image.channels() != 1) {
    return absl::InvalidArgumentError(
        absl::StrCat(what, ": has ", image.channels(),
                     " channels; a depth image must have one (16UC1 or 32FC1)"));
  }
  switch (image.depth()) {
    case CV_16U:
      return CopyPacked(image, DepthEncoding::kU16);
    case CV_32F:
      return CopyPacked(image, DepthEncoding::kF32);
  }
  return absl::InvalidArgumentError(
      absl::StrCat(what, ": is ", DepthName(image.depth()),
                   "; a depth image must be 16-bit unsigned (millimetres) or 32-bit float"));
}

absl::StatusOr<OwnedColor> ToColor(const cv::Mat& image, const std::string& what) {
  if (auto s = CheckSize(image, what); !s.ok()) return s;
  cv::Mat eight_bit;
  switch (image.depth()) {
    case CV_8U:
      eight_bit = image;
      break;
    case CV_16U:
      // v16 / 257 inverts the usual v8 * 257 widening exactly and maps 65535 to 255.
      image.convertTo(eight_bit, CV_8U, 1.0 / 257.0);
      break;
    default:
      return absl::InvalidArgumentError(
          absl::StrCat(what, ": is ", DepthName(image.depth()),
                       "; a colour image must be 8-bit or 16-bit unsigned"));
  }
  cv::Mat bgr;
  switch (eight_bit.channels()) {
    case 1:
      return CopyPacked(eight_bit, ColorEncoding::kMono8);
    case 2: {
      // Grey + alpha: keep the grey, ignore alpha as for colour images.
      cv::Mat grey;
      cv::extractChannel(eight_bit, grey, 0);
      return CopyPacked(grey, ColorEncoding::kMono8);
    }
    case 3:
      return CopyPacked(eight_bit, ColorEncoding::kBGR8);
    case 4:
      // RGBA PNGs (New Tsukuba's colour images) keep their colour where alpha is 0; alpha is
      // dropped, not composited, as PCL ignores it too.
      cv::cvtColor(eight_bit, bgr, cv::COLOR_BGRA2BGR);
      return CopyPacked(bgr, ColorEncoding::kBGR8);
  }
  return absl::InvalidArgumentError(absl::StrCat(what, ": has ", eight_bit.channels(),
                                                 " channels; a colour image must have 1, 3 or 4"));
}

// Wraps a conversion so that no OpenCV exception (e.g. out of memory) escapes the Status API.
template <typename Fn>
auto Guarded(const std::string& what, Fn fn) -> decltype(fn()) {
  try {
    return fn();
  } catch (const std::exception& e) {
    return absl::InternalError(absl::StrCat(what, ": ", e.what()));
  }
}

// The first image file directory of a TIFF, as far as sizes go: what libtiff (through OpenCV)
// would allocate for. Nothing for anything that is not a classic TIFF or is cut short.
struct TiffDirectory {
  std::uint32_t width = 0, height = 0;
  bool have_width = false, have_height = false;
  std::uint32_t tile_width = 0, tile_height = 0;  // 0: not tiled
  // Why OpenCV could not be trusted with it (empty: nothing): libtiff keeps the first of two
  // equal tags where a reader of the last sees another size, and OpenCV allocates a whole tile
  // (up to 1 GB) whatever the image's size.
  std::string problem;
};

std::optional<TiffDirectory> ReadTiffDirectory(std::string_view bytes) {
  const auto* p = reinterpret_cast<const unsigned char*>(bytes.data());
  const std::size_t n = bytes.size();
  const bool le = n >= 8 && p[0] == 'I' && p[1] == 'I' && p[2] == 42 && p[3] == 0;
  const bool be = n >= 8 && p[0] == 'M' && p[1] == 'M' && p[2] == 0 && p[3] == 42;
  if (!le && !be) return std::nullopt;
  // The directory: a count, then 12-byte entries (tag, type, count, value); ImageWidth is tag
  // 256, ImageLength 257, TileWidth 322, TileLength 323, each a SHORT (3) or LONG (4).
  auto u16 = [&](std::size_t i) {
    return le ? std::uint32_t{p[i]} | std::uint32_t{p[i + 1]} << 8 : BigEndian16(p + i);
  };
  auto u32 = [&](std::size_t i) { return le ? u16(i) | u16(i + 2) << 16 : BigEndian32(p + i); };
  const std::size_t ifd = u32(4);
  if (ifd + 2 > n) return std::nullopt;
  const std::size_t entries = u16(ifd);
  TiffDirectory dir;
  std::uint32_t previous_tag = 0;
  for (std::size_t e = 0; e < entries; ++e) {
    const std::size_t at = ifd + 2 + 12 * e;
    if (at + 12 > n) return std::nullopt;
    const std::uint32_t tag = u16(at);
    const std::uint32_t type = u16(at + 2);
    if (e > 0 && tag <= previous_tag && dir.problem.empty()) {
      dir.problem = absl::StrCat("its directory's tags are not in ascending order (tag ", tag,
                                 " after ", previous_tag, "), as the TIFF specification requires");
    }
    previous_tag = tag;
    if (tag != 256 && tag != 257 && tag != 322 && tag != 323) continue;
    if (type != 3 && type != 4) return std::nullopt;
    const std::uint32_t value = type == 3 ? u16(at + 8) : u32(at + 8);
    switch (tag) {
      case 256:
        if (!dir.have_width) dir.width = value;  // libtiff keeps the first
        dir.have_width = true;
        break;
      case 257:
        if (!dir.have_height) dir.height = value;
        dir.have_height = true;
        break;
      case 322:
        dir.tile_width = value;
        break;
      case 323:
        dir.tile_height = value;
        break;
    }
  }
  // Tiles are multiples of 16 pixels (the spec); more than one tile's rounding past the image
  // buys nothing but memory.
  auto rounded = [](std::uint32_t side) { return (std::uint64_t{side} + 15) / 16 * 16; };
  if (dir.problem.empty() && (dir.tile_width != 0 || dir.tile_height != 0) &&
      (dir.tile_width > rounded(dir.width) || dir.tile_height > rounded(dir.height))) {
    dir.problem = absl::StrCat("its tiles (", dir.tile_width, "x", dir.tile_height,
                               ") are larger than the image (", dir.width, "x", dir.height,
                               ") rounded up to 16 pixels");
  }
  return dir;
}

}  // namespace

absl::StatusOr<OwnedDisparity> LoadDisparity(const std::string& path) {
  const std::string what = absl::StrCat("disparity file '", path, "'");
  return Guarded(what, [&]() -> absl::StatusOr<OwnedDisparity> {
    auto image = ReadFile(path, what);
    if (!image.ok()) return image.status();
    return ToDisparity(*image, what);
  });
}

absl::StatusOr<OwnedDisparity> DecodeDisparity(std::string_view bytes, std::string_view field) {
  const std::string what(field);
  return Guarded(what, [&]() -> absl::StatusOr<OwnedDisparity> {
    auto image = DecodeBytes(bytes, what);
    if (!image.ok()) return image.status();
    return ToDisparity(*image, what);
  });
}

absl::StatusOr<OwnedDepth> LoadDepth(const std::string& path) {
  const std::string what = absl::StrCat("depth file '", path, "'");
  return Guarded(what, [&]() -> absl::StatusOr<OwnedDepth> {
    auto image = ReadFile(path, what);
    if (!image.ok()) return image.status();
    return ToDepth(*image, what);
  });
}

absl::StatusOr<OwnedDepth> DecodeDepth(std::string_view bytes, std::string_view field) {
  const std::string what(field);
  return Guarded(what, [&]() -> absl::StatusOr<OwnedDepth> {
    auto image = DecodeBytes(bytes, what);
    if (!image.ok()) return image.status();
    return ToDepth(*image, what);
  });
}

absl::StatusOr<OwnedColor> LoadColor(const std::string& path) {
  const std::string what = absl::StrCat("colour file '", path, "'");
  return Guarded(what, [&]() -> absl::StatusOr<OwnedColor> {
    auto image = ReadFile(path, what);
    if (!image.ok()) return image.status();
    return ToColor(*image, what);
  });
}

absl::StatusOr<OwnedColor> DecodeColor(std::string_view bytes, std::string_view field) {
  const std::string what(field);
  return Guarded(what, [&]() -> absl::StatusOr<OwnedColor> {
    auto image = DecodeBytes(bytes, what);
    if (!image.ok()) return image.status();
    return ToColor(*image, what);
  });
}

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
  if (std::optional<TiffDirectory> tiff = ReadTiffDirectory(bytes)) {
    if (!tiff->have_width || !tiff->have_height) return false;
    *width = tiff->width;
    *height = tiff->height;
    *format = "TIFF";
    return true;
  }
  if (pfm::LooksLikePfm(bytes)) {
    std::string problem;
    const std::optional<pfm::Header> header = pfm::ReadHeader(bytes, &problem);
    if (!header) return false;
    *width = header->width;
    *height = header->height;
    *format = "PFM";
    return true;
  }
  if (n >= 3 && p[0] == 'P' && p[1] >= '1' && p[1] <= '6') {
    // Netpbm: the magic, then width and height in ASCII, with # comments in between.
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
    *format = "PNM";
    return true;
  }
  return false;
}

absl::Status CheckEncodedImage(std::string_view bytes, std::string_view field_name,
                               const Limits& limits, const char** format_out) {
  const std::string field(field_name);
  if (bytes.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(field, " is empty"));
  }
  std::uint32_t w = 0, h = 0;
  const char* format = nullptr;
  if (std::string problem; pfm::LooksLikePfm(bytes) && !pfm::ReadHeader(bytes, &problem)) {
    return absl::InvalidArgumentError(absl::StrCat(field, " is a PFM image that ", problem));
  }
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
  if (std::string_view(format) == "TIFF") {
    if (const std::string problem = ReadTiffDirectory(bytes)->problem; !problem.empty()) {
      return absl::InvalidArgumentError(absl::StrCat(field, " is a TIFF whose ", problem));
    }
  }
  if (format_out != nullptr) *format_out = format;
  return check::ImageSize(absl::StrCat(field, " (", format, ")"), w, h, limits);
}

}  // namespace cloudcast
