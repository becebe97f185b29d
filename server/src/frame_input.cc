#include "frame_input.h"

#include <algorithm>
#include <cstring>
#include <string_view>
#include <type_traits>

#include "absl/strings/str_cat.h"
#include "cloudcast/proto/convert.h"
#include "cloudcast/stereo/budget.h"

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
        " is a JPEG: its lossy compression changes the values (disparities and depths must "
        "stay exact); send it raw, compressed, or as PNG, TIFF, PNM or PFM"));
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

namespace {

const ScatteredBytes* Plane(const InPlacePixels* in_place, const ScatteredBytes InPlacePixels::*p) {
  return in_place != nullptr ? &(in_place->*p) : nullptr;
}

// One image message of any kind (DisparityImage, DepthImage, ColorImage) into a view: raw pixels
// in place, compressed ones decompressed, encoded files decoded. `field` is its proto path
// ("frame.depth"); `decode` decodes a file of its kind.
template <typename Image, typename View, typename Owned, typename Decode>
absl::Status PrepareImage(const Image& image, const char* field, const Limits& limits,
                          const ScatteredBytes* in_place, bool lossless, Decode decode,
                          RowTable* rows, Owned* owned, PlaneDecompressor* codec, View* view,
                          bool* decoded) {
  const std::string f(field);
  switch (image.data_case()) {
    case Image::kRaw:
      return ViewRawImage(image.raw(), in_place, (f + ".raw").c_str(), limits, rows, view);
    case Image::kEncoded:
      *decoded = true;
      return DecodeChecked(image.encoded(), (f + ".encoded").c_str(), limits, lossless, decode,
                           owned, view);
    case Image::kCompressed:
      *decoded = true;
      return convert::DecodeCompressed(image.compressed(), f + ".compressed", limits, codec, view);
    default:
      return absl::InvalidArgumentError(
          absl::StrCat(f, " is missing: set ", f, ".raw, .compressed or .encoded"));
  }
}

}  // namespace

absl::Status PrepareFrameImages(const v1::Frame& frame, const Limits& limits,
                                DecodeScratch* scratch, FrameImages* out,
                                const InPlacePixels* in_place, const DecodedVideo* video) {
  out->decoded = false;
  const auto decode_colour = [](std::string_view b, const char* f) { return DecodeColor(b, f); };
  // A video picture was decoded when its frame was read (video_input.h): viewed here.
  const auto prepare_colour = [&](const v1::ColorImage& image, const char* field,
                                  const OwnedColor* picture, ColorView* view, auto prepare) {
    if (!image.has_video()) return prepare();
    if (picture == nullptr) {
      return absl::InvalidArgumentError(absl::StrCat(
          field, ".video: video pictures are decoded on Stream calls and Process calls only"));
    }
    out->decoded = true;
    *view = picture->view();
    return ValidateView(*view, limits, field);
  };
  absl::Status s;
  const char* geometry_field = "frame.disparity";
  switch (frame.geometry_case()) {
    case v1::Frame::kDisparity:
      out->kind = FrameKind::kDisparity;
      s = PrepareImage(
          frame.disparity(), "frame.disparity", limits, Plane(in_place, &InPlacePixels::disparity),
          /*lossless=*/true,
          [](std::string_view b, const char* f) { return DecodeDisparity(b, f); },
          &scratch->disparity_rows, &scratch->disparity, &scratch->disparity_codec, &out->disparity,
          &out->decoded);
      break;
    case v1::Frame::kDepth:
      out->kind = FrameKind::kDepth;
      geometry_field = "frame.depth";
      s = PrepareImage(
          frame.depth(), "frame.depth", limits, Plane(in_place, &InPlacePixels::depth),
          /*lossless=*/true, [](std::string_view b, const char* f) { return DecodeDepth(b, f); },
          &scratch->depth_rows, &scratch->depth, &scratch->depth_codec, &out->depth, &out->decoded);
      break;
    case v1::Frame::kRight:
      out->kind = FrameKind::kStereo;
      geometry_field = "frame.right";
      s = prepare_colour(frame.right(), "frame.right",
                         video != nullptr ? video->right_picture() : nullptr, &out->right, [&] {
                           return PrepareImage(frame.right(), "frame.right", limits,
                                               Plane(in_place, &InPlacePixels::right),
                                               /*lossless=*/false, decode_colour,
                                               &scratch->right_rows, &scratch->right,
                                               &scratch->right_codec, &out->right, &out->decoded);
                         });
      break;
    default:
      return absl::InvalidArgumentError(
          "frame.disparity is missing, and so are frame.depth and frame.right: set one (a "
          "disparity map, a depth image, or the right image of a stereo pair whose left is "
          "frame.color)");
  }
  if (!s.ok()) return s;
  s = prepare_colour(frame.color(), "frame.color",
                     video != nullptr ? video->colour_picture() : nullptr, &out->colour,
                     [&] {
                       return PrepareImage(frame.color(), "frame.color", limits,
                                           Plane(in_place, &InPlacePixels::colour),
                                           /*lossless=*/false, decode_colour, &scratch->colour_rows,
                                           &scratch->colour, &scratch->colour_codec, &out->colour,
                                           &out->decoded);
                     });
  if (!s.ok()) return s;
  switch (out->kind) {
    case FrameKind::kDisparity:
      return CheckSameSize(out->disparity, geometry_field, out->colour, "frame.color");
    case FrameKind::kDepth:
      return CheckSameSize(out->depth, geometry_field, out->colour, "frame.color");
    case FrameKind::kStereo:
      break;
  }
  return CheckSameSize(out->colour, "frame.color", out->right, geometry_field);
}

