// The server's video frame path: access units of one stream through one video::Decoder (our
// Annex B / SPS parser, the size check and charge, then libavcodec's H.264 decoder), as the server
// keeps one per stream and role; and the RVL depth decoder. The input is a stream:
//   byte 0       bit 0: output BGR8 (else mono8); bit 1: a gap (RequireKeyframe) before unit 2;
//                bit 2: the rest is one RVL image instead (bit 3: 8-bit, else 16-bit samples)
//   then units   each a 2-byte big-endian length and that many bytes
// The limits are small (256 a side) so that each run stays fast; what they bound is the check.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string_view>
#include <vector>

#include "cloudcast/video/decoder.h"
#include "cloudcast/video/rvl.h"

using namespace cloudcast;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  if (data[0] & 4) {
    // The size the frame would declare: taken from the header itself, so that decoding runs.
    const std::string_view bytes(reinterpret_cast<const char*>(data + 1), size - 1);
    std::uint32_t w = 0, h = 0;
    if (bytes.size() >= 12) {
      for (int i = 0; i < 4; ++i)
        w |= std::uint32_t{static_cast<std::uint8_t>(bytes[4 + i])} << 8 * i;
      for (int i = 0; i < 4; ++i)
        h |= std::uint32_t{static_cast<std::uint8_t>(bytes[8 + i])} << 8 * i;
    }
    Limits limits;
    limits.max_side = 256;
    limits.max_pixels = 256 * 256;
    const std::uint32_t max = (data[0] & 8) ? 255 : 65535;
    std::vector<std::uint16_t> out;
    if (video::DecodeRvl(bytes, w, h, max, limits, "rvl", &out).ok()) {
      for (std::uint16_t v : out) {
        if (v > max) std::abort();
      }
      if (out.size() != std::size_t{w} * h) std::abort();
    }
    return 0;
  }
  video::Decoder::Options options;
  options.limits.max_side = 256;
  options.limits.max_pixels = 256 * 256;
  options.output = (data[0] & 1) ? ColorEncoding::kBGR8 : ColorEncoding::kMono8;
  std::uint64_t charged = 0;
  options.charge = [&](std::uint64_t bytes) {
    charged += bytes;
    return absl::OkStatus();
  };
  video::Decoder decoder(options);
  std::size_t at = 1;
  for (int unit = 0; at + 2 <= size && unit < 16; ++unit) {
    const std::size_t len = (std::size_t{data[at]} << 8) | data[at + 1];
    at += 2;
    const std::size_t take = len < size - at ? len : size - at;
    if (unit == 2 && (data[0] & 2)) decoder.RequireKeyframe();
    ColorView out;
    const absl::Status s = decoder.Decode(
        std::string_view(reinterpret_cast<const char*>(data + at), take), "au", &out);
    at += take;
    if (!s.ok()) {
      if (!decoder.needs_keyframe()) {
        std::fprintf(stderr, "an error left the decoder not asking for a keyframe\n");
        std::abort();
      }
      continue;
    }
    // The documented result: the stream's size, within the limits, charged before it was made.
    if (out.width == 0 || out.width > 256 || out.height == 0 || out.height > 256 ||
        out.width != decoder.width() || out.height != decoder.height() ||
        charged != decoder.charged_bytes() || charged == 0) {
      std::fprintf(stderr, "decoded %ux%u (stream %ux%u), charged %llu\n", out.width, out.height,
                   decoder.width(), decoder.height(), static_cast<unsigned long long>(charged));
      std::abort();
    }
    volatile std::uint8_t sink = 0;  // every byte of the picture is readable
    const std::uint8_t* p = static_cast<const std::uint8_t*>(out.data);
    for (std::size_t i = 0; i < out.size_bytes; i += 61) sink = sink ^ p[i];
    (void)sink;
  }
  return 0;
}
