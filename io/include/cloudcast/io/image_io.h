// Loading a frame's images from files and from encoded bytes (PNG, JPEG, TIFF) with OpenCV.
// Kept apart from the pipeline so the hot path never sees OpenCV.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/limits.h"

namespace cloudcast {

// An image that owns its pixels, tightly packed rows.
template <typename Encoding>
struct OwnedImage {
  std::vector<std::uint8_t> pixels;
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  Encoding encoding{};

  ImageView<Encoding> view() const {
    ImageView<Encoding> v;
    v.data = pixels.data();
    v.size_bytes = pixels.size();
    v.width = width;
    v.height = height;
    v.stride_bytes = static_cast<std::size_t>(width) * BytesPerPixel(encoding);
    v.encoding = encoding;
    return v;
  }
};
using OwnedDisparity = OwnedImage<DisparityEncoding>;
using OwnedDepth = OwnedImage<DepthEncoding>;
using OwnedColor = OwnedImage<ColorEncoding>;

// A disparity map from a file: 8-bit -> kU8, 16-bit unsigned -> kU16, 32-bit float (TIFF, PFM)
// -> kF32, values unchanged. Multi-channel files and other sample types are rejected (a disparity
// map has one channel).
//
// Errors name the file (or `field` for bytes) and the reason: NotFound for a missing file,
// InvalidArgument for undecodable data, wrong channels or sample type, ResourceExhausted for a
// size over Limits{}. Bytes from the network: check them with CheckEncodedImage first.
absl::StatusOr<OwnedDisparity> LoadDisparity(const std::string& path);
absl::StatusOr<OwnedDisparity> DecodeDisparity(std::string_view bytes,
                                               std::string_view field = "disparity bytes");
// A depth image from a file: 16-bit unsigned (PNG, TIFF, PGM: what depth cameras record) ->
// kU16, 32-bit float (TIFF, PFM) -> kF32, values unchanged; other types and several channels
// are refused. Errors as for LoadDisparity.
absl::StatusOr<OwnedDepth> LoadDepth(const std::string& path);
absl::StatusOr<OwnedDepth> DecodeDepth(std::string_view bytes,
                                       std::string_view field = "depth bytes");
// A colour image as BGR8, or mono8 when the file is grey. Alpha is dropped, not composited (New
// Tsukuba's colour PNGs are RGBA with alpha down to 0); 16-bit samples become v / 257, rounded.
// Errors as for LoadDisparity.
absl::StatusOr<OwnedColor> LoadColor(const std::string& path);
absl::StatusOr<OwnedColor> DecodeColor(std::string_view bytes,
                                       std::string_view field = "colour bytes");

// Width and height from a PNG, JPEG, TIFF (first image), PNM (P1..P6) or PFM header, without
// decoding. False for any other format, or a header cut short. `format` gets "PNG", "JPEG",
// "TIFF", "PNM" or "PFM".
bool SniffImageSize(std::string_view bytes, std::uint32_t* width, std::uint32_t* height,
                    const char** format);

// Checks encoded bytes before a decoder allocates anything for them: not empty, a format whose
// header gives the size (a decoder allocates whatever an unchecked header claims, and OpenCV
// allows 2^30 pixels), and that size within `limits` (RESOURCE_EXHAUSTED). Errors name `field`.
// `format`, when given, gets the format's name as SniffImageSize gives it.
absl::Status CheckEncodedImage(std::string_view bytes, std::string_view field, const Limits& limits,
                               const char** format = nullptr);

}  // namespace cloudcast
