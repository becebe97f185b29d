// Frame images from files or encoded bytes, through OpenCV's imgcodecs.
//
// Everything is decoded with IMREAD_UNCHANGED and converted here rather than by IMREAD_GRAYSCALE /
// IMREAD_COLOR, because those would silently squash a 16-bit or float disparity map to 8 bits and
// turn a colour file into a plausible-looking disparity map; converting here lets every rejection
// name its file and its reason.
#include "cloudcast/core/image_io.h"

#include <climits>
#include <cstring>
#include <exception>
#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <system_error>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/limits.h"

namespace cloudcast {
namespace {

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
  const Limits limits;
  const auto w = static_cast<std::uint64_t>(image.cols);
  const auto h = static_cast<std::uint64_t>(image.rows);
  if (image.dims != 2 || w == 0 || h == 0) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": is not a 2-D image"));
  }
  if (w > limits.max_side || h > limits.max_side || w * h > limits.max_pixels) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": is ", w, "x", h, "; the limits are ",
                                                   limits.max_side, " pixels per side and ",
                                                   limits.max_pixels, " pixels"));
  }
  return absl::OkStatus();
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

}  // namespace

absl::StatusOr<OwnedDisparity> LoadDisparity(const std::string& path) {
  const std::string what = absl::StrCat("disparity file '", path, "'");
  return Guarded(what, [&]() -> absl::StatusOr<OwnedDisparity> {
    auto image = ReadFile(path, what);
    if (!image.ok()) return image.status();
    return ToDisparity(*image, what);
  });
}

absl::StatusOr<OwnedDisparity> DecodeDisparity(std::string_view bytes) {
  const std::string what = "disparity bytes";
  return Guarded(what, [&]() -> absl::StatusOr<OwnedDisparity> {
    auto image = DecodeBytes(bytes, what);
    if (!image.ok()) return image.status();
    return ToDisparity(*image, what);
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

absl::StatusOr<OwnedColor> DecodeColor(std::string_view bytes) {
  const std::string what = "colour bytes";
  return Guarded(what, [&]() -> absl::StatusOr<OwnedColor> {
    auto image = DecodeBytes(bytes, what);
    if (!image.ok()) return image.status();
    return ToColor(*image, what);
  });
}

}  // namespace cloudcast
