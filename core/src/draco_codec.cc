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
#include "draco/compression/decode.h"
#include "draco/compression/expert_encode.h"
#include "draco/compression/mesh/mesh_sequential_decoder.h"
#include "draco/compression/point_cloud/point_cloud_kd_tree_decoder.h"
#include "draco/compression/point_cloud/point_cloud_sequential_decoder.h"
#include "draco/core/decoder_buffer.h"
#include "draco/core/draco_types.h"
#include "draco/core/encoder_buffer.h"
#include "draco/mesh/mesh.h"
#include "draco/point_cloud/point_cloud.h"
#include "draco_sequential_encoder.h"

namespace cloudcast {
namespace {

constexpr int kMaxPositionBits = 30;      // Draco's AttributeQuantizationTransform accepts 1..30.
constexpr int kMaxEntropyCodedBits = 20;  // see EncodeDraco

// No frame yields more points than pixels, so a larger count in a file is corruption or abuse.
constexpr std::uint64_t kMaxDecodedPoints = Limits{}.max_pixels;
// Above 2^20 points a file must also hold at least one byte per 16 points. Real clouds take
// 1..8 bytes per point (only masses of identical points go below 0.5 bit); without this a
// 30 KB file could still make Draco allocate and zero about 0.5 GB before failing.
constexpr std::uint64_t kPointsFreeOfRatioCheck = std::uint64_t{1} << 20;
constexpr std::uint64_t kMaxPointsPerByte = 16;
// Position, colour, normal, texture coordinates and a few generic values fit comfortably.
constexpr std::uint64_t kMaxAttributeBytesPerPoint = 64;

constexpr std::uint64_t MaxPointsFor(std::size_t bytes) {
  return std::min(kMaxDecodedPoints, std::max(kPointsFreeOfRatioCheck, kMaxPointsPerByte * bytes));
}

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
// needs libdraco after all; the bytes are libdraco's either way.
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
  *done = true;
  return absl::OkStatus();
}

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

bool ReadableIndex(const draco::PointAttribute& attribute, int num_points) {
  // Draco's mapped_index() does not bounds-check; a hostile file must not make us read past
  // the attribute.
  if (attribute.is_mapping_identity()) {
    return attribute.size() >= static_cast<std::size_t>(num_points);
  }
  return attribute.indices_map_size() >= static_cast<std::size_t>(num_points);
}

// Whether Draco's ConvertValue can read the attribute's values. DT_BOOL is refused: Draco 1.5.5
// loads each byte as a C++ bool, undefined behaviour for any byte but 0 and 1, which a hostile
// file sets freely (found by fuzz/draco_decode_fuzzer.cc).
bool NumericType(draco::DataType type) {
  return type >= draco::DT_INT8 && type <= draco::DT_FLOAT64;
}

// Reads positions into out->points[i].x/y/z. Returns false on an unreadable value.
bool ReadPositions(const draco::PointAttribute& position, int num_points, PointCloud* out) {
  if (!NumericType(position.data_type())) return false;
  Point* dst = out->points.data();
  const std::size_t needed = static_cast<std::size_t>(num_points) * 12;
  if (position.data_type() == draco::DT_FLOAT32 && position.num_components() == 3 &&
      position.byte_stride() == 12 && position.byte_offset() == 0 &&
      position.is_mapping_identity() && position.buffer() != nullptr &&
      position.buffer()->data_size() >= needed) {
    // What Draco's own decoders produce: one packed float array, read in bulk.
    const std::uint8_t* src = position.buffer()->data();
    for (int i = 0; i < num_points; ++i) {
      std::memcpy(&dst[i].x, src + std::size_t{12} * i, 12);
    }
    return true;
  }
  for (int i = 0; i < num_points; ++i) {
    const draco::AttributeValueIndex avi = position.mapped_index(draco::PointIndex(i));
    if (avi.value() >= position.size()) return false;
    float v[3];
    if (!position.ConvertValue<float>(avi, 3, v)) return false;
    dst[i].x = v[0];
    dst[i].y = v[1];
    dst[i].z = v[2];
  }
  return true;
}

std::uint8_t UnitToByte(double v) {
  if (!(v > 0.0)) return 0;  // also NaN
  if (v >= 1.0) return 255;
  return static_cast<std::uint8_t>(v * 255.0 + 0.5);
}

// Reads colours into out->points[i].rgba (alpha 255). Floats are taken as 0..1 (glTF and
// three.js convention), 16-bit unsigned as 0..65535, other integers as 0..255 (clamped).
// One or two components are read as grey.
bool ReadColors(const draco::PointAttribute& color, int num_points, PointCloud* out) {
  Point* dst = out->points.data();
  const int components = color.num_components();
  if (color.data_type() == draco::DT_UINT8 && components >= 3 &&
      color.byte_stride() == components && color.byte_offset() == 0 &&
      color.is_mapping_identity() && color.buffer() != nullptr &&
      color.buffer()->data_size() >= static_cast<std::size_t>(num_points) * components) {
    const std::uint8_t* src = color.buffer()->data();
    for (int i = 0; i < num_points; ++i, src += components) {
      dst[i].rgba = PackRgba(src[0], src[1], src[2]);
    }
    return true;
  }
  const draco::DataType type = color.data_type();
  if (!NumericType(type)) return false;
  const bool is_float = type == draco::DT_FLOAT32 || type == draco::DT_FLOAT64;
  for (int i = 0; i < num_points; ++i) {
    const draco::AttributeValueIndex avi = color.mapped_index(draco::PointIndex(i));
    if (avi.value() >= color.size()) return false;
    std::uint8_t rgb[3];
    if (is_float) {
      double v[3];
      if (!color.ConvertValue<double>(avi, 3, v)) return false;
      for (int c = 0; c < 3; ++c) rgb[c] = UnitToByte(v[c]);
    } else {
      std::int64_t v[3];
      if (!color.ConvertValue<std::int64_t>(avi, 3, v)) return false;
      for (int c = 0; c < 3; ++c) {
        rgb[c] = type == draco::DT_UINT16
                     ? static_cast<std::uint8_t>((v[c] * 255 + 32767) / 65535)
                     : static_cast<std::uint8_t>(std::clamp<std::int64_t>(v[c], 0, 255));
      }
    }
    if (components < 3) rgb[1] = rgb[2] = rgb[0];
    dst[i].rgba = PackRgba(rgb[0], rgb[1], rgb[2]);
  }
  return true;
}

// A file that claims more than the caps below allow: one wording wherever a cap is checked.
std::string PointCountRefusal(std::uint64_t points, std::uint64_t most) {
  return absl::StrCat(points, " points; at most ", most, " are accepted");
}
absl::Status FileClaims(std::size_t file_bytes, const std::string& what) {
  return absl::DataLossError(absl::StrCat("draco: a ", file_bytes, "-byte file claims ", what));
}

// Draco sizes each attribute from the point count stored in the file before it reads a single
// value, and zero-fills it: one flipped byte of a 30 KB frame made it touch 24 GB here, and the
// kernel killed the process. Each Draco decoder is therefore wrapped to refuse a count above
// MaxPointsFor(file size) between reading the geometry (where the count is read) and the
// attributes (where it allocates), and attributes wider than kMaxAttributeBytesPerPoint. With
// both, 180,000 corrupted frames decoded in at most 25 ms and 35 MB each. The dispatch below
// mirrors draco::Decoder::DecodePointCloudFromBuffer of Draco 1.5.5.
template <typename Base>
class CappedDecoder : public Base {
 public:
  explicit CappedDecoder(std::uint64_t max_points) : max_points_(max_points) {}
  // Empty while the file stayed within the caps.
  const std::string& refusal() const { return refusal_; }

