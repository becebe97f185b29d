// A proto Frame as the core's image views: raw images viewed in place, encoded ones decoded.
#pragma once

#include <cstdint>

#include "absl/status/status.h"
#include "cloudcast/core/frame_codec.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/limits.h"
#include "cloudcast/io/image_io.h"
#include "cloudcast/v1/cloudcast.pb.h"
#include "request_reader.h"

namespace cloudcast::server {

// What gives a frame's points their depth (the proto's Frame.geometry).
enum class FrameKind : std::uint8_t {
  kDisparity,  // a disparity map
  kDepth,      // a depth image
  kStereo,     // the right image of a stereo pair; `colour` is the left one
};

// The images of one frame as the core reads them.
struct FrameImages {
  FrameKind kind = FrameKind::kDisparity;
  DisparityView disparity;  // kDisparity
  DepthView depth;          // kDepth
  ColorView colour;         // the reference (left) camera's image, always
  ColorView right;          // kStereo
  // at least one image came encoded (PNG, JPEG, ...) or compressed, and was decoded
  bool decoded = false;
};

// Where the rows of a raw image in pieces are: in place where a row lies inside one piece, else
// in `bounce` (the rows that straddle two pieces, copied: a few in a hundred).
struct RowTable {
  std::vector<const std::uint8_t*> rows;
  std::vector<std::uint8_t> bounce;
};

// Decoded pixels, kept by a worker from frame to frame.
struct DecodeScratch {
  RowTable disparity_rows, depth_rows, colour_rows, right_rows;
  OwnedDisparity disparity;
  OwnedDepth depth;
  OwnedColor colour, right;
  // Compressed images: buffers that grow to the largest frame seen and are then reused.
  PlaneDecompressor disparity_codec, depth_codec, colour_codec, right_codec;
};

// Fills `out` from `frame`. Raw images are viewed in place, without a copy: the views point into
// `frame`'s bytes, which must outlive them (convert::ViewRaw). Encoded images are decoded into
// `scratch` once their header's size has been checked (CheckEncodedImage); compressed images are
// decompressed into `scratch` once their size and payload header have been checked
// (convert::DecodeCompressed).
//
// Errors name the field by its proto path under "frame." and the limit it broke:
// RESOURCE_EXHAUSTED for an image over `limits`, INVALID_ARGUMENT for anything malformed.
//
// `in_place`: the pixels RequestReader left in gRPC's slices, for a frame it parsed. A raw image
// whose pixels are there is viewed through a row table in `scratch` (ImageView::rows).
absl::Status PrepareFrameImages(const v1::Frame& frame, const Limits& limits,
                                DecodeScratch* scratch, FrameImages* out,
                                const InPlacePixels* in_place = nullptr);

// The frame's size in pixels as its message states it (raw sizes, or an encoded image's header),
// without decoding anything: the cost the worker pool weighs it by. 1 when it cannot tell (such
// a frame is refused quickly anyway).
std::uint64_t FramePixels(const v1::Frame& frame);

}  // namespace cloudcast::server
