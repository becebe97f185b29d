// RVL (Wilson, "Fast Lossless Depth Image Compression", ISS 2017): lossless compression of 8- or
// 16-bit depth and disparity images in one pass, no entropy coder. Runs of zeros (no measurement)
// and of non-zero pixels alternate; each non-zero pixel is its difference from the previous
// non-zero pixel, zig-zagged; every number is written in 4-bit groups (3 bits of value and a
// continuation bit), packed into 32-bit words. Measured against the uplink's row deltas + zstd in
// cloudcast-video-bench --depth (docs/video.md).
//
// The bytes: a 12-byte header (magic "RVL1", width and height as little-endian uint32) and the
// words (little-endian uint32).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "cloudcast/core/limits.h"

namespace cloudcast::video {

// `pixels` is width x height samples, row-major without padding. Replaces `out`.
void EncodeRvl(const std::uint16_t* pixels, std::uint32_t width, std::uint32_t height,
               std::string* out);
void EncodeRvl(const std::uint8_t* pixels, std::uint32_t width, std::uint32_t height,
               std::string* out);

// Decodes into `out` (resized to width x height, which must be what the header says: the caller
// knows the frame's size). Every value is checked against `max_value` (255 for 8-bit images,
// 65535 for 16-bit), every run against the pixels left, and the words against the bytes given:
// INVALID_ARGUMENT naming `field`. The size is checked against `limits` before `out` grows.
absl::Status DecodeRvl(std::string_view bytes, std::uint32_t width, std::uint32_t height,
                       std::uint32_t max_value, const Limits& limits, std::string_view field,
                       std::vector<std::uint16_t>* out);

}  // namespace cloudcast::video
