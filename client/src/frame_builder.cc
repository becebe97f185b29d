#include "frame_builder.h"

#include <chrono>
#include <cstdint>
#include <string>

#include "absl/strings/str_cat.h"
#include "cloudcast/proto/convert.h"

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

absl::Status FillImages(const DisparityInput& disparity, const ColorInput& colour,
                        v1::Frame* frame) {
  v1::DisparityImage* d = frame->mutable_disparity();
  if (const auto* view = std::get_if<DisparityView>(&disparity)) {
    if (absl::Status s = convert::ToProto(*view, "disparity", d->mutable_raw()); !s.ok()) return s;
  } else if (const auto* c = std::get_if<CompressedDisparityView>(&disparity)) {
    if (absl::Status s =
            convert::ToProto(c->view, c->compression, "disparity", d->mutable_compressed());
        !s.ok()) {
      return s;
    }
  } else if (const auto* p = std::get_if<PrecompressedDisparity>(&disparity)) {
    if (p->message == nullptr) return absl::InvalidArgumentError("disparity message is null");
    *d->mutable_compressed() = *p->message;
  } else {
    const auto& encoded = std::get<EncodedImage>(disparity);
    if (absl::Status s = CheckEncoded(encoded, "disparity"); !s.ok()) return s;
    d->set_encoded(encoded.bytes.data(), encoded.bytes.size());
  }

  v1::ColorImage* c = frame->mutable_colour();
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

}  // namespace internal
}  // namespace cloudcast::client
