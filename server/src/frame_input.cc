#include "frame_input.h"

#include <algorithm>
#include <cstring>
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

// Points view->rows at the rows of `bytes` (the view's size was checked against bytes.size).
// A row is read in place when it and one byte after it lie in one piece (the kernels may load a
// 3-byte pixel with 4 bytes); otherwise it is copied into `table->bounce`, with a byte to spare.
// Rows (with their spare byte) do not overlap, so each piece's end is crossed by one row at most:
// the bounce buffer needs a slot per piece.
template <typename View>
void GatherRows(const ScatteredBytes& bytes, RowTable* table, View* view) {
  const std::size_t row_bytes = std::size_t{view->width} * BytesPerPixel(view->encoding);
  const std::size_t slot = row_bytes + 1;
  if (table->bounce.size() < bytes.pieces.size() * slot) {
    table->bounce.resize(bytes.pieces.size() * slot);
  }
  table->rows.resize(view->height);
  std::uint8_t* next = table->bounce.data();
  std::size_t piece = 0, piece_start = 0;
  for (std::uint32_t v = 0; v < view->height; ++v) {
    std::size_t at = std::size_t{v} * view->stride_bytes;
    while (at >= piece_start + bytes.pieces[piece].size()) {
      piece_start += bytes.pieces[piece++].size();
    }
    const std::string_view here = bytes.pieces[piece];
    if (at - piece_start + row_bytes < here.size()) {
      table->rows[v] = reinterpret_cast<const std::uint8_t*>(here.data()) + (at - piece_start);
      continue;
    }
    // Across pieces: gathered from those it spans.
    table->rows[v] = next;
    std::size_t p = piece, p_start = piece_start, left = row_bytes;
    while (left > 0) {
      const std::string_view s = bytes.pieces[p];
      const std::size_t take = std::min(left, s.size() - (at - p_start));
      std::memcpy(next, s.data() + (at - p_start), take);
      next += take, at += take, left -= take;
      p_start += s.size(), ++p;
    }
    *next++ = 0;  // the spare byte
  }
  view->rows = table->rows.data();
}

// Views a raw image: in the message, or in the pieces RequestReader left it in.
template <typename Raw, typename View>
absl::Status ViewRawImage(const Raw& raw, const ScatteredBytes* in_place, const char* field,
                          const Limits& limits, RowTable* table, View* view) {
  if (in_place == nullptr || in_place->size == 0) return convert::ViewRaw(raw, field, limits, view);
  const std::string_view first = in_place->pieces.front();
  if (absl::Status s = convert::ViewRaw(raw, std::string_view(first.data(), in_place->size), field,
                                        limits, view);
      !s.ok()) {
    return s;
  }
  if (in_place->pieces.size() > 1) GatherRows(*in_place, table, view);
  return absl::OkStatus();
}

}  // namespace

absl::Status PrepareFrameImages(const v1::Frame& frame, const Limits& limits,
                                DecodeScratch* scratch, FrameImages* out,
                                const InPlacePixels* in_place) {
  out->decoded = false;
  switch (frame.disparity().data_case()) {
    case v1::DisparityImage::kRaw:
      if (auto s = ViewRawImage(
              frame.disparity().raw(), in_place != nullptr ? &in_place->disparity : nullptr,
              "frame.disparity.raw", limits, &scratch->disparity_rows, &out->disparity);
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
      if (auto s =
              ViewRawImage(frame.colour().raw(), in_place != nullptr ? &in_place->colour : nullptr,
                           "frame.colour.raw", limits, &scratch->colour_rows, &out->colour);
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

namespace {

// One image's stated size: width x height, and the bytes decoding it takes (0 for raw pixels,
// which are in the message already).
struct ImageCost {
  std::uint64_t pixels = 0;
  std::uint32_t max_side = 0;
  std::uint64_t decoded_bytes = 0;
};

template <typename Image, typename Encoding>
ImageCost CostOf(const Image& image) {
  ImageCost c;
  if (image.has_raw()) {
    c.pixels = std::uint64_t{image.raw().width()} * image.raw().height();
    c.max_side = std::max(image.raw().width(), image.raw().height());
  } else if (image.has_compressed()) {
    c.pixels = std::uint64_t{image.compressed().width()} * image.compressed().height();
    c.max_side = std::max(image.compressed().width(), image.compressed().height());
    Encoding e{};
    const bool known = convert::FromProto(image.compressed().encoding(), "", &e).ok();
    c.decoded_bytes = c.pixels * (known ? BytesPerPixel(e) : 4);
  } else if (image.has_encoded()) {
    std::uint32_t w = 0, h = 0;
    const char* format = nullptr;
    if (SniffImageSize(image.encoded(), &w, &h, &format)) c.pixels = std::uint64_t{w} * h;
    c.max_side = std::max(w, h);
    c.decoded_bytes = c.pixels * kEncodedImageBytesPerPixel / 2;
  }
  return c;
}

}  // namespace

FrameMemoryCost EstimateFrameMemory(const v1::Frame& frame) {
  const ImageCost d = CostOf<v1::DisparityImage, DisparityEncoding>(frame.disparity());
  const ImageCost c = CostOf<v1::ColorImage, ColorEncoding>(frame.colour());
  FrameMemoryCost cost;
  // Both images are decoded before their sizes are compared: each is charged its own.
  cost.pixels = std::max(d.pixels, c.pixels);
  cost.max_side = std::max(d.max_side, c.max_side);
  cost.decoded_bytes = d.decoded_bytes + c.decoded_bytes;
  cost.work_bytes = cost.decoded_bytes + cost.pixels * kWorkBytesPerPixel;
  return cost;
}

}  // namespace cloudcast::server
