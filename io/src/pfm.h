// PFM (Portable Float Map) read from memory.
//
// OpenCV 4.6 reads PFM only from a file: cv::imdecode writes the bytes to a temporary file first,
// and leaves it behind when the header does not read as it expects. Frames arrive from the
// network, so a server must not touch its disk for them; this reads them in memory, to the same
// cv::Mat OpenCV gives for the same file (tests/image_io_test.cc checks bit for bit).
#pragma once

#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <string_view>

namespace cloudcast::pfm {

// "Pf" (one channel) or "PF" (RGB), a line break, then width, height and scale, each in ASCII and
// each ended by one whitespace byte; then rows of 32-bit floats, the bottom row first,
// little-endian when the scale is negative. The grammar is OpenCV's, without what OpenCV reads
// differently from other readers (comments, runs of whitespace, numbers with trailing letters).
struct Header {
  int channels = 0;
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  float scale = 0;                // finite, not 0; pixels are divided by |scale|
  std::size_t pixels_offset = 0;  // where the bottom row starts
};

// True when `bytes` start as a PFM does (OpenCV's signature: "Pf" or "PF" and a whitespace byte).
bool LooksLikePfm(std::string_view bytes);

// The header, or why there is none ("its height is not a number", ...).
std::optional<Header> ReadHeader(std::string_view bytes, std::string* problem);

// The image as cv::imread gives it for the same file: CV_32FC1, or CV_32FC3 in BGR order.
// Throws nothing; `problem` says why it failed (a bad header, pixels cut short).
std::optional<cv::Mat> Decode(std::string_view bytes, std::string* problem);

}  // namespace cloudcast::pfm
