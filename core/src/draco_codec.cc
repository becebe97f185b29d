#include "cloudcast/core/draco_codec.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <new>
#include <string>
#include <string_view>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/checks.h"
#include "cloudcast/core/limits.h"
#include "draco/attributes/geometry_attribute.h"
#include "draco/attributes/point_attribute.h"
#include "draco/compression/config/compression_shared.h"
#include "draco/compression/expert_encode.h"
#include "draco/core/draco_types.h"
#include "draco/core/encoder_buffer.h"
#include "draco/mesh/mesh.h"
#include "draco/point_cloud/point_cloud.h"
#include "draco_cap.h"
#include "draco_limits.h"
#include "draco_sequential_encoder.h"

namespace cloudcast {
namespace {

constexpr int kMaxPositionBits = internal::kMaxDracoPositionBits;
constexpr int kMaxEntropyCodedBits = 20;  // see EncodeDraco

// The largest per-coordinate error of Draco 1.5.5's position quantization on a cloud whose
// largest bounding-box side is `range` and whose largest |coordinate| is `max_abs`.
//
// Draco (AttributeQuantizationTransform) uses ONE range for all three axes, the largest side,
// computed in float as max - min. With m = 2^bits - 1 it stores q = floor((v - min) * (m / range)
// + 0.5) and decodes q * (range / m) + min, all in float. The ideal error is half a step,
// range / (2m). Every float operation on the way adds at most half an ulp of its result: v - min,
// the scaling, the + 0.5 and the int->float of q (the last two matter above 23 bits, where one
// step is finer than a float), then q * delta and + min. Seven terms of at most 2^-24 * range and
// one of 2^-24 * max_abs; we count 8 and 2 to stay on the safe side. On a 10 m cloud that slack
// is about 6 micrometres, far below one step at the bit depths anybody uses.
// A cloud whose points are all equal (range 0) decodes exactly: Draco stores q = 0 for all.
double QuantizationErrorBound(float range, float max_abs, int bits) {
  if (range <= 0.0f) return 0.0;
  const double m = static_cast<double>((std::uint32_t{1} << bits) - 1);
  const double r = range;
  return 0.5 * r / m + (8.0 * r + 2.0 * static_cast<double>(max_abs)) * 0x1p-24;
}

// Reused across calls on the same thread: the Draco cloud and its two attribute buffers are
// resized, not reallocated, on the per-frame path (they keep the largest frame's capacity,
// 15 bytes per point).
struct EncodeScratch {
  draco::PointCloud cloud;
  int position_id = -1;
  int color_id = -1;

