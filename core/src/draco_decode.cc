// The Draco decoder and the Draco options' checks: the part of the codec a client needs. Plain
// C++ over libdraco's decoder, so it builds on any architecture (cloudcast_core_portable); the
// encoder (draco_codec.cc, with our x86-64 sequential encoder) stays in cloudcast_core.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <string_view>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/checks.h"
#include "cloudcast/core/draco_codec.h"
#include "cloudcast/core/limits.h"
#include "draco/attributes/attribute_quantization_transform.h"
#include "draco/attributes/attribute_transform_data.h"
#include "draco/attributes/geometry_attribute.h"
#include "draco/attributes/point_attribute.h"
#include "draco/compression/config/compression_shared.h"
#include "draco/compression/decode.h"
#include "draco/compression/mesh/mesh_sequential_decoder.h"
#include "draco/compression/point_cloud/point_cloud_kd_tree_decoder.h"
#include "draco/compression/point_cloud/point_cloud_sequential_decoder.h"
#include "draco/core/decoder_buffer.h"
#include "draco/core/draco_types.h"
#include "draco/mesh/mesh.h"
#include "draco/point_cloud/point_cloud.h"
#include "draco_limits.h"

namespace cloudcast {
namespace {

constexpr int kMaxPositionBits = internal::kMaxDracoPositionBits;

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

// Quantized positions (the sequential decoders leave them so, see RunCapped), dequantized as
// Draco 1.5.5's AttributeQuantizationTransform::InverseTransformAttribute does: one delta,
// range / (2^bits - 1), then float(q) * delta, rounded, plus the axis' minimum, rounded. Here, and
// not in libdraco, so that every architecture gets the same floats: Debian's arm64 libdraco fuses
// the multiply and the add (GCC contracts them into FMA there), which moved 677 of 821 points of a
// test cloud by one ulp. This library builds with -ffp-contract=off (core/CMakeLists.txt).
// Returns false when the attribute holds no quantization or an unreadable value.
bool DequantizePositions(const draco::PointAttribute& position, int num_points, PointCloud* out) {
  const draco::AttributeTransformData* transform = position.GetAttributeTransformData();
  if (transform == nullptr ||
      transform->transform_type() != draco::ATTRIBUTE_QUANTIZATION_TRANSFORM) {
    return false;
  }
  draco::AttributeQuantizationTransform quantization;
  if (!quantization.InitFromAttribute(position) || position.num_components() != 3 ||
      quantization.min_values().size() != 3 || quantization.quantization_bits() < 1 ||
      quantization.quantization_bits() > kMaxPositionBits ||
      (position.data_type() != draco::DT_INT32 && position.data_type() != draco::DT_UINT32)) {
    return false;
  }
  const auto max_quantized =
      static_cast<float>((std::uint32_t{1} << quantization.quantization_bits()) - 1);
  const float delta = quantization.range() / max_quantized;
  const float* min = quantization.min_values().data();
  Point* dst = out->points.data();
  for (int i = 0; i < num_points; ++i) {
    const draco::AttributeValueIndex avi = position.mapped_index(draco::PointIndex(i));
    if (avi.value() >= position.size()) return false;
    std::int32_t q[3];
    if (!position.ConvertValue<std::int32_t>(avi, 3, q)) return false;
    float v[3];
    for (int c = 0; c < 3; ++c) {
      const float scaled = static_cast<float>(q[c]) * delta;
      v[c] = scaled + min[c];
    }
    dst[i].x = v[0];
    dst[i].y = v[1];
    dst[i].z = v[2];
  }
  return true;
}

// Reads positions into out->points[i].x/y/z. Returns false on an unreadable value.
bool ReadPositions(const draco::PointAttribute& position, int num_points, PointCloud* out) {
  if (position.GetAttributeTransformData() != nullptr) {
    return DequantizePositions(position, num_points, out);
  }
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

// kOwnDequantization: the decoder (a sequential one) leaves quantized positions as they are, with
// their quantization, for DequantizePositions.
template <typename Decoder, typename Geometry, bool kOwnDequantization = false>
absl::Status RunCapped(draco::DecoderBuffer* buffer, std::unique_ptr<draco::PointCloud>* out) {
  auto geometry = std::make_unique<Geometry>();
  const std::int64_t size = buffer->remaining_size();  // the whole file: nothing read yet
  const std::uint64_t max_points = MaxPointsFor(static_cast<std::size_t>(size));
  Decoder decoder(max_points);
  draco::DecoderOptions options;
  if (kOwnDequantization) {
    options.SetAttributeBool(draco::GeometryAttribute::POSITION, "skip_attribute_transform", true);
  }
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
        return RunCapped<CappedDecoder<draco::PointCloudSequentialDecoder>, draco::PointCloud,
                         true>(&buffer, out);
      case draco::POINT_CLOUD_KD_TREE_ENCODING:
        // A kd-tree cloud of bitstream 2.2 (Draco before 1.4; current ones write 2.3) decodes its
        // attributes through a legacy path that sizes a buffer from counts of its own, after the
        // caps above: a fuzzed 69-byte file of 254 points made libdraco allocate and zero 6.8 GB
        // (fuzz/corpus/draco_decode/kdtree_v22_allocation_bomb). Refused from the header.
        if (header.version_major == 2 && header.version_minor < 3) {
          return absl::DataLossError(absl::StrCat(
              "draco: a kd-tree cloud of bitstream version 2.", int{header.version_minor},
              " (Draco before 1.4) is not read; re-encode it with a current draco_encoder"));
        }
        return RunCapped<CappedDecoder<draco::PointCloudKdTreeDecoder>, draco::PointCloud>(&buffer,
                                                                                           out);
    }
  } else if (header.encoder_type == draco::TRIANGULAR_MESH) {
    switch (header.encoder_method) {
      case draco::MESH_SEQUENTIAL_ENCODING:
        return RunCapped<CappedDecoder<draco::MeshSequentialDecoder>, draco::Mesh, true>(&buffer,
                                                                                          out);
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
  const bool cap_ok = max_cloud_bytes == 0 || max_cloud_bytes >= kMinCloudBytesCap;
  if (in(position_bits, 1, kMaxPositionBits) && in(color_bits, 1, 8) && in(encode_speed, 0, 10) &&
      in(decode_speed, 0, 10) && std::isfinite(max_position_error) && max_position_error >= 0.0f &&
      cap_ok && in(min_color_bits, 1, 8)) {
    return absl::OkStatus();
  }
  const std::string f(field);
  for (absl::Status s : {check::InRange(f + ".position_bits", position_bits, 1, kMaxPositionBits),
                         check::InRange(f + ".color_bits", color_bits, 1, 8),
                         check::InRange(f + ".encode_speed", encode_speed, 0, 10),
                         check::InRange(f + ".decode_speed", decode_speed, 0, 10),
                         check::InRange(f + ".min_color_bits", min_color_bits, 1, 8)}) {
    if (!s.ok()) return s;
  }
  if (!std::isfinite(max_position_error) || max_position_error < 0.0f) {
    return absl::InvalidArgumentError(
        absl::StrCat(f, ".max_position_error must be finite and >= 0, got ", max_position_error));
  }
  if (!cap_ok) {
    return absl::InvalidArgumentError(absl::StrCat(
        f, ".max_cloud_bytes is ", max_cloud_bytes, "; it must be 0 (no cap) or at least ",
        kMinCloudBytesCap, " (a Draco cloud's header alone takes about 30 bytes)"));
  }
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
