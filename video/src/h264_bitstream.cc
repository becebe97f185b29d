#include "cloudcast/video/h264_bitstream.h"

#include <string>

#include "absl/strings/str_cat.h"

namespace cloudcast::video {

namespace {
// Debian's Abseil has its own string_view, which StrCat takes; std::string converts to both.
std::string S(std::string_view v) { return std::string(v); }
}  // namespace
namespace {

// Reads the RBSP of one NAL unit: emulation-prevention bytes (00 00 03) are skipped as the bits
// are read, so no unescaped copy is made. Every read past the end is an error, not a zero.
class BitReader {
 public:
  explicit BitReader(std::string_view nal) : data_(nal) {}

  bool Bit(std::uint32_t* out) {
    if (bit_ == 0) {
      if (pos_ >= data_.size()) return false;
      // An emulation-prevention byte: 0x03 after two zero bytes of payload.
      if (zeros_ >= 2 && static_cast<std::uint8_t>(data_[pos_]) == 3) {
        zeros_ = 0;
        if (++pos_ >= data_.size()) return false;
      }
      byte_ = static_cast<std::uint8_t>(data_[pos_++]);
      zeros_ = byte_ == 0 ? zeros_ + 1 : 0;
      bit_ = 8;
    }
    --bit_;
    *out = (byte_ >> bit_) & 1u;
    return true;
  }
  bool Bits(int n, std::uint32_t* out) {
    std::uint32_t v = 0;
    for (int i = 0; i < n; ++i) {
      std::uint32_t b;
      if (!Bit(&b)) return false;
      v = (v << 1) | b;
    }
    *out = v;
    return true;
  }
  // ue(v): at most 31 leading zeros (values up to 2^32 - 2); more is malformed.
  bool Ue(std::uint32_t* out) {
    int zeros = 0;
    std::uint32_t b = 0;
    while (true) {
      if (!Bit(&b)) return false;
      if (b == 1) break;
      if (++zeros > 31) return false;
    }
    std::uint32_t rest = 0;
    if (!Bits(zeros, &rest)) return false;
    *out = static_cast<std::uint32_t>((std::uint64_t{1} << zeros) - 1 + rest);
    return true;
  }
  bool Se(std::int64_t* out) {
    std::uint32_t k = 0;
    if (!Ue(&k)) return false;
    *out = (k & 1) ? (std::int64_t{k} + 1) / 2 : -(std::int64_t{k} / 2);
    return true;
  }

 private:
  std::string_view data_;
  std::size_t pos_ = 0;
  std::uint8_t byte_ = 0;
  int bit_ = 0;
  int zeros_ = 0;
};

// Field-naming reads: each failure says which SPS member ran out of bits or was out of range.
class SpsReader {
 public:
  SpsReader(std::string_view nal, std::string_view field)
      : bits_(nal.substr(1)), field_(absl::StrCat(S(field), ".sps")) {}

  absl::Status U(int n, const char* name, std::uint32_t* out) {
    if (!bits_.Bits(n, out)) return Truncated(name);
    return absl::OkStatus();
  }
  absl::Status Ue(const char* name, std::uint32_t* out, std::uint32_t max) {
    if (!bits_.Ue(out)) return Truncated(name);
    if (*out > max) return OutOfRange(name, *out, 0, max);
    return absl::OkStatus();
  }
  absl::Status Se(const char* name, std::int64_t lo, std::int64_t hi) {
    std::int64_t v = 0;
    if (!bits_.Se(&v)) return Truncated(name);
    if (v < lo || v > hi) return OutOfRange(name, v, lo, hi);
    return absl::OkStatus();
  }
  absl::Status Invalid(const char* name, const std::string& why) const {
    return absl::InvalidArgumentError(absl::StrCat(field_, ".", name, ": ", why));
  }
  const std::string& field() const { return field_; }

 private:
  absl::Status Truncated(const char* name) const {
    return absl::InvalidArgumentError(
        absl::StrCat(field_, ".", name,
                     ": the sequence parameter set ends (or holds a malformed "
                     "Exp-Golomb code) before this field"));
  }
  absl::Status OutOfRange(const char* name, std::int64_t v, std::int64_t lo,
                          std::int64_t hi) const {
    return absl::InvalidArgumentError(
        absl::StrCat(field_, ".", name, " is ", v, "; H.264 allows ", lo, " to ", hi));
  }