  EncodeScratch() {
    auto position = std::make_unique<draco::PointAttribute>();
    position->Init(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32, false, 0);
    position_id = cloud.AddAttribute(std::move(position));
    // Normalized, as Draco's own PLY reader marks 8-bit colour: viewers such as three.js then
    // map 255 to 1.0.
    auto color = std::make_unique<draco::PointAttribute>();
    color->Init(draco::GeometryAttribute::COLOR, 3, draco::DT_UINT8, true, 0);
    color_id = cloud.AddAttribute(std::move(color));
  }
};

// Maps 8-bit colour values to the nearest of 2^bits levels spread over 0..255. Draco ignores
// quantization options on integer attributes, so fewer colour bits are applied here; the file
// stays plain 8-bit RGB that any Draco decoder reads, only with fewer distinct values for the
// entropy coder.
std::array<std::uint8_t, 256> ColorLevels(int bits) {
  std::array<std::uint8_t, 256> lut;
  const int top = (1 << bits) - 1;
  for (int c = 0; c < 256; ++c) {
    const int level = (c * top + 127) / 255;
    lut[c] = static_cast<std::uint8_t>((level * 255 + top / 2) / top);
  }
  return lut;
}

// Colour level tables for 1..8 bits (index = bits).
const std::array<std::uint8_t, 256>& ColorLut(int bits) {
  static const std::array<std::array<std::uint8_t, 256>, 9> kLevels = [] {
    std::array<std::array<std::uint8_t, 256>, 9> t{};
    for (int b = 1; b <= 8; ++b) t[b] = ColorLevels(b);
    return t;
  }();
  return kLevels[bits];
}

// The bits to quantize a cloud of finite points with this bounding box at: the requested ones,
// raised as max_position_error needs. Also gives the largest side and |coordinate|.
absl::Status ChoosePositionBits(const float lo[3], const float hi[3], const DracoOptions& options,
                                int* bits, float* range, float* max_abs) {
  // The same float arithmetic as Draco's ComputeParameters, so `range` is bit-identical to the
  // one it quantizes with.
  *range = 0.0f;
  *max_abs = 0.0f;
  for (int c = 0; c < 3; ++c) {
    *range = std::max(*range, hi[c] - lo[c]);
    *max_abs = std::max({*max_abs, std::fabs(lo[c]), std::fabs(hi[c])});
  }
  if (!std::isfinite(*range)) {
    return absl::InvalidArgumentError(
        absl::StrCat("draco: the cloud's extent overflows a float (", *range, ")"));
  }
  *bits = options.position_bits;
  if (options.max_position_error > 0.0f) {
    const double limit = options.max_position_error;
    int needed = 1;
    while (needed <= kMaxPositionBits && QuantizationErrorBound(*range, *max_abs, needed) > limit) {
      ++needed;
    }
    if (needed > kMaxPositionBits) {
      return absl::InvalidArgumentError(
          absl::StrCat("draco.max_position_error ", options.max_position_error, " needs more than ",
                       kMaxPositionBits, " position bits for this cloud (largest side ", *range,
                       ", largest |coordinate| ", *max_abs, ")"));
    }
    *bits = std::max(*bits, needed);
  }
  return absl::OkStatus();
}

void FillInfo(int bits, float range, float max_abs, std::size_t bytes, DracoEncoder encoder,
              DracoEncodeInfo* info) {
  if (info == nullptr) return;
  *info = DracoEncodeInfo{};
  info->position_bits = bits;
  // Rounded up, so that the float never understates the bound.
  const double bound = QuantizationErrorBound(range, max_abs, bits);
  float reported = static_cast<float>(bound);
  if (reported < bound) reported = std::nextafter(reported, std::numeric_limits<float>::max());
  info->position_error_bound = reported;
  info->bytes = bytes;
  info->encoder = encoder;
}

// Speed 10 above this many bits: Draco's entropy coding is switched off (see EncodeDraco).
bool EntropyCoded(int bits) { return bits <= kMaxEntropyCodedBits; }

// Our encoder (draco_sequential_encoder.h), for sequential coding. Sets *done unless the cloud
// needs libdraco after all; the bytes are libdraco's either way. Only where it is built (x86-64).
#if defined(__x86_64__) && defined(__SSE2__)
absl::Status EncodeWithCloudcast(const PointCloud& cloud, const DracoOptions& options,
                                 std::string* out, DracoEncodeInfo* info, bool* done) {
  *done = false;
  const Point* points = cloud.points.data();
  const internal::DracoCloudExtent extent = internal::ScanForDraco(points, cloud.size());
  if (extent.finite != cloud.size()) {
    thread_local PointVector finite;  // organized clouds: holes dropped, order kept
    finite.resize(extent.finite);
    std::size_t n = 0;
    for (const Point& p : cloud.points) {
      if (std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z)) finite[n++] = p;
    }
    points = finite.data();
  }
  if (extent.finite == 0) {
    internal::EncodeDracoEmpty(out);
    if (info != nullptr) {
      *info = {options.position_bits, 0.0f, out->size(), DracoEncoder::kCloudcast};
      info->color_bits = options.color_bits;
    }
    *done = true;
    return absl::OkStatus();
  }
  int bits = 0;
  float range = 0.0f, max_abs = 0.0f;
  if (absl::Status s = ChoosePositionBits(extent.lo, extent.hi, options, &bits, &range, &max_abs);
      !s.ok()) {
    *done = true;
    return s;
  }
  internal::DracoSequentialOptions sequential;
  sequential.position_bits = bits;
  sequential.entropy_coding = EntropyCoded(bits);
  sequential.color_lut = options.color_bits < 8 ? ColorLut(options.color_bits).data() : nullptr;
  try {
    if (!internal::EncodeDracoSequential(points, extent.finite, extent, sequential, out)) {
      return absl::OkStatus();  // libdraco's turn
    }
  } catch (const std::bad_alloc&) {
    *done = true;
    return absl::ResourceExhaustedError(absl::StrCat("draco: out of memory encoding ",
                                                     extent.finite, " points at ", bits, " bits"));
  }
  FillInfo(bits, range, max_abs, out->size(), DracoEncoder::kCloudcast, info);
  info->color_bits = options.color_bits;
  *done = true;
  return absl::OkStatus();
}
#else
absl::Status EncodeWithCloudcast(const PointCloud&, const DracoOptions&, std::string*,
                                 DracoEncodeInfo*, bool* done) {
  *done = false;  // libdraco's turn, always
  return absl::OkStatus();
}
#endif

// Draco 1.5.5 crashes when quantizing an attribute with no values (ComputeParameters reads
// value 0), and fails to decode a 0-point cloud that carries an 8-bit attribute. A 0-point cloud
// with one unquantized float POSITION attribute round-trips, and stays a file any Draco decoder
// reads.
absl::Status EncodeEmpty(std::string* out) {
  draco::PointCloud cloud;
  auto position = std::make_unique<draco::PointAttribute>();
  position->Init(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32, false, 0);
  cloud.AddAttribute(std::move(position));
  draco::ExpertEncoder encoder(cloud);
  encoder.SetEncodingMethod(draco::POINT_CLOUD_SEQUENTIAL_ENCODING);
  draco::EncoderBuffer buffer;
  const draco::Status status = encoder.EncodeToBuffer(&buffer);
  if (!status.ok()) {
    return absl::InternalError(
        absl::StrCat("draco: encoding an empty cloud failed: ", status.error_msg()));
  }
  out->assign(buffer.data(), buffer.size());
  return absl::OkStatus();
}

}  // namespace

