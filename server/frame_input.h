// A proto Frame as the core's image views, checked field by field.
#pragma once

#include <cstdint>
#include <string_view>

#include "absl/status/status.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/image_io.h"
#include "cloudcast/core/limits.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace cloudcast::server {

// The images of one frame as the core reads them.
struct FrameImages {
  DisparityView disparity;
  ColorView colour;
  bool decoded = false;  // at least one image came encoded (PNG, JPEG, ...) and was decoded
};

// Decoded pixels, kept by a worker from frame to frame.
struct DecodeScratch {
  OwnedDisparity disparity;
  OwnedColor colour;
};

// Fills `out` from `frame`. Raw images are viewed in place, without a copy: the views point into
// `frame`'s bytes, which must outlive them. Encoded images are decoded into `scratch` (their size
// is read from the file's header and checked before anything is decoded; formats whose header
// SniffImageSize cannot read are refused).
//
// Errors name the field by its proto path under "frame." and the limit it broke:
// RESOURCE_EXHAUSTED for an image over `limits`, INVALID_ARGUMENT for anything malformed
// (missing image, unknown encoding, zero size, short row_stride or pixel buffer, undecodable
// bytes, a multi-channel disparity file, disparity and colour of different sizes).
absl::Status PrepareFrameImages(const v1::Frame& frame, const Limits& limits,
                                DecodeScratch* scratch, FrameImages* out);

// Width and height from a PNG, JPEG, TIFF (first image), PNM (P1..P6) or PFM header, without
// decoding. False for any other format, or a header cut short. `format` gets "PNG", "JPEG",
// "TIFF", "PNM" or "PFM". Encoded images are only decoded when this knows their size: a decoder
// allocates whatever a header claims.
bool SniffImageSize(std::string_view bytes, std::uint32_t* width, std::uint32_t* height,
                    const char** format);

}  // namespace cloudcast::server