 protected:
  // Runs after the point count is read and before any per-point allocation.
  bool DecodePointAttributes() override {
    const auto points = static_cast<std::uint64_t>(this->point_cloud()->num_points());
    if (points > max_points_) {
      refusal_ = PointCountRefusal(points, max_points_);
      return false;
    }
    return Base::DecodePointAttributes();
  }
  // Runs once the attribute descriptors are read and before their values are allocated: the
  // component counts (up to 255 each) come from the file too.
  bool DecodeAllAttributes() override {
    const draco::PointCloud& pc = *this->point_cloud();
    std::uint64_t bytes_per_point = 0;
    for (int i = 0; i < pc.num_attributes(); ++i) {
      const draco::PointAttribute& a = *pc.attribute(i);
      bytes_per_point +=
          static_cast<std::uint64_t>(draco::DataTypeLength(a.data_type())) * a.num_components();
    }
    if (bytes_per_point > kMaxAttributeBytesPerPoint) {
      refusal_ =
          absl::StrCat(pc.num_attributes(), " attributes of ", bytes_per_point,
                       " bytes per point; at most ", kMaxAttributeBytesPerPoint, " are accepted");
      return false;
    }
    return Base::DecodeAllAttributes();
  }

 private:
  std::uint64_t max_points_;
  std::string refusal_;
};

template <typename Decoder, typename Geometry>
absl::Status RunCapped(draco::DecoderBuffer* buffer, std::unique_ptr<draco::PointCloud>* out) {
  auto geometry = std::make_unique<Geometry>();
  const std::int64_t size = buffer->remaining_size();  // the whole file: nothing read yet
  const std::uint64_t max_points = MaxPointsFor(static_cast<std::size_t>(size));
  Decoder decoder(max_points);
  const draco::DecoderOptions options;
  const draco::Status status = decoder.Decode(options, buffer, geometry.get());
  if (!decoder.refusal().empty()) {
    return FileClaims(static_cast<std::size_t>(size), decoder.refusal());
  }
  if (!status.ok()) {
    return absl::DataLossError(absl::StrCat("draco: cannot decode: ", status.error_msg()));
  }
  *out = std::move(geometry);
  return absl::OkStatus();
}

absl::Status DecodeCapped(std::string_view bytes, std::unique_ptr<draco::PointCloud>* out) {
  draco::DecoderBuffer buffer;
  buffer.Init(bytes.data(), bytes.size());
  draco::DecoderBuffer header_buffer(buffer);  // the decoders read the header again
  draco::DracoHeader header;
  const draco::Status status = draco::PointCloudDecoder::DecodeHeader(&header_buffer, &header);
  if (!status.ok()) {
    return absl::DataLossError(absl::StrCat("draco: bad header: ", status.error_msg()));
  }
  // Bitstreams before 2.2 (written only by Draco releases before 1.0, 2017) go through legacy
  // decoding paths: a fuzzed 42-byte kd-tree file of version 2.0 kept libdraco busy for 33 s and
  // came back with 1.4 billion points (fuzz/corpus/cloud_readers/drc_kdtree_shared_values_bomb).
  // Refused from the header.
  if (header.version_major < 2 || (header.version_major == 2 && header.version_minor < 2)) {
    return absl::DataLossError(absl::StrCat(
        "draco: bitstream version ", int{header.version_major}, ".", int{header.version_minor},
        " predates 2.2 (Draco 1.0) and is not read; re-encode it with a current draco_encoder"));
  }
  if (header.encoder_type == draco::POINT_CLOUD) {
    switch (header.encoder_method) {
      case draco::POINT_CLOUD_SEQUENTIAL_ENCODING:
        return RunCapped<CappedDecoder<draco::PointCloudSequentialDecoder>, draco::PointCloud>(
            &buffer, out);
      case draco::POINT_CLOUD_KD_TREE_ENCODING:
        return RunCapped<CappedDecoder<draco::PointCloudKdTreeDecoder>, draco::PointCloud>(&buffer,
                                                                                           out);
    }
  } else if (header.encoder_type == draco::TRIANGULAR_MESH) {
    switch (header.encoder_method) {
      case draco::MESH_SEQUENTIAL_ENCODING:
        return RunCapped<CappedDecoder<draco::MeshSequentialDecoder>, draco::Mesh>(&buffer, out);
      case draco::MESH_EDGEBREAKER_ENCODING:
        // libdraco 1.5.5's Edgebreaker decoder sizes its connectivity buffers from counts in
        // the file before any of the caps above can see them: a fuzzed 146-byte file made it
        // reserve 5.6 GB (fuzz/corpus/cloud_readers/drc_edgebreaker_connectivity_bomb). We read
        // clouds, not meshes, so that decoder stays out of reach of untrusted bytes; a mesh's
        // vertices are still read from a sequentially coded mesh, or from a PLY.
        return absl::DataLossError(
            "draco: Edgebreaker-coded meshes are not read (cloudcast reads point clouds); "
            "re-encode the vertices as a point cloud (draco_encoder -point_cloud) or "
            "as a sequential mesh (draco_encoder -cl 0), or convert it to PLY");
    }
  }
  return absl::DataLossError(absl::StrCat("draco: unsupported geometry type ",
                                          int{header.encoder_type}, " / method ",
                                          int{header.encoder_method}));
}

}  // namespace