absl::Status EncodeDraco(const PointCloud& cloud, const DracoOptions& options, std::string* out,
                         DracoEncodeInfo* info) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (out == nullptr) return absl::InvalidArgumentError("draco: output string is null");
  if (cloud.size() > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max())) {
    return absl::InvalidArgumentError(
        absl::StrCat("draco: ", cloud.size(), " points exceed Draco's 2^31 - 1 limit"));
  }
  DracoEncodeInfo local;
  absl::Status s = options.max_cloud_bytes > 0
                       ? internal::EncodeDracoCapped(cloud, options, out, &local)
                       : internal::EncodeDracoOnce(cloud, options, out, &local);
  if (s.ok() && info != nullptr) *info = local;
  return s;
}

namespace internal {

absl::Status PositionBitsFloor(const float lo[3], const float hi[3], float max_position_error,
                               int* bits) {
  DracoOptions fewest;
  fewest.position_bits = 1;
  fewest.max_position_error = max_position_error;
  float range = 0.0f, max_abs = 0.0f;
  return ChoosePositionBits(lo, hi, fewest, bits, &range, &max_abs);
}

absl::Status EncodeDracoOnce(const PointCloud& cloud, const DracoOptions& options, std::string* out,
                             DracoEncodeInfo* info) {
  if (std::max(options.encode_speed, options.decode_speed) == 10 && !options.force_libdraco) {
    bool done = false;
    const absl::Status s = EncodeWithCloudcast(cloud, options, out, info, &done);
    if (done) return s;
  }

  thread_local EncodeScratch scratch;
  draco::PointAttribute* position = scratch.cloud.attribute(scratch.position_id);
  draco::PointAttribute* color = scratch.cloud.attribute(scratch.color_id);
  if (!position->Reset(cloud.size()) || !color->Reset(cloud.size())) {
    return absl::ResourceExhaustedError("draco: cannot size the attribute buffers");
  }

  // One pass: drop non-finite points, pack xyz and RGB for Draco, track the bounding box.
  const bool reduce_color = options.color_bits < 8;
  const std::array<std::uint8_t, 256>& lut = ColorLut(options.color_bits);
  auto* xyz = reinterpret_cast<float*>(position->GetAddress(draco::AttributeValueIndex(0)));
  std::uint8_t* rgb = color->GetAddress(draco::AttributeValueIndex(0));
  float lo[3] = {std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
                 std::numeric_limits<float>::infinity()};
  float hi[3] = {-lo[0], -lo[1], -lo[2]};
  std::size_t n = 0;
  for (const Point& p : cloud.points) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) continue;
    float* d = xyz + 3 * n;
    d[0] = p.x;
    d[1] = p.y;
    d[2] = p.z;
    lo[0] = std::min(lo[0], p.x);
    lo[1] = std::min(lo[1], p.y);
    lo[2] = std::min(lo[2], p.z);
    hi[0] = std::max(hi[0], p.x);
    hi[1] = std::max(hi[1], p.y);
    hi[2] = std::max(hi[2], p.z);
    std::uint8_t* c = rgb + 3 * n;
    c[0] = RedOf(p.rgba);
    c[1] = GreenOf(p.rgba);
    c[2] = BlueOf(p.rgba);
    if (reduce_color) {
      c[0] = lut[c[0]];
      c[1] = lut[c[1]];
      c[2] = lut[c[2]];
    }
    ++n;
  }

  if (n == 0) {
    if (absl::Status s = EncodeEmpty(out); !s.ok()) return s;
    if (info != nullptr) {
      *info = {options.position_bits, 0.0f, out->size()};
      info->color_bits = options.color_bits;
    }
    return absl::OkStatus();
  }
  if (n != cloud.size()) {
    // Shrinking a std::vector-backed buffer keeps its capacity and the packed prefix.
    position->Reset(n);
    color->Reset(n);
  }
  scratch.cloud.set_num_points(static_cast<draco::PointIndex::ValueType>(n));

  int bits = 0;
  float range = 0.0f, max_abs = 0.0f;
  if (absl::Status s = ChoosePositionBits(lo, hi, options, &bits, &range, &max_abs); !s.ok()) {
    return s;
  }

  draco::ExpertEncoder encoder(scratch.cloud);
  encoder.SetAttributeQuantization(scratch.position_id, bits);
  encoder.SetSpeedOptions(options.encode_speed, options.decode_speed);
  if (!EntropyCoded(bits) && std::max(options.encode_speed, options.decode_speed) == 10) {
    // Draco's sequential coder (speed 10) builds a symbol table of 4 * 2^bits bytes: 64 MB and
    // 0.1 s at 24 bits, 4 GB and 15 s at 30 (measured on 20,000 points). Above 20 bits its
    // entropy coding saves little (10.5 vs 12 bytes per point at 20, nothing at 24), so the
    // values are stored raw. The kd-tree coder (speed < 10) has no such table.
    encoder.SetUseBuiltInAttributeCompression(false);
  }
  draco::EncoderBuffer buffer;
  // Draco reports failures as Status but allocates with std::vector; running out of memory on
  // one frame must not abort the service.
  try {
    const draco::Status status = encoder.EncodeToBuffer(&buffer);
    if (!status.ok()) {
      return absl::InternalError(absl::StrCat("draco: encoding failed: ", status.error_msg()));
    }
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError(
        absl::StrCat("draco: out of memory encoding ", n, " points at ", bits, " bits"));
  }
  out->assign(buffer.data(), buffer.size());
  FillInfo(bits, range, max_abs, out->size(), DracoEncoder::kLibdraco, info);
  info->color_bits = options.color_bits;
  return absl::OkStatus();
}

}  // namespace internal
}  // namespace cloudcast
