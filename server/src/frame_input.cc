#include "frame_input.h"

#include <string_view>

#include "absl/strings/str_cat.h"
#include "cloudcast/proto/convert.h"

namespace cloudcast::server {
namespace {

// Decodes `bytes` into `owned` and views it. Formats the header check cannot size are refused
// before the decoder runs; the decoded size is checked again (a TIFF may hold several pages).
// `lossless` refuses JPEG, whose compression changes the values (disparities must stay exact).
template <typename Owned, typename View, typename Decode>
absl::Status DecodeChecked(std::string_view bytes, const char* field, const Limits& limits,
                           bool lossless, Decode decode, Owned* owned, View* view) {
  const char* format = nullptr;
  if (absl::Status s = CheckEncodedImage(bytes, field, limits, &format); !s.ok()) return s;
  if (lossless && std::string_view(format) == "JPEG") {
    return absl::InvalidArgumentError(absl::StrCat(
        field,
        " is a JPEG: its lossy compression changes disparity values; send it raw or as "
        "PNG, TIFF, PNM or PFM"));
  }
  auto decoded = decode(bytes, field);
  if (!decoded.ok()) return decoded.status();
  *owned = *std::move(decoded);
  *view = owned->view();
  return ValidateView(*view, limits, field);
}

}  // namespace

absl::Status PrepareFrameImages(const v1::Frame& frame, const Limits& limits,
                                DecodeScratch* scratch, FrameImages* out) {
  out->decoded = false;
  switch (frame.disparity().data_case()) {
    case v1::DisparityImage::kRaw:
      if (auto s = convert::ViewRaw(frame.disparity().raw(), "frame.disparity.raw", limits,
                                    &out->disparity);
          !s.ok()) {
        return s;
      }
      break;
    case v1::DisparityImage::kEncoded:
      if (auto s = DecodeChecked(
              frame.disparity().encoded(), "frame.disparity.encoded", limits, /*lossless=*/true,
              [](std::string_view b, const char* f) { return DecodeDisparity(b, f); },
              &scratch->disparity, &out->disparity);
          !s.ok()) {
        return s;
      }
      out->decoded = true;
      break;
    case v1::DisparityImage::kCompressed:
      if (auto s = convert::DecodeCompressed(frame.disparity().compressed(),
                                             "frame.disparity.compressed", limits,
                                             &scratch->disparity_codec, &out->disparity);
          !s.ok()) {
        return s;
      }
      out->decoded = true;
      break;
    default:
      return absl::InvalidArgumentError(
          "frame.disparity is missing: set frame.disparity.raw, .compressed or .encoded");
  }
  switch (frame.colour().data_case()) {
    case v1::ColorImage::kRaw:
      if (auto s = convert::ViewRaw(frame.colour().raw(), "frame.colour.raw", limits, &out->colour);
          !s.ok()) {
        return s;
      }
      break;
    case v1::ColorImage::kEncoded:
      if (auto s = DecodeChecked(
              frame.colour().encoded(), "frame.colour.encoded", limits, /*lossless=*/false,
              [](std::string_view b, const char* f) { return DecodeColor(b, f); }, &scratch->colour,
              &out->colour);
          !s.ok()) {
        return s;
      }
      out->decoded = true;
      break;
    case v1::ColorImage::kCompressed:
      if (auto s = convert::DecodeCompressed(frame.colour().compressed(), "frame.colour.compressed",
                                             limits, &scratch->colour_codec, &out->colour);
          !s.ok()) {
        return s;
      }
      out->decoded = true;
      break;
    default:
      return absl::InvalidArgumentError(
          "frame.colour is missing: set frame.colour.raw, .compressed or .encoded");
  }
  return CheckSameSize(out->disparity, "frame.disparity", out->colour, "frame.colour");
}

std::uint64_t FramePixels(const v1::Frame& frame) {
  const v1::DisparityImage& d = frame.disparity();
  std::uint64_t pixels = 0;
  if (d.has_raw()) {
    pixels = std::uint64_t{d.raw().width()} * d.raw().height();
  } else if (d.has_compressed()) {
    pixels = std::uint64_t{d.compressed().width()} * d.compressed().height();
  } else if (d.has_encoded()) {
    std::uint32_t w = 0, h = 0;
    const char* format = nullptr;
    if (SniffImageSize(d.encoded(), &w, &h, &format)) pixels = std::uint64_t{w} * h;
  }
  return pixels > 0 ? pixels : 1;
}

}  // namespace cloudcast::server