namespace {

// width x height as an image message states it, without decoding; 0 when it cannot tell.
template <typename Image>
std::uint64_t StatedPixels(const Image& image) {
  if (image.has_raw()) return std::uint64_t{image.raw().width()} * image.raw().height();
  if (image.has_compressed()) {
    return std::uint64_t{image.compressed().width()} * image.compressed().height();
  }
  if (image.has_encoded()) {
    std::uint32_t w = 0, h = 0;
    const char* format = nullptr;
    if (SniffImageSize(image.encoded(), &w, &h, &format)) return std::uint64_t{w} * h;
  }
  if constexpr (std::is_same_v<Image, v1::ColorImage>) {
    if (image.has_video()) return std::uint64_t{image.video().width()} * image.video().height();
  }
  return 0;
}

}  // namespace

std::uint64_t FramePixels(const v1::Frame& frame) {
  std::uint64_t pixels = 0;
  switch (frame.geometry_case()) {
    case v1::Frame::kDepth:
      pixels = StatedPixels(frame.depth());
      break;
    case v1::Frame::kRight:
      pixels = StatedPixels(frame.right());
      break;
    default:
      pixels = StatedPixels(frame.disparity());
  }
  return pixels > 0 ? pixels : 1;
}

namespace {

// One image's stated size: width x height, and the bytes decoding it takes (0 for raw pixels,
// which are in the message already).
struct ImageCost {
  std::uint64_t pixels = 0;
  std::uint32_t width = 0, height = 0;
  std::uint32_t max_side = 0;
  std::uint64_t decoded_bytes = 0;
};

template <typename Image, typename Encoding>
ImageCost CostOf(const Image& image) {
  ImageCost c;
  if (image.has_raw()) {
    c.width = image.raw().width();
    c.height = image.raw().height();
  } else if (image.has_compressed()) {
    c.width = image.compressed().width();
    c.height = image.compressed().height();
  } else if (image.has_encoded()) {
    const char* format = nullptr;
    if (!SniffImageSize(image.encoded(), &c.width, &c.height, &format)) c.width = c.height = 0;
  }
  bool video = false;
  if constexpr (std::is_same_v<Image, v1::ColorImage>) {
    if (image.has_video()) {
      video = true;
      c.width = image.video().width();
      c.height = image.video().height();
    }
  }
  c.pixels = std::uint64_t{c.width} * c.height;
  c.max_side = std::max(c.width, c.height);
  if (image.has_compressed()) {
    Encoding e{};
    const bool known = convert::FromProto(image.compressed().encoding(), "", &e).ok();
    c.decoded_bytes = c.pixels * (known ? BytesPerPixel(e) : 4);
  } else if (image.has_encoded()) {
    c.decoded_bytes = c.pixels * kEncodedImageBytesPerPixel / 2;
  } else if (video) {
    c.decoded_bytes = c.pixels * 3;  // the decoded picture the frame keeps: BGR8 at most
  }
  return c;
}

}  // namespace

FrameMemoryCost EstimateFrameMemory(const v1::Frame& frame, const StereoParams& stereo) {
  ImageCost g;  // the geometry's image
  switch (frame.geometry_case()) {
    case v1::Frame::kDepth:
      g = CostOf<v1::DepthImage, DepthEncoding>(frame.depth());
      break;
    case v1::Frame::kRight:
      g = CostOf<v1::ColorImage, ColorEncoding>(frame.right());
      break;
    default:
      g = CostOf<v1::DisparityImage, DisparityEncoding>(frame.disparity());
  }
  const ImageCost c = CostOf<v1::ColorImage, ColorEncoding>(frame.color());
  FrameMemoryCost cost;
  // Both images are decoded before their sizes are compared: each is charged its own.
  cost.pixels = std::max(g.pixels, c.pixels);
  cost.max_side = std::max(g.max_side, c.max_side);
  cost.decoded_bytes = g.decoded_bytes + c.decoded_bytes;
  cost.work_bytes = cost.decoded_bytes + cost.pixels * kWorkBytesPerPixel;
  if (frame.has_right()) {
    // The two grey images and the disparity map, and what the matcher allocates for this size
    // (OpenCV's SGBM modes were charged nothing before: 2 GB for a 128 KB request).
    cost.work_bytes += cost.pixels * 12 + stereo::MatchWorkBytes(stereo, std::max(g.width, c.width),
                                                                 std::max(g.height, c.height));
  }
  return cost;
}

}  // namespace cloudcast::server