absl::Status DracoOptions::Validate(std::string_view field) const {
  // The field names are built only to report an error: EncodeDraco validates on every call, and a
  // warm encoder allocates nothing (gcc -O3 elides these strings, -O2 and the sanitizer builds do
  // not).
  const auto in = [](int v, int lo, int hi) { return v >= lo && v <= hi; };
  if (in(position_bits, 1, kMaxPositionBits) && in(color_bits, 1, 8) && in(encode_speed, 0, 10) &&
      in(decode_speed, 0, 10) && std::isfinite(max_position_error) && max_position_error >= 0.0f) {
    return absl::OkStatus();
  }
  const std::string f(field);
  for (absl::Status s : {check::InRange(f + ".position_bits", position_bits, 1, kMaxPositionBits),
                         check::InRange(f + ".color_bits", color_bits, 1, 8),
                         check::InRange(f + ".encode_speed", encode_speed, 0, 10),
                         check::InRange(f + ".decode_speed", decode_speed, 0, 10)}) {
    if (!s.ok()) return s;
  }
  if (!std::isfinite(max_position_error) || max_position_error < 0.0f) {
    return absl::InvalidArgumentError(
        absl::StrCat(f, ".max_position_error must be finite and >= 0, got ", max_position_error));
  }
  return absl::OkStatus();
}

