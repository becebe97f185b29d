// Draco compression of our clouds: positions quantized, colour as 8-bit RGB.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "cloudcast/core/point.h"

namespace cloudcast {

// Which encoder wrote a Draco file. Where both apply they write the same bytes.
enum class DracoEncoder {
  kLibdraco,   // libdraco 1.5.5's ExpertEncoder
  kCloudcast,  // ours, for sequential coding (speed 10): libdraco's bytes, several times faster
};

struct DracoOptions {
  // Position quantization bits (1..30). The codec raises them when needed to keep the error
  // under `max_position_error`. 10 by measurement (cloudcast-bench's Draco table, README): the
  // fewest bytes that keep paper-parameter clouds (<= 12.5 units wide) within a quarter of a
  // 0.03 leaf; 11 bits cost 9% more bytes for the same time.
  int position_bits = 10;
  // Colour quantization bits (1..8); 8 keeps colours exact. Fewer bits snap each channel to
  // 2^bits levels over 0..255 before encoding (Draco ignores quantization of 8-bit attributes),
  // so the file stays plain 8-bit RGB for any decoder.
  int color_bits = 8;
  // Draco's speed, 0 (smallest) .. 10 (fastest); Draco uses the larger of the two. Speed 10 is
  // Draco's sequential coder: it keeps point order, and its size depends on that order (it
  // predicts each point from the previous one). Speeds 0..9 use the kd-tree coder, which
  // reorders points. Above 20 position bits speed 10 stores values without entropy coding.
  int encode_speed = 10;
  int decode_speed = 10;
  // If > 0: the largest allowed distance, per coordinate, between a point and its decoded
  // position. The pipeline sets it to a quarter of the voxel leaf.
  float max_position_error = 0.0f;
  // EncodeDraco uses its own encoder where it covers the options (speed 10, i.e. the larger of
  // the two speeds is 10; any bits) and libdraco elsewhere. true always uses libdraco, so that
  // tests and benchmarks can compare the two on the same input.
  bool force_libdraco = false;

  // Errors name the member under `field` (e.g. "draco.position_bits").
  absl::Status Validate(std::string_view field = "draco") const;
};

// What an encode produced.
struct DracoEncodeInfo {
  int position_bits = 0;           // the bits actually used
  float position_error_bound = 0;  // max per-coordinate error those bits allow on this cloud
  std::size_t bytes = 0;
  DracoEncoder encoder = DracoEncoder::kLibdraco;  // which one wrote the bytes
};

// Encodes the finite points of `cloud` (NaN points are dropped). An empty cloud encodes too.
absl::Status EncodeDraco(const PointCloud& cloud, const DracoOptions& options, std::string* out,
                         DracoEncodeInfo* info = nullptr);

// Decodes a Draco point cloud or mesh (ours or any with POSITION and optional COLOR attributes)
// into an unorganized cloud; colour defaults to white, alpha is 255, non-finite points are
// dropped. Corrupted input gives an error. To bound the memory a hostile file can make Draco
// allocate, files claiming more than Limits{}.max_pixels points, more than 16 points per byte
// above 2^20 points, or more than 64 bytes of attributes per point are refused.
absl::Status DecodeDraco(std::string_view bytes, PointCloud* out);

}  // namespace cloudcast
