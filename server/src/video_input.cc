#include "video_input.h"

#include <chrono>
#include <cstring>
#include <utility>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/checks.h"
#include "cloudcast/video/decoder.h"
#include "cloudcast/video/h264_bitstream.h"

namespace cloudcast::server {

void DecodedVideo::Clear() {
  has_colour = has_right = false;
  keyframe_needed.clear();
  decode_seconds = 0;
  // The pixel buffers keep their capacity for the next frame of this slot.
}

std::vector<v1::VideoCodec> DecodedVideoCodecs() { return {v1::VIDEO_CODEC_H264}; }

// One bitstream: its decoder (made at its first sequence header, whose chroma format decides
// what it outputs: grey for a 4:0:0 bitstream, BGR otherwise) and the picture_index it expects.
struct VideoDecoders::Bitstream {
  explicit Bitstream(v1::VideoBitstream id) : id(id) {}
  const v1::VideoBitstream id;
  std::unique_ptr<video::Decoder> decoder;
  std::optional<std::uint64_t> next_index;

  // Whether the next picture must be an IDR.
  bool needs_keyframe() const { return decoder == nullptr || decoder->needs_keyframe(); }
  // This bitstream lost a picture: what follows cannot be decoded until an IDR.
  void Lost() {
    if (decoder != nullptr) decoder->RequireKeyframe();
  }
};

VideoDecoders::VideoDecoders(const Limits& limits, Charge charge, Release release)
    : limits_(limits), charge_(std::move(charge)), release_(std::move(release)) {}

VideoDecoders::~VideoDecoders() = default;  // each decoder gives its charge back

bool VideoDecoders::HasVideo(const v1::Frame& frame) {
  return frame.color().has_video() || frame.right().has_video();
}

namespace {

// The picture's own fields, before its bytes are looked at.
absl::Status CheckPicture(const v1::VideoPicture& p, const std::string& field,
                          const Limits& limits) {
  if (p.codec() != v1::VIDEO_CODEC_H264) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, ".codec is ", v1::VideoCodec_Name(p.codec()),
                     ": this server decodes VIDEO_CODEC_H264 (ServerInfo.video_codecs)"));
  }
  if (absl::Status s = check::ImageSize(field, p.width(), p.height(), limits); !s.ok()) return s;
  if (p.access_unit().empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, ".access_unit is empty: a picture is one access unit"));
  }
  return absl::OkStatus();
}

void CopyPicture(const ColorView& view, OwnedColor* out) {
  out->width = view.width;
  out->height = view.height;
  out->encoding = view.encoding;
  const std::size_t row = std::size_t{view.width} * BytesPerPixel(view.encoding);
  out->pixels.resize(row * view.height);
  for (std::uint32_t v = 0; v < view.height; ++v) {
    std::memcpy(out->pixels.data() + v * row,
                static_cast<const std::uint8_t*>(view.data) + v * view.stride_bytes, row);
  }
}

}  // namespace

