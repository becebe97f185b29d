// What the server must know of an H.264 access unit before any decoder sees it: its NAL units
// (Annex B byte stream), whether it starts a stream (an IDR picture), and the sequence header
// (SPS) fields that size the decoder's memory. Parsed here, by us, so that a picture size is
// checked against the limits and charged before libavcodec allocates anything for it. Pure
// parsing: no FFmpeg, no allocation beyond the small vectors returned.
#pragma once

#include <cstdint>
#include <optional>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/core/limits.h"

namespace cloudcast::video {

// H.264 nal_unit_type values this layer acts on (ITU-T H.264 table 7-1).
enum NalType : std::uint8_t {
  kNalSlice = 1,
  kNalSliceIdr = 5,
  kNalSei = 6,
  kNalSps = 7,
  kNalPps = 8,
  kNalAccessUnitDelimiter = 9,
};

// One NAL unit of an access unit: the bytes after its start code, header byte included, without
// trailing zero bytes.
struct NalUnit {
  std::uint8_t type = 0;
  std::uint8_t ref_idc = 0;
  std::string_view bytes;
};

// The fields of a sequence parameter set that the decoder's memory and the stream's checks need.
struct SequenceHeader {
  std::uint32_t sps_id = 0;
  std::uint32_t profile_idc = 0;
  std::uint32_t level_idc = 0;
  std::uint32_t chroma_format_idc = 1;  // 0: grey (4:0:0), 1: 4:2:0, 3: 4:4:4
  std::uint32_t max_num_ref_frames = 0;
  std::uint32_t coded_width = 0;  // in whole macroblocks
  std::uint32_t coded_height = 0;
  std::uint32_t width = 0;  // after the cropping window: the picture's size
  std::uint32_t height = 0;
};

// An access unit split into NAL units, what it starts, and its SPS if it carries one.
struct AccessUnitInfo {
  std::vector<NalUnit> nals;
  bool has_slices = false;
  bool idr = false;  // an IDR picture: the stream may start (or restart) here
  std::optional<SequenceHeader> sps;
};

// Splits an Annex B byte stream (each NAL unit after a 00 00 01 or 00 00 00 01 start code) and
// parses every SPS in it. Checks, each error naming `field` (e.g. "frame.video.left.access_unit"):
// not empty and starting with a start code; every NAL unit non-empty, forbidden_zero_bit 0, a
// type this decoder takes (1..12; not the SVC/MVC/3D extensions); an SPS of 8-bit 4:0:0, 4:2:0 or
// 4:4:4, progressive (frame_mbs_only_flag 1), with a cropping window inside the picture; its
// picture size within `limits` (RESOURCE_EXHAUSTED naming the SPS field, before anything is
// allocated); at most one SPS and one IDR-or-not kind of slice. INVALID_ARGUMENT otherwise.
absl::StatusOr<AccessUnitInfo> InspectAccessUnit(std::string_view bytes, std::string_view field,
                                                 const Limits& limits);

// One SPS NAL unit (header byte included). Errors as above, naming `field`.sps.<member>.
absl::StatusOr<SequenceHeader> ParseSequenceHeader(std::string_view nal, std::string_view field,
                                                   const Limits& limits);

}  // namespace cloudcast::video