absl::Status EncodeDraco(const PointCloud& cloud, const DracoOptions& options, std::string* out,
                         DracoEncodeInfo* info) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (out == nullptr) return absl::InvalidArgumentError("draco: output string is null");
  if (cloud.size() > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max())) {
    return absl::InvalidArgumentError(
        absl::StrCat("draco: ", cloud.size(), " points exceed Draco's 2^31 - 1 limit"));
  }

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
    if (info != nullptr) *info = {options.position_bits, 0.0f, out->size()};
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
  return absl::OkStatus();
}

absl::Status DecodeDraco(std::string_view bytes, PointCloud* out) {
  if (out == nullptr) return absl::InvalidArgumentError("draco: output cloud is null");
  std::unique_ptr<draco::PointCloud> decoded;
  // Draco can still throw std::bad_alloc or std::length_error on sizes read from a corrupted
  // file (other than the point count, which CappedDecoder bounds). That is bad input, not a
  // reason to take the process down.
  try {
    if (absl::Status s = DecodeCapped(bytes, &decoded); !s.ok()) return s;
  } catch (const std::exception& e) {
    return absl::DataLossError(absl::StrCat("draco: cannot decode: ", e.what()));
  }
  if (decoded == nullptr) return absl::DataLossError("draco: decoder returned no cloud");

  const int num_points = decoded->num_points();
  if (num_points < 0) return absl::DataLossError("draco: negative point count");
  const draco::PointAttribute* position =
      decoded->GetNamedAttribute(draco::GeometryAttribute::POSITION);
  if (num_points == 0) {
    out->ResizeUnorganized(0);
    return absl::OkStatus();
  }
  if (position == nullptr) {
    return absl::InvalidArgumentError(
        absl::StrCat("draco: ", num_points, " points but no POSITION attribute"));
  }
  if (position->num_components() < 3) {
    return absl::InvalidArgumentError(absl::StrCat(
        "draco: POSITION has ", int{position->num_components()}, " components; need 3"));
  }
  if (!ReadableIndex(*position, num_points)) {
    return absl::DataLossError("draco: POSITION holds fewer values than points");
  }
  const draco::PointAttribute* color = decoded->GetNamedAttribute(draco::GeometryAttribute::COLOR);
  if (color != nullptr && (color->num_components() < 1 || !ReadableIndex(*color, num_points))) {
    return absl::DataLossError("draco: COLOR holds fewer values than points");
  }

  // CappedDecoder bounds the count where Draco reads it, but a decoder can end with more points
  // than it allocated values for, sharing values through its point-to-value map (a fuzzed
  // 42-byte kd-tree file of bitstream 2.0 decoded to 1.4 billion points, and the cloud below
  // would have been 22 GB). The same bound holds for what we allocate.
  if (const std::uint64_t most = MaxPointsFor(bytes.size());
      static_cast<std::uint64_t>(num_points) > most) {
    return FileClaims(bytes.size(),
                      PointCountRefusal(static_cast<std::uint64_t>(num_points), most));
  }
  out->ResizeUnorganized(static_cast<std::size_t>(num_points));
  if (!ReadPositions(*position, num_points, out)) {
    out->ResizeUnorganized(0);  // no half-filled cloud on error
    return absl::DataLossError("draco: unreadable POSITION value");
  }
  if (color == nullptr) {
    for (Point& p : out->points) p.rgba = PackRgba(255, 255, 255);
  } else if (!ReadColors(*color, num_points, out)) {
    out->ResizeUnorganized(0);
    return absl::DataLossError("draco: unreadable COLOR value");
  }

  // An unquantized float file can carry NaN or Inf; unorganized clouds hold finite points only.
  auto keep_end = std::remove_if(out->points.begin(), out->points.end(), [](const Point& p) {
    return !std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z);
  });
  if (keep_end != out->points.end()) {
    out->ResizeUnorganized(static_cast<std::size_t>(keep_end - out->points.begin()));
  }
  return absl::OkStatus();
}

}  // namespace cloudcast
