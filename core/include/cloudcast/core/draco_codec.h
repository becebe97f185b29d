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
  // The downlink cap: if > 0, the largest encoded size in bytes. EncodeDraco then chooses the
  // position and colour bits (draco_cap.h): position bits from position_bits down to the fewest
  // that keep max_position_error (never below position_bits when there is no bound), then colour
  // bits from color_bits down to min_color_bits. What it cannot meet at those floors it encodes
  // at the floors and reports (DracoEncodeInfo::over_cap). 0: no cap, the bits as given.
  std::uint64_t max_cloud_bytes = 0;
  // The fewest colour bits (1..8) the cap may use; a color_bits below it is its own floor.
  // 5 (32 levels a channel): colour costs about 0.6 bytes a point less than at 8 bits on New
  // Tsukuba clouds, and 4 bits or fewer band visibly (docs/links.md, "Downlink").
  int min_color_bits = 5;

  // Errors name the member under `field` (e.g. "draco.position_bits").
  absl::Status Validate(std::string_view field = "draco") const;
};

// What an encode produced.
struct DracoEncodeInfo {
  int position_bits = 0;           // the bits actually used
  float position_error_bound = 0;  // max per-coordinate error those bits allow on this cloud
  std::size_t bytes = 0;
  DracoEncoder encoder = DracoEncoder::kLibdraco;  // which one wrote the bytes
  int color_bits = 8;                              // the colour bits actually used
  // With a cap (DracoOptions::max_cloud_bytes): how many encodes it took (1..3), and whether the
  // cloud is over the cap at the floors of both bit depths. 1 and false without a cap.
  int encodes = 1;
  bool over_cap = false;
};

// Nonzero caps below this are refused (DracoOptions::Validate): a header alone takes about 30.
inline constexpr std::uint64_t kMinCloudBytesCap = 64;

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
