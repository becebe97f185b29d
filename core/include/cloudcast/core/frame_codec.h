// Lossless compression of raw image planes for the uplink: an optional predictor over the rows,
// then one zstd frame. Used by both sides: the client library compresses a view, the server
// decompresses into a buffer it keeps from frame to frame. No OpenCV, no PCL: only zstd.
//
// The compressed bytes of an image of width x height pixels of `bpp` bytes each are one zstd
// frame that declares its content size, width x height x bpp, and carries zstd's content checksum:
// the rows packed tightly, after the predictor. Predictors work on whole samples of the encoding (8
// bits for U8 disparity and every colour encoding, 16 for U16, the 32 bits of an F32 as an unsigned
// integer), modulo 2^bits, so they are exact for any value, NaN included:
//   kNone  the samples as they are;
//   kUp    each sample minus the same sample one row up (the first row as it is);
//   kLeft  each sample minus the same channel of the pixel on its left (the first column as it is).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/limits.h"

namespace cloudcast {

enum class Predictor : std::uint8_t { kNone, kUp, kLeft };
std::string_view Name(Predictor predictor);  // "none", "up", "left"

// zstd's compression levels: 1 (fast) .. 19; negative levels are faster still and smaller ratio.
// The default is the one the uplink table chose (README, cloudcast-uplink-bench).
inline constexpr int kDefaultCompressionLevel = 1;

// The layout of a plane as the codec sees it. `bpp` bytes per pixel made of `sample_bytes`-byte
// samples (1, 2 or 4).
struct PlaneLayout {
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  std::size_t bpp = 0;
  std::size_t sample_bytes = 1;

  std::uint64_t bytes() const { return std::uint64_t{width} * height * bpp; }
};
PlaneLayout LayoutOf(const DisparityView& view);
PlaneLayout LayoutOf(const DepthView& view);
PlaneLayout LayoutOf(const ColorView& view);
PlaneLayout LayoutOf(DisparityEncoding encoding, std::uint32_t width, std::uint32_t height);
PlaneLayout LayoutOf(DepthEncoding encoding, std::uint32_t width, std::uint32_t height);
PlaneLayout LayoutOf(ColorEncoding encoding, std::uint32_t width, std::uint32_t height);

// Compresses views. Keeps zstd's context and the predictor's row buffer, so same-sized frames
// allocate nothing after the first. Not thread-safe: one per sending thread.
class PlaneCompressor {
 public:
  PlaneCompressor();
  ~PlaneCompressor();
  PlaneCompressor(const PlaneCompressor&) = delete;
  PlaneCompressor& operator=(const PlaneCompressor&) = delete;

  // Replaces `out` with the compressed view (its capacity is kept). The view is checked for
  // memory safety only (ValidateView without limits); errors name it under `field`.
  absl::Status Compress(const DisparityView& view, Predictor predictor, int level,
                        std::string_view field, std::string* out);
  absl::Status Compress(const DepthView& view, Predictor predictor, int level,
                        std::string_view field, std::string* out);
  absl::Status Compress(const ColorView& view, Predictor predictor, int level,
                        std::string_view field, std::string* out);

  // Any rows `stride` bytes apart, laid out as `layout`.
  absl::Status Compress(const void* data, std::size_t stride, const PlaneLayout& layout,
                        Predictor predictor, int level, std::string* out);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Decompresses into a buffer it owns and reuses: after the largest frame seen, nothing is
// allocated. Not thread-safe: one per worker.
class PlaneDecompressor {
 public:
  PlaneDecompressor();
  ~PlaneDecompressor();
  PlaneDecompressor(const PlaneDecompressor&) = delete;
  PlaneDecompressor& operator=(const PlaneDecompressor&) = delete;

  // Decompresses `payload` into exactly layout.bytes() bytes and undoes the predictor; `*pixels`
  // then points at the packed rows, valid until the next call. The caller has checked the
  // layout's size against its limits. Every check that the bytes allow is made before the buffer
  // grows: the payload must be one whole zstd frame with a content checksum, declaring a content
  // size equal to layout.bytes(). Any error is INVALID_ARGUMENT naming
  // `field` and, for a size mismatch, `what` (e.g. "640x480 DISPARITY_U8"), e.g.
  // "frame.disparity.compressed.payload decompresses to 1000 bytes; 640x480 DISPARITY_U8 needs
  // 307200".
  absl::Status Decompress(std::string_view payload, const PlaneLayout& layout, Predictor predictor,
                          std::string_view field, std::string_view what,
                          const std::uint8_t** pixels);

  // Bytes held for decompressed pixels (for tests: a refused bomb leaves it where it was).
  std::size_t capacity() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The predictor alone, in place on packed rows (exposed for tests and benchmarks).
void ApplyPredictor(Predictor predictor, const PlaneLayout& layout, const void* src,
                    std::size_t src_stride, std::uint8_t* dst);
void UndoPredictor(Predictor predictor, const PlaneLayout& layout, std::uint8_t* pixels);

}  // namespace cloudcast
