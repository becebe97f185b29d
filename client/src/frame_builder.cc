#include "frame_builder.h"

#include <chrono>
#include <cstdint>
#include <string>
#include <type_traits>
#include <utility>
#include <variant>

#include "absl/strings/str_cat.h"
#include "cloudcast/proto/convert.h"
#include "cloudcast/proto/wire.h"

namespace cloudcast::client {

std::int64_t UnixNanosNow() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

DisparityInput CompressRaw(const DisparityInput& input, const convert::Compression& compression) {
  if (const auto* view = std::get_if<DisparityView>(&input)) return Compressed(*view, compression);
  return input;
}

DepthInput CompressRaw(const DepthInput& input, const convert::Compression& compression) {
  if (const auto* view = std::get_if<DepthView>(&input)) return Compressed(*view, compression);
  return input;
}

ColorInput CompressRaw(const ColorInput& input, const convert::Compression& compression) {
  if (const auto* view = std::get_if<ColorView>(&input)) return Compressed(*view, compression);
  return input;
}

FrameInput CompressRaw(const FrameInput& input, const convert::Compression& compression) {
  if (const auto* f = std::get_if<DisparityFrame>(&input)) {
    return DisparityFrame{CompressRaw(f->disparity, compression),
                          CompressRaw(f->colour, compression)};
  }
  if (const auto* f = std::get_if<DepthFrame>(&input)) {
    return DepthFrame{CompressRaw(f->depth, compression), CompressRaw(f->colour, compression)};
  }
  const auto& f = std::get<StereoFrame>(input);
  return StereoFrame{CompressRaw(f.left, compression), CompressRaw(f.right, compression)};
}

FrameInput CompressGeometry(const FrameInput& input, const convert::Compression& compression) {
  if (const auto* f = std::get_if<DisparityFrame>(&input)) {
    return DisparityFrame{CompressRaw(f->disparity, compression), f->colour};
  }
  if (const auto* f = std::get_if<DepthFrame>(&input)) {
    return DepthFrame{CompressRaw(f->depth, compression), f->colour};
  }
  return input;
}

namespace internal {
namespace {

absl::Status CheckEncoded(const EncodedImage& image, const char* field) {
  if (image.bytes.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(field, " encoded image holds no bytes"));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status FillDisparity(const DisparityInput& disparity, v1::DisparityImage* d) {
  if (const auto* view = std::get_if<DisparityView>(&disparity)) {
    return convert::ToProto(*view, "disparity", d->mutable_raw());
  }
  if (const auto* c = std::get_if<CompressedDisparityView>(&disparity)) {
    return convert::ToProto(c->view, c->compression, "disparity", d->mutable_compressed());
  }
  if (const auto* p = std::get_if<PrecompressedDisparity>(&disparity)) {
    if (p->message == nullptr) return absl::InvalidArgumentError("disparity message is null");
    *d->mutable_compressed() = *p->message;
    return absl::OkStatus();
  }
  const auto& encoded = std::get<EncodedImage>(disparity);
  if (absl::Status s = CheckEncoded(encoded, "disparity"); !s.ok()) return s;
  d->set_encoded(encoded.bytes.data(), encoded.bytes.size());
  return absl::OkStatus();
}

absl::Status FillDepth(const DepthInput& depth, v1::DepthImage* d) {
  if (const auto* view = std::get_if<DepthView>(&depth)) {
    return convert::ToProto(*view, "depth", d->mutable_raw());
  }
  if (const auto* c = std::get_if<CompressedDepthView>(&depth)) {
    return convert::ToProto(c->view, c->compression, "depth", d->mutable_compressed());
  }
  if (const auto* p = std::get_if<PrecompressedDepth>(&depth)) {
    if (p->message == nullptr) return absl::InvalidArgumentError("depth message is null");
    *d->mutable_compressed() = *p->message;
    return absl::OkStatus();
  }
  const auto& encoded = std::get<EncodedImage>(depth);
  if (absl::Status s = CheckEncoded(encoded, "depth"); !s.ok()) return s;
  d->set_encoded(encoded.bytes.data(), encoded.bytes.size());
  return absl::OkStatus();
}

absl::Status FillColour(const ColorInput& colour, v1::ColorImage* c, const char* field) {
  if (const auto* view = std::get_if<ColorView>(&colour)) {
    return convert::ToProto(*view, field, c->mutable_raw());
  }
  if (const auto* cv = std::get_if<CompressedColorView>(&colour)) {
    return convert::ToProto(cv->view, cv->compression, field, c->mutable_compressed());
  }
  if (const auto* p = std::get_if<PrecompressedColor>(&colour)) {
    if (p->message == nullptr) {
      return absl::InvalidArgumentError(absl::StrCat(field, " message is null"));
    }
    *c->mutable_compressed() = *p->message;
    return absl::OkStatus();
  }
  if (const auto* v = std::get_if<PrecodedVideo>(&colour)) {
    if (v->message == nullptr) {
      return absl::InvalidArgumentError(absl::StrCat(field, " video picture is null"));
    }
    *c->mutable_video() = *v->message;
    return absl::OkStatus();
  }
  if (const auto* view = std::get_if<BgraView>(&colour)) {
    return convert::BgraToProto(view->data, view->size_bytes, view->width, view->height,
                                view->stride_bytes, field, c->mutable_raw());
  }
  const auto& encoded = std::get<EncodedImage>(colour);
  if (absl::Status s = CheckEncoded(encoded, field); !s.ok()) return s;
  c->set_encoded(encoded.bytes.data(), encoded.bytes.size());
  return absl::OkStatus();
}

absl::Status FillImages(const FrameInput& input, v1::Frame* frame) {
  if (const auto* f = std::get_if<DisparityFrame>(&input)) {
    if (absl::Status s = FillDisparity(f->disparity, frame->mutable_disparity()); !s.ok()) {
      return s;
    }
    return FillColour(f->colour, frame->mutable_color());
  }
  if (const auto* f = std::get_if<DepthFrame>(&input)) {
    if (absl::Status s = FillDepth(f->depth, frame->mutable_depth()); !s.ok()) return s;
    return FillColour(f->colour, frame->mutable_color());
  }
  const auto& f = std::get<StereoFrame>(input);
  if (absl::Status s = FillColour(f.left, frame->mutable_color(), "left"); !s.ok()) return s;
  return FillColour(f.right, frame->mutable_right(), "right");
}

namespace {

template <typename Image>
std::uint64_t BytesOf(const Image& image) {
  return image.raw().pixels().size() + image.encoded().size() + image.compressed().payload().size();
}

}  // namespace

std::uint64_t ImageBytes(const v1::Frame& frame) {
  return BytesOf(frame.disparity()) + BytesOf(frame.depth()) + BytesOf(frame.color()) +
         BytesOf(frame.right()) + frame.color().video().access_unit().size() +
         frame.right().video().access_unit().size();
}

void FillMeta(const FrameMeta& meta, std::uint64_t sequence, v1::Frame* frame) {
  frame->set_sequence(sequence);
  frame->set_capture_time_unix_ns(meta.capture_time_unix_ns != 0 ? meta.capture_time_unix_ns
                                                                 : UnixNanosNow());
  frame->set_frame_id(meta.frame_id);
  if (meta.camera.has_value()) {
    *frame->mutable_camera() = *meta.camera;
  } else {
    frame->clear_camera();  // a reused Frame must not keep an earlier frame's camera
  }
}

namespace {

// Appends frame { <image_field> { raw { pixels: <n bytes> } } } up to the pixels themselves.
void PutPixelsHeader(int image_field, std::size_t n, std::string* out) {
  static_assert(static_cast<int>(v1::DisparityImage::kRawFieldNumber) ==
                    static_cast<int>(v1::ColorImage::kRawFieldNumber) &&
                static_cast<int>(v1::RawDisparity::kPixelsFieldNumber) ==
                    static_cast<int>(v1::RawColor::kPixelsFieldNumber));
  const std::uint64_t path[4] = {
      v1::StreamRequest::kFrameFieldNumber, static_cast<std::uint64_t>(image_field),
      v1::DisparityImage::kRawFieldNumber, v1::RawDisparity::kPixelsFieldNumber};
  wire::PutNestedHeaders(path, 4, n, out);
}

// The rows of `view`, packed, in a slice of their own (the one copy).
template <typename View>
grpc::Slice PixelSlice(const View& view) {
  grpc::Slice slice(convert::PackedBytes(view));
  convert::PackRows(view, const_cast<std::uint8_t*>(slice.begin()));
  return slice;
}

}  // namespace

namespace {

// An image of the frame whose raw pixels go in a slice of their own: its field number in the
// Frame and its view; field 0 when the image is not raw.
struct RawPlane {
  int field = 0;
  std::variant<DisparityView, DepthView, ColorView> view;
};

// Fills one image message, or only its header when it is raw (the pixels go apart), noting the
// raw plane.
template <typename View, typename Input, typename Image, typename Raw, typename Fill>
absl::Status FillOrHeader(const Input& input, int field, const char* name, Image* image,
                          Raw* (Image::*mutable_raw)(), Fill fill, RawPlane* plane) {
  if (const auto* view = std::get_if<View>(&input)) {
    *plane = RawPlane{field, *view};
    return convert::ToProtoWithoutPixels(*view, name, (image->*mutable_raw)());
  }
  return fill(input, image);
}

}  // namespace

absl::Status RequestWriter::Write(const FrameInput& input, const FrameMeta& meta,
                                  std::uint64_t sequence, grpc::ByteBuffer* out) {
  v1::Frame* frame = request_.mutable_frame();
  // Raw views get every field but their pixels, which go in slices of their own below. The
  // geometry is written first, then the colour: their order on the wire is the proto's
  // field order either way.
  RawPlane planes[2];
  absl::Status s;
  const auto fill_colour = [](const char* name) {
    return
        [name](const ColorInput& c, v1::ColorImage* image) { return FillColour(c, image, name); };
  };
  if (const auto* f = std::get_if<DisparityFrame>(&input)) {
    s = FillOrHeader<DisparityView>(f->disparity, v1::Frame::kDisparityFieldNumber, "disparity",
                                    frame->mutable_disparity(), &v1::DisparityImage::mutable_raw,
                                    FillDisparity, &planes[0]);
    if (s.ok()) {
      s = FillOrHeader<ColorView>(f->colour, v1::Frame::kColorFieldNumber, "colour",
                                  frame->mutable_color(), &v1::ColorImage::mutable_raw,
                                  fill_colour("colour"), &planes[1]);
    }
  } else if (const auto* f = std::get_if<DepthFrame>(&input)) {
    s = FillOrHeader<DepthView>(f->depth, v1::Frame::kDepthFieldNumber, "depth",
                                frame->mutable_depth(), &v1::DepthImage::mutable_raw, FillDepth,
                                &planes[0]);
    if (s.ok()) {
      s = FillOrHeader<ColorView>(f->colour, v1::Frame::kColorFieldNumber, "colour",
                                  frame->mutable_color(), &v1::ColorImage::mutable_raw,
                                  fill_colour("colour"), &planes[1]);
    }
  } else {
    const auto& pair = std::get<StereoFrame>(input);
    s = FillOrHeader<ColorView>(pair.left, v1::Frame::kColorFieldNumber, "left",
                                frame->mutable_color(), &v1::ColorImage::mutable_raw,
                                fill_colour("left"), &planes[0]);
    if (s.ok()) {
      s = FillOrHeader<ColorView>(pair.right, v1::Frame::kRightFieldNumber, "right",
                                  frame->mutable_right(), &v1::ColorImage::mutable_raw,
                                  fill_colour("right"), &planes[1]);
    }
  }
  if (!s.ok()) return s;
  FillMeta(meta, sequence, frame);
  image_bytes_ = ImageBytes(*frame);

  head_.clear();
  request_.AppendToString(&head_);
  grpc::Slice slices[5];  // at most: head, pixels, their header, pixels, tail
  std::size_t n = 0;
  // The bytes so far, the pixels' headers, then the pixels in a slice of their own.
  for (const RawPlane& plane : planes) {
    if (plane.field == 0) continue;
    grpc::Slice pixels = std::visit([](const auto& view) { return PixelSlice(view); }, plane.view);
    PutPixelsHeader(plane.field, pixels.size(), &head_);
    slices[n++] = grpc::Slice(head_);
    head_.clear();
    image_bytes_ += pixels.size();
    slices[n++] = std::move(pixels);
  }
  if (!head_.empty()) slices[n++] = grpc::Slice(head_);
  grpc::ByteBuffer bytes(slices, n);
  out->Swap(&bytes);
  return absl::OkStatus();
}

template <typename View>
absl::Status HeldFrame::Keep(const View& view, const char* field, View* out) {
  // The same checks as the request's (ToProtoWithoutPixels), then the rows packed.
  typename std::conditional_t<
      std::is_same_v<View, DisparityView>, v1::RawDisparity,
      std::conditional_t<std::is_same_v<View, DepthView>, v1::RawDepth, v1::RawColor>>
      scratch;
  if (absl::Status s = convert::ToProtoWithoutPixels(view, field, &scratch); !s.ok()) return s;
  std::string& pixels = bytes_.emplace_back(convert::PackedBytes(view), '\0');
  convert::PackRows(view, pixels.data());
  *out = view;
  out->data = pixels.data();
  out->size_bytes = pixels.size();
  out->stride_bytes = view.height > 0 ? pixels.size() / view.height : 0;
  out->rows = nullptr;
  return absl::OkStatus();
}

template <typename Input>
absl::Status HeldFrame::KeepImage(const Input& in, const char* field, Input* out) {
  return std::visit(
      [&](const auto& image) -> absl::Status {
        using T = std::decay_t<decltype(image)>;
        if constexpr (std::is_same_v<T, DisparityView> || std::is_same_v<T, DepthView> ||
                      std::is_same_v<T, ColorView>) {
          T kept;
          if (absl::Status s = Keep(image, field, &kept); !s.ok()) return s;
          *out = kept;
        } else if constexpr (std::is_same_v<T, CompressedDisparityView> ||
                             std::is_same_v<T, CompressedDepthView> ||
                             std::is_same_v<T, CompressedColorView>) {
          T kept = image;
          if (absl::Status s = Keep(image.view, field, &kept.view); !s.ok()) return s;
          *out = kept;
        } else if constexpr (std::is_same_v<T, EncodedImage>) {
          if (absl::Status s = CheckEncoded(image, field); !s.ok()) return s;
          *out = EncodedImage{bytes_.emplace_back(image.bytes)};
        } else if constexpr (std::is_same_v<T, BgraView>) {
          // Kept as BGR8 (what Send makes of it), checked as Send checks it.
          v1::RawColor raw;
          if (absl::Status s = convert::BgraToProto(image.data, image.size_bytes, image.width,
                                                    image.height, image.stride_bytes, field, &raw);
              !s.ok()) {
            return s;
          }
          std::string& pixels = bytes_.emplace_back(std::move(*raw.mutable_pixels()));
          // ColorView, named through T so that the assignment below depends on this lambda's
          // parameter: clang checks a discarded branch's non-dependent code for every Input.
          std::conditional_t<std::is_same_v<T, BgraView>, ColorView, T> kept;
          kept.data = pixels.data();
          kept.size_bytes = pixels.size();
          kept.width = image.width;
          kept.height = image.height;
          kept.stride_bytes = static_cast<std::size_t>(image.width) * 3;
          kept.encoding = ColorEncoding::kBGR8;
          *out = kept;
        } else {
          // A message made earlier (precompressed, precoded video): copied.
          if (image.message == nullptr) {
            return absl::InvalidArgumentError(absl::StrCat(field, " message is null"));
          }
          using M = std::decay_t<decltype(*image.message)>;
          auto copy = std::make_shared<M>(*image.message);
          messages_.push_back(copy);
          *out = T{copy.get()};
        }
        return absl::OkStatus();
      },
      in);
}

absl::Status HeldFrame::Hold(const FrameInput& input) {
  bytes_.clear();
  messages_.clear();
  if (const auto* f = std::get_if<DisparityFrame>(&input)) {
    DisparityFrame kept;
    if (absl::Status s = KeepImage(f->disparity, "disparity", &kept.disparity); !s.ok()) return s;
    if (absl::Status s = KeepImage(f->colour, "colour", &kept.colour); !s.ok()) return s;
    input_ = kept;
  } else if (const auto* d = std::get_if<DepthFrame>(&input)) {
    DepthFrame kept;
    if (absl::Status s = KeepImage(d->depth, "depth", &kept.depth); !s.ok()) return s;
    if (absl::Status s = KeepImage(d->colour, "colour", &kept.colour); !s.ok()) return s;
    input_ = kept;
  } else {
    const auto& pair = std::get<StereoFrame>(input);
    StereoFrame kept;
    if (absl::Status s = KeepImage(pair.left, "left", &kept.left); !s.ok()) return s;
    if (absl::Status s = KeepImage(pair.right, "right", &kept.right); !s.ok()) return s;
    input_ = kept;
  }
  return absl::OkStatus();
}

}  // namespace internal
}  // namespace cloudcast::client
