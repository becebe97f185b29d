#include "pfm.h"

#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <opencv2/imgproc.hpp>

#include "absl/strings/str_cat.h"

namespace cloudcast::pfm {
namespace {

// One token up to the whitespace byte that ends it; nullopt when the bytes end first or the
// token is empty (two whitespace bytes in a row, which OpenCV reads as the number 0).
std::optional<std::string_view> Token(std::string_view bytes, std::size_t* at) {
  const std::size_t start = *at;
  std::size_t i = start;
  while (i < bytes.size() && !std::isspace(static_cast<unsigned char>(bytes[i]))) ++i;
  if (i == start || i >= bytes.size()) return std::nullopt;
  *at = i + 1;  // past the one whitespace byte
  return bytes.substr(start, i - start);
}

std::optional<std::uint32_t> Dimension(std::string_view token) {
  // OpenCV reads it with atoi, so at most 9 digits keep every accepted value an int.
  if (token.empty() || token.size() > 9) return std::nullopt;
  std::uint32_t v = 0;
  for (char c : token) {
    if (c < '0' || c > '9') return std::nullopt;
    v = v * 10 + static_cast<std::uint32_t>(c - '0');
  }
  return v;
}

std::optional<float> Scale(std::string_view token) {
  if (token.size() > 64) return std::nullopt;
  const std::string text(token);
  char* end = nullptr;
  const float v = std::strtof(text.c_str(), &end);
  if (end != text.c_str() + text.size() || !std::isfinite(v) || v == 0.0f) return std::nullopt;
  return v;
}

bool HostIsLittleEndian() {
  const std::uint32_t one = 1;
  unsigned char first;
  std::memcpy(&first, &one, 1);
  return first == 1;
}

}  // namespace

bool LooksLikePfm(std::string_view bytes) {
  return bytes.size() >= 3 && bytes[0] == 'P' && (bytes[1] == 'f' || bytes[1] == 'F') &&
         std::isspace(static_cast<unsigned char>(bytes[2]));
}

std::optional<Header> ReadHeader(std::string_view bytes, std::string* problem) {
  if (!LooksLikePfm(bytes)) {
    *problem = "does not start with Pf or PF";
    return std::nullopt;
  }
  if (bytes[2] != '\n') {
    *problem = "has no line break after Pf or PF";
    return std::nullopt;
  }
  Header header;
  header.channels = bytes[1] == 'F' ? 3 : 1;
  std::size_t at = 3;
  const auto width = Token(bytes, &at);
  const auto w = width ? Dimension(*width) : std::nullopt;
  if (!w) {
    *problem = "has no width (digits and one space or line break) after its magic";
    return std::nullopt;
  }
  const auto height = Token(bytes, &at);
  const auto h = height ? Dimension(*height) : std::nullopt;
  if (!h) {
    *problem = "has no height (digits and one space or line break) after its width";
    return std::nullopt;
  }
  const auto scale = Token(bytes, &at);
  const auto s = scale ? Scale(*scale) : std::nullopt;
  if (!s) {
    *problem = "has no scale (a finite number other than 0, then a line break) after its height";
    return std::nullopt;
  }
  header.width = *w;
  header.height = *h;
  header.scale = *s;
  header.pixels_offset = at;
  return header;
}

std::optional<cv::Mat> Decode(std::string_view bytes, std::string* problem) {
  const std::optional<Header> header = ReadHeader(bytes, problem);
  if (!header) return std::nullopt;
  if (header->width == 0 || header->height == 0) {
    *problem = absl::StrCat("is ", header->width, "x", header->height, " pixels");
    return std::nullopt;
  }
  const std::size_t row_bytes = std::size_t{header->width} * header->channels * sizeof(float);
  const std::size_t need = row_bytes * header->height;
  if (bytes.size() - header->pixels_offset < need) {
    *problem =
        absl::StrCat("is cut short: ", header->width, "x", header->height, " pixels need ", need,
                     " bytes after the header, it has ", bytes.size() - header->pixels_offset);
    return std::nullopt;
  }
  cv::Mat image(static_cast<int>(header->height), static_cast<int>(header->width),
                header->channels == 3 ? CV_32FC3 : CV_32FC1);
  // A positive scale means big-endian samples.
  const bool swap = (header->scale >= 0) == HostIsLittleEndian();
  const char* row = bytes.data() + header->pixels_offset;
  for (int y = image.rows - 1; y >= 0; --y, row += row_bytes) {  // bottom row first
    std::memcpy(image.ptr(y), row, row_bytes);
    if (swap) {
      auto* words = image.ptr<std::uint32_t>(y);
      for (std::size_t i = 0; i < row_bytes / 4; ++i) words[i] = __builtin_bswap32(words[i]);
    }
  }
  if (image.channels() == 3) cv::cvtColor(image, image, cv::COLOR_RGB2BGR);
  // OpenCV divides by |scale| as `image *= 1.f / fabs(scale)`, in double: so here, so that the
  // bits agree. A scale of +-1 leaves every sample as it is.
  if (std::fabs(header->scale) != 1.0f)
    image *= 1.0 / std::fabs(static_cast<double>(header->scale));
  return image;
}

}  // namespace cloudcast::pfm