absl::Status VideoDecoders::DecodePicture(const v1::VideoPicture& picture, const std::string& field,
                                          Bitstream* b, OwnedColor* out) {
  // A jump in the numbering: pictures were lost before this one, and it may reference them.
  const bool gap = b->next_index.has_value() && picture.picture_index() != *b->next_index;
  b->next_index = picture.picture_index() + 1;
  if (gap) b->Lost();
  if (absl::Status s = CheckPicture(picture, field, limits_); !s.ok()) {
    b->Lost();
    return s;
  }
  const std::string au_field = absl::StrCat(field, ".access_unit");
  // Our parser first (video::Decoder parses again: a few microseconds): the keyframe flag is
  // checked against the bytes, and the first sequence header picks the decoder's output.
  auto info = video::InspectAccessUnit(picture.access_unit(), au_field, limits_);
  if (!info.ok()) {
    b->Lost();
    return info.status();
  }
  if (info->idr != picture.keyframe()) {
    b->Lost();
    return absl::InvalidArgumentError(
        absl::StrCat(field, ".keyframe is ", picture.keyframe() ? "true" : "false",
                     " but the access unit ", info->idr ? "is" : "is not", " an IDR picture"));
  }
  if (b->decoder == nullptr) {
    if (!info->idr) {
      return absl::FailedPreconditionError(absl::StrCat(
          au_field, " is not a keyframe (no IDR slice), and ", v1::VideoBitstream_Name(b->id),
          " has had no IDR to decode it from: not decoded; the reply asks for one "
          "(keyframe_needed)"));
    }
    if (!info->sps) {
      return absl::InvalidArgumentError(absl::StrCat(
          au_field, ": the bitstream's first IDR carries no sequence header (SPS); it must"));
    }
    video::Decoder::Options o;
    o.limits = limits_;
    o.output = info->sps->chroma_format_idc == 0 ? ColorEncoding::kMono8 : ColorEncoding::kBGR8;
    o.width = picture.width();
    o.height = picture.height();
    o.charge = charge_;
    o.release = release_;
    b->decoder = std::make_unique<video::Decoder>(std::move(o));
  }
  ColorView view;
  if (absl::Status s = b->decoder->Decode(picture.access_unit(), au_field, &view); !s.ok()) {
    return s;  // the decoder wants an IDR now
  }
  CopyPicture(view, out);
  return absl::OkStatus();
}

absl::Status VideoDecoders::Decode(const v1::Frame& frame, DecodedVideo* out) {
  out->Clear();
  const auto start = std::chrono::steady_clock::now();
  absl::Status first;
  const auto note = [&first](absl::Status s) {
    if (first.ok()) first = std::move(s);
  };
  const bool colour_video = frame.color().has_video();
  if (colour_video) {
    const v1::VideoPicture& p = frame.color().video();
    if (colour_ == nullptr) colour_ = std::make_unique<Bitstream>(v1::VIDEO_BITSTREAM_COLOR);
    if (p.layout() == v1::VIDEO_LAYOUT_INTERLEAVED) {
      colour_->Lost();
      note(absl::InvalidArgumentError(
          "frame.color.video.layout is VIDEO_LAYOUT_INTERLEAVED: only frame.right's pictures "
          "are interleaved (into frame.color's bitstream)"));
    } else {
      absl::Status s = DecodePicture(p, "frame.color.video", colour_.get(), &out->colour);
      out->has_colour = s.ok();
      note(std::move(s));
    }
  }
  if (frame.right().has_video()) {
    const v1::VideoPicture& p = frame.right().video();
    if (p.layout() == v1::VIDEO_LAYOUT_INTERLEAVED) {
      if (!colour_video) {
        note(absl::InvalidArgumentError(
            "frame.right.video.layout is VIDEO_LAYOUT_INTERLEAVED, but frame.color is not a "
            "video picture: an interleaved right view follows its left view's picture"));
      } else {
        // Decoded right after its left view, by the same decoder.
        absl::Status s = DecodePicture(p, "frame.right.video", colour_.get(), &out->right);
        out->has_right = s.ok();
        note(std::move(s));
      }
    } else {
      if (right_ == nullptr) right_ = std::make_unique<Bitstream>(v1::VIDEO_BITSTREAM_RIGHT);
      absl::Status s = DecodePicture(p, "frame.right.video", right_.get(), &out->right);
      out->has_right = s.ok();
      note(std::move(s));
    }
  }
  KeyframeNeeded(&out->keyframe_needed);
  out->decode_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (!first.ok()) out->has_colour = out->has_right = false;
  return first;
}

void VideoDecoders::KeyframeNeeded(std::vector<v1::VideoBitstream>* out) const {
  if (colour_ != nullptr && colour_->needs_keyframe()) out->push_back(v1::VIDEO_BITSTREAM_COLOR);
  if (right_ != nullptr && right_->needs_keyframe()) out->push_back(v1::VIDEO_BITSTREAM_RIGHT);
}

}  // namespace cloudcast::server