  BitReader bits_;
  std::string field_;
};

// scaling_list(): only read past (the decoder applies it).
absl::Status SkipScalingList(SpsReader& r, int size) {
  std::int64_t last = 8, next = 8;
  for (int j = 0; j < size; ++j) {
    if (next != 0) {
      // delta_scale is se(v) in [-128, 127].
      std::uint32_t k = 0;
      if (absl::Status s = r.Ue("scaling_list.delta_scale", &k, 255); !s.ok()) return s;
      const std::int64_t delta = (k & 1) ? (std::int64_t{k} + 1) / 2 : -(std::int64_t{k} / 2);
      next = (last + delta + 256) % 256;
    }
    last = next == 0 ? last : next;
  }
  return absl::OkStatus();
}

// The profiles whose SPS carries chroma_format_idc, bit depths and scaling lists (7.3.2.1.1).
bool HasChromaFields(std::uint32_t profile) {
  for (std::uint32_t p : {100, 110, 122, 244, 44, 83, 86, 118, 128, 138, 139, 134, 135}) {
    if (p == profile) return true;
  }
  return false;
}

#define CC_RETURN_IF_ERROR(expr)                       \
  do {                                                 \
    if (absl::Status _s = (expr); !_s.ok()) return _s; \
  } while (0)

}  // namespace

absl::StatusOr<SequenceHeader> ParseSequenceHeader(std::string_view nal, std::string_view field,
                                                   const Limits& limits) {
  SpsReader r(nal, field);
  SequenceHeader h;
  std::uint32_t v = 0;
  CC_RETURN_IF_ERROR(r.U(8, "profile_idc", &h.profile_idc));
  CC_RETURN_IF_ERROR(r.U(8, "constraint_flags", &v));
  CC_RETURN_IF_ERROR(r.U(8, "level_idc", &h.level_idc));
  CC_RETURN_IF_ERROR(r.Ue("seq_parameter_set_id", &h.sps_id, 31));
  if (HasChromaFields(h.profile_idc)) {
    CC_RETURN_IF_ERROR(r.Ue("chroma_format_idc", &h.chroma_format_idc, 3));
    if (h.chroma_format_idc == 2) {
      return r.Invalid("chroma_format_idc",
                       "2 (4:2:2) is not taken; 0 (grey), 1 (4:2:0), 3 (4:4:4)");
    }
    if (h.chroma_format_idc == 3) {
      std::uint32_t separate = 0;
      CC_RETURN_IF_ERROR(r.U(1, "separate_colour_plane_flag", &separate));
      if (separate) {
        return r.Invalid("separate_colour_plane_flag", "1 (three pictures per frame) is not taken");
      }
    }
    std::uint32_t depth_luma = 0, depth_chroma = 0;
    CC_RETURN_IF_ERROR(r.Ue("bit_depth_luma_minus8", &depth_luma, 6));
    CC_RETURN_IF_ERROR(r.Ue("bit_depth_chroma_minus8", &depth_chroma, 6));
    if (depth_luma != 0 || depth_chroma != 0) {
      return r.Invalid(depth_luma != 0 ? "bit_depth_luma_minus8" : "bit_depth_chroma_minus8",
                       absl::StrCat(8 + (depth_luma != 0 ? depth_luma : depth_chroma),
                                    "-bit samples are not taken; 8 only"));
    }
    CC_RETURN_IF_ERROR(r.U(1, "qpprime_y_zero_transform_bypass_flag", &v));
    std::uint32_t scaling = 0;
    CC_RETURN_IF_ERROR(r.U(1, "seq_scaling_matrix_present_flag", &scaling));
    if (scaling) {
      const int lists = h.chroma_format_idc == 3 ? 12 : 8;
      for (int i = 0; i < lists; ++i) {
        std::uint32_t present = 0;
        CC_RETURN_IF_ERROR(r.U(1, "seq_scaling_list_present_flag", &present));
        if (present) CC_RETURN_IF_ERROR(SkipScalingList(r, i < 6 ? 16 : 64));
      }
    }
  }
  CC_RETURN_IF_ERROR(r.Ue("log2_max_frame_num_minus4", &v, 12));
  std::uint32_t poc_type = 0;
  CC_RETURN_IF_ERROR(r.Ue("pic_order_cnt_type", &poc_type, 2));
  if (poc_type == 0) {
    CC_RETURN_IF_ERROR(r.Ue("log2_max_pic_order_cnt_lsb_minus4", &v, 12));
  } else if (poc_type == 1) {
    constexpr std::int64_t kMax = (std::int64_t{1} << 31) - 1;
    CC_RETURN_IF_ERROR(r.U(1, "delta_pic_order_always_zero_flag", &v));
    CC_RETURN_IF_ERROR(r.Se("offset_for_non_ref_pic", -kMax, kMax));
    CC_RETURN_IF_ERROR(r.Se("offset_for_top_to_bottom_field", -kMax, kMax));
    std::uint32_t cycle = 0;
    CC_RETURN_IF_ERROR(r.Ue("num_ref_frames_in_pic_order_cnt_cycle", &cycle, 255));
    for (std::uint32_t i = 0; i < cycle; ++i) {
      CC_RETURN_IF_ERROR(r.Se("offset_for_ref_frame", -kMax, kMax));
    }
  }
  CC_RETURN_IF_ERROR(r.Ue("max_num_ref_frames", &h.max_num_ref_frames, 16));
  CC_RETURN_IF_ERROR(r.U(1, "gaps_in_frame_num_value_allowed_flag", &v));
  std::uint32_t width_mbs = 0, height_units = 0, frame_mbs_only = 0;
  // The largest value a ue(v) holds; the limits below are what bound the size.
  constexpr std::uint32_t kUeMax = 0xFFFFFFFEu;
  CC_RETURN_IF_ERROR(r.Ue("pic_width_in_mbs_minus1", &width_mbs, kUeMax));
  CC_RETURN_IF_ERROR(r.Ue("pic_height_in_map_units_minus1", &height_units, kUeMax));
  CC_RETURN_IF_ERROR(r.U(1, "frame_mbs_only_flag", &frame_mbs_only));
  if (!frame_mbs_only) {
    return r.Invalid("frame_mbs_only_flag", "0 (interlaced coding) is not taken; progressive only");
  }
  const std::uint64_t coded_w = (std::uint64_t{width_mbs} + 1) * 16;
  const std::uint64_t coded_h = (std::uint64_t{height_units} + 1) * 16;
  // The size is judged here, before any decoder exists for it: a header claiming 16k x 16k costs
  // the server these few bytes of parsing and nothing else.
  const char* over = coded_w > limits.max_side   ? "pic_width_in_mbs_minus1"
                     : coded_h > limits.max_side ? "pic_height_in_map_units_minus1"
                                                 : nullptr;
  if (over != nullptr) {
    return absl::ResourceExhaustedError(absl::StrCat(
        r.field(), ".", over, ": the sequence header claims ", coded_w, "x", coded_h,
        " pixels; this server takes at most ", limits.max_side, " pixels a side (max_side)"));
  }
  if (coded_w * coded_h > limits.max_pixels) {
    return absl::ResourceExhaustedError(
        absl::StrCat(r.field(), ".pic_width_in_mbs_minus1: the sequence header claims ", coded_w,
                     "x", coded_h, " = ", coded_w * coded_h, " pixels; this server takes at most ",
                     limits.max_pixels, " (max_pixels)"));
  }
  CC_RETURN_IF_ERROR(r.U(1, "direct_8x8_inference_flag", &v));
  std::uint32_t cropping = 0;
  CC_RETURN_IF_ERROR(r.U(1, "frame_cropping_flag", &cropping));
  std::uint64_t crop_x = 0, crop_y = 0;
  if (cropping) {
    std::uint32_t left = 0, right = 0, top = 0, bottom = 0;
    CC_RETURN_IF_ERROR(r.Ue("frame_crop_left_offset", &left, kUeMax));
    CC_RETURN_IF_ERROR(r.Ue("frame_crop_right_offset", &right, kUeMax));
    CC_RETURN_IF_ERROR(r.Ue("frame_crop_top_offset", &top, kUeMax));
    CC_RETURN_IF_ERROR(r.Ue("frame_crop_bottom_offset", &bottom, kUeMax));
    // CropUnitX and CropUnitY (progressive): 2 for 4:2:0's subsampled chroma, else 1.
    const std::uint64_t unit = h.chroma_format_idc == 1 ? 2 : 1;
    crop_x = unit * (std::uint64_t{left} + right);
    crop_y = unit * (std::uint64_t{top} + bottom);
    if (crop_x >= coded_w || crop_y >= coded_h) {
      return r.Invalid(
          crop_x >= coded_w ? "frame_crop_left_offset" : "frame_crop_top_offset",
          absl::StrCat("the cropping window (", crop_x, " columns, ", crop_y,
                       " rows) leaves nothing of the ", coded_w, "x", coded_h, " picture"));
    }
  }
  h.coded_width = static_cast<std::uint32_t>(coded_w);
  h.coded_height = static_cast<std::uint32_t>(coded_h);
  h.width = static_cast<std::uint32_t>(coded_w - crop_x);
  h.height = static_cast<std::uint32_t>(coded_h - crop_y);
  return h;
}

absl::StatusOr<AccessUnitInfo> InspectAccessUnit(std::string_view bytes, std::string_view field,
                                                 const Limits& limits) {
  if (bytes.empty()) return absl::InvalidArgumentError(absl::StrCat(S(field), " is empty"));
  const auto at = [&](std::size_t i) { return static_cast<std::uint8_t>(bytes[i]); };
  // Start codes: positions just after each 00 00 01.
  std::vector<std::size_t> starts;
  for (std::size_t i = 0; i + 2 < bytes.size(); ++i) {
    if (at(i) == 0 && at(i + 1) == 0 && at(i + 2) == 1) {
      starts.push_back(i + 3);
      i += 2;
    }
  }
  std::size_t first = 0;
  while (first < bytes.size() && at(first) == 0) ++first;
  if (starts.empty() || first != starts[0] - 1 || first < 2) {
    return absl::InvalidArgumentError(absl::StrCat(
        S(field),
        " is not an H.264 Annex B access unit: it must start with the start code 00 00 01 "
        "(or 00 00 00 01)"));
  }
  AccessUnitInfo info;
  bool non_idr = false;
  for (std::size_t n = 0; n < starts.size(); ++n) {
    std::size_t end = n + 1 < starts.size() ? starts[n + 1] - 3 : bytes.size();
    while (end > starts[n] && at(end - 1) == 0) --end;  // trailing_zero_8bits, or a 4-byte code
    const std::string nal_field = absl::StrCat(S(field), ".nal[", n, "]");
    if (end <= starts[n]) {
      return absl::InvalidArgumentError(absl::StrCat(nal_field, " is empty"));
    }
    NalUnit nal;
    nal.bytes = bytes.substr(starts[n], end - starts[n]);
    const std::uint8_t header = static_cast<std::uint8_t>(nal.bytes[0]);
    if (header & 0x80) {
      return absl::InvalidArgumentError(
          absl::StrCat(nal_field, ".forbidden_zero_bit is 1; it must be 0"));
    }
    nal.ref_idc = (header >> 5) & 3;
    nal.type = header & 31;
    if (nal.type == 0 || nal.type > 12) {
      return absl::InvalidArgumentError(
          absl::StrCat(nal_field, ".nal_unit_type is ", nal.type,
                       "; this decoder takes 1..12 (no SVC, MVC or 3D extension NAL units)"));
    }
    if (nal.type >= 2 && nal.type <= 4) {
      return absl::InvalidArgumentError(absl::StrCat(
          nal_field, ".nal_unit_type is ", nal.type,
          " (data partitioning, Extended profile); this decoder takes Baseline, Main and High"));
    }
    if (nal.type == kNalSliceIdr) info.idr = true;
    if (nal.type == kNalSlice) non_idr = true;
    if (nal.type == kNalSps) {
      if (info.sps) {
        return absl::InvalidArgumentError(
            absl::StrCat(nal_field, ": a second sequence parameter set in one access unit"));
      }
      auto sps = ParseSequenceHeader(nal.bytes, field, limits);
      if (!sps.ok()) return sps.status();
      info.sps = *sps;
    }
    info.nals.push_back(nal);
  }
  if (info.idr && non_idr) {
    return absl::InvalidArgumentError(absl::StrCat(
        S(field),
        " mixes IDR (nal_unit_type 5) and non-IDR (1) slices; one picture is one or the "
        "other"));
  }
  info.has_slices = info.idr || non_idr;
  return info;
}

}  // namespace cloudcast::video
