#include "frame_builder.h"

#include <chrono>
#include <cstdint>
#include <string>

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

ColorInput CompressRaw(const ColorInput& input, const convert::Compression& compression) {
  if (const auto* view = std::get_if<ColorView>(&input)) return Compressed(*view, compression);
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

absl::Status FillColour(const ColorInput& colour, v1::ColorImage* c) {
  if (const auto* view = std::get_if<ColorView>(&colour)) {
    return convert::ToProto(*view, "colour", c->mutable_raw());
  }
  if (const auto* cv = std::get_if<CompressedColorView>(&colour)) {
    return convert::ToProto(cv->view, cv->compression, "colour", c->mutable_compressed());
  }
  if (const auto* p = std::get_if<PrecompressedColor>(&colour)) {
    if (p->message == nullptr) return absl::InvalidArgumentError("colour message is null");
    *c->mutable_compressed() = *p->message;
    return absl::OkStatus();
  }
  if (const auto* view = std::get_if<BgraView>(&colour)) {
    return convert::BgraToProto(view->data, view->size_bytes, view->width, view->height,
                                view->stride_bytes, "colour", c->mutable_raw());
  }
  const auto& encoded = std::get<EncodedImage>(colour);
  if (absl::Status s = CheckEncoded(encoded, "colour"); !s.ok()) return s;
  c->set_encoded(encoded.bytes.data(), encoded.bytes.size());
  return absl::OkStatus();
}

absl::Status FillImages(const DisparityInput& disparity, const ColorInput& colour,
                        v1::Frame* frame) {
  if (absl::Status s = FillDisparity(disparity, frame->mutable_disparity()); !s.ok()) return s;
  return FillColour(colour, frame->mutable_colour());
}

std::uint64_t ImageBytes(const v1::Frame& frame) {
  const v1::DisparityImage& d = frame.disparity();
  const v1::ColorImage& c = frame.colour();
  return d.raw().pixels().size() + d.encoded().size() + d.compressed().payload().size() +
         c.raw().pixels().size() + c.encoded().size() + c.compressed().payload().size();
}

void FillMeta(const FrameMeta& meta, std::uint64_t sequence, v1::Frame* frame) {
  frame->set_sequence(sequence);
  frame->set_capture_time_unix_ns(meta.capture_time_unix_ns != 0 ? meta.capture_time_unix_ns
                                                                 : UnixNanosNow());
  frame->set_frame_id(meta.frame_id);
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

absl::Status RequestWriter::Write(const DisparityInput& disparity, const ColorInput& colour,
                                  const FrameMeta& meta, std::uint64_t sequence,
                                  grpc::ByteBuffer* out) {
  v1::Frame* frame = request_.mutable_frame();
  // Raw views get every field but their pixels, which go in slices of their own below.
  const auto* disparity_view = std::get_if<DisparityView>(&disparity);
  const auto* colour_view = std::get_if<ColorView>(&colour);
  if (absl::Status s =
          disparity_view != nullptr
              ? convert::ToProtoWithoutPixels(*disparity_view, "disparity",
                                              frame->mutable_disparity()->mutable_raw())
              : FillDisparity(disparity, frame->mutable_disparity());
      !s.ok()) {
    return s;
  }
  if (absl::Status s = colour_view != nullptr
                           ? convert::ToProtoWithoutPixels(*colour_view, "colour",
                                                           frame->mutable_colour()->mutable_raw())
                           : FillColour(colour, frame->mutable_colour());
      !s.ok()) {
    return s;
  }
  FillMeta(meta, sequence, frame);
  image_bytes_ = ImageBytes(*frame);

  head_.clear();
  request_.AppendToString(&head_);
  grpc::Slice slices[5];  // at most: head, disparity pixels, their header, colour pixels, tail
  std::size_t n = 0;
  // The bytes so far, the pixels' headers, then the pixels in a slice of their own.
  auto add_pixels = [&](const auto& view, int image_field) {
    grpc::Slice pixels = PixelSlice(view);
    PutPixelsHeader(image_field, pixels.size(), &head_);
    slices[n++] = grpc::Slice(head_);
    head_.clear();
    image_bytes_ += pixels.size();
    slices[n++] = std::move(pixels);
  };
  if (disparity_view != nullptr) add_pixels(*disparity_view, v1::Frame::kDisparityFieldNumber);
  if (colour_view != nullptr) add_pixels(*colour_view, v1::Frame::kColourFieldNumber);
  if (!head_.empty()) slices[n++] = grpc::Slice(head_);
  grpc::ByteBuffer bytes(slices, n);
  out->Swap(&bytes);
  return absl::OkStatus();
}

}  // namespace internal
}  // namespace cloudcast::client
