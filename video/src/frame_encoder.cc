#include "cloudcast/video/frame_encoder.h"

#include <algorithm>
#include <utility>
#include <variant>

#include "absl/strings/str_cat.h"
#include "cloudcast/stereo/grey.h"

namespace cloudcast::video {

// One bitstream: its encoder (remade when the picture size or kind changes) and what the keyframe
// requests need to know.
struct FrameEncoder::Bitstream {
  std::unique_ptr<Encoder> encoder;
  std::uint32_t width = 0, height = 0;
  PictureKind kind = PictureKind::kColour;
  std::uint64_t next_index = 0;  // VideoPicture.picture_index, kept across remade encoders
  bool force_idr = true;         // the next picture is an IDR
  bool idr_sent = false;
  std::uint64_t idr_sequence = 0;  // the frame that carried the last IDR

  // A request about the frame `sequence`: honoured unless an IDR went after that frame.
  bool Request(std::uint64_t sequence) {
    if (force_idr || (idr_sent && idr_sequence > sequence)) return false;
    force_idr = true;
    return true;
  }
};

FrameEncoder::FrameEncoder(FrameEncoderOptions options) : options_(std::move(options)) {}
FrameEncoder::~FrameEncoder() = default;

namespace {

absl::StatusOr<ColorView> RawColour(const client::ColorInput& input, const char* field) {
  if (const auto* view = std::get_if<ColorView>(&input)) return *view;
  return absl::InvalidArgumentError(
      absl::StrCat(field,
                   ": video encoding takes raw pixels (a ColorView of BGR8, RGB8, RGBA8 or MONO8), "
                   "not a file, a compressed or a BGRA image"));
}

}  // namespace

absl::Status FrameEncoder::EncodePicture(const ColorView& view, const char* field, bool stereo,
                                         Bitstream* b, v1::VideoPicture* out) {
  const bool interleaved = stereo && options_.interleave_stereo;
  const PictureKind kind =
      view.encoding == ColorEncoding::kMono8 ? PictureKind::kGrey : options_.colour_kind;
  // Interleaved, the right view is the second picture of the frame in this bitstream: it follows
  // the left one's encoder and kind.
  const bool second = interleaved && out == &right_picture_;
  if (!second && (b->encoder == nullptr || b->width != view.width || b->height != view.height ||
                  b->kind != kind)) {
    EncoderOptions o = options_.encoder;
    o.kind = kind;
    o.width = view.width;
    o.height = view.height;
    if (interleaved) {
      // Two pictures a frame: L0, R0, L1, R1, ... with the right predicted from its left and the
      // left from the previous pair (docs/video.md's measured layout).
      o.fps *= 2;
      o.keyframe_interval *= 2;
      o.refs = 2;
    } else if (stereo) {
      o.bitrate_bps /= 2;  // the bitrate is for both views together
    }
    auto encoder = Encoder::Make(o);
    if (!encoder.ok()) {
      return absl::Status(encoder.status().code(),
                          absl::StrCat(field, ": ", encoder.status().message()));
    }
    b->encoder = *std::move(encoder);
    b->width = view.width;
    b->height = view.height;
    b->kind = kind;
    b->force_idr = true;
  }
  FrameControl control;
  control.keyframe = b->force_idr && !second;
  if (bitrate_bps_ > 0 && !second) {
    control.bitrate_bps = stereo && !interleaved ? bitrate_bps_ / 2 : bitrate_bps_;
  }
  EncodedPicture picture;
  if (absl::Status s = b->encoder->Encode(view, control, field, &picture); !s.ok()) return s;
  out->Clear();
  out->set_codec(v1::VIDEO_CODEC_H264);
  out->set_width(view.width);
  out->set_height(view.height);
  out->set_access_unit(std::move(picture.bytes));
  out->set_keyframe(picture.keyframe);
  out->set_layout(second ? v1::VIDEO_LAYOUT_INTERLEAVED : v1::VIDEO_LAYOUT_OWN);
  out->set_picture_index(b->next_index++);
  last_bytes_ += out->access_unit().size();
  if (picture.keyframe) {
    b->force_idr = false;
    ++keyframes_sent_;
  }
  return absl::OkStatus();
}

absl::StatusOr<client::FrameInput> FrameEncoder::Encode(const client::FrameInput& input,
                                                        std::uint64_t sequence) {
  std::lock_guard<std::mutex> lock(mu_);
  last_bytes_ = 0;
  const auto encode = [&](const client::ColorInput& image, const char* field, bool stereo,
                          std::unique_ptr<Bitstream>* b,
                          v1::VideoPicture* out) -> absl::StatusOr<client::ColorInput> {
    auto view = RawColour(image, field);
    if (!view.ok()) return view.status();
    if (options_.grey && view->encoding != ColorEncoding::kMono8) {
      OwnedColor* grey = out == &right_picture_ ? &grey_right_ : &grey_colour_;
      if (absl::Status s = stereo::ToGrey(*view, grey, field); !s.ok()) return s;
      *view = grey->view();
    }
    if (*b == nullptr) *b = std::make_unique<Bitstream>();
    if (absl::Status s = EncodePicture(*view, field, stereo, b->get(), out); !s.ok()) return s;
    if (out->keyframe()) {
      (*b)->idr_sent = true;
      (*b)->idr_sequence = sequence;
    }
    return client::ColorInput(client::PrecodedVideo{out});
  };
  absl::StatusOr<client::FrameInput> result;
  if (const auto* f = std::get_if<client::DisparityFrame>(&input)) {
    auto colour = encode(f->colour, "colour", false, &colour_, &colour_picture_);
    if (!colour.ok()) return colour.status();
    result = client::FrameInput(client::DisparityFrame{f->disparity, *std::move(colour)});
  } else if (const auto* f = std::get_if<client::DepthFrame>(&input)) {
    auto colour = encode(f->colour, "colour", false, &colour_, &colour_picture_);
    if (!colour.ok()) return colour.status();
    result = client::FrameInput(client::DepthFrame{f->depth, *std::move(colour)});
  } else {
    const auto& pair = std::get<client::StereoFrame>(input);
    auto left = encode(pair.left, "left", true, &colour_, &colour_picture_);
    if (!left.ok()) return left.status();
    // Interleaved, the right view is the next picture of the left's bitstream.
    auto right = encode(pair.right, "right", true, options_.interleave_stereo ? &colour_ : &right_,
                        &right_picture_);
    if (!right.ok()) return right.status();
    result = client::FrameInput(client::StereoFrame{*std::move(left), *std::move(right)});
  }
  bitrate_bps_ = 0;
  return result;
}

void FrameEncoder::OnResult(const client::Result& result) {
  std::lock_guard<std::mutex> lock(mu_);
  const auto request = [&](std::unique_ptr<Bitstream>& b) {
    if (b != nullptr && b->Request(result.sequence)) ++keyframes_requested_;
  };
  // The server's word, on a cloud or an error alike: the bitstreams it cannot decode until an
  // IDR. A refused config answers no picture.
  if (result.fate == client::FrameFate::kAnswered) {
    if (result.config_rejected) return;
    for (v1::VideoBitstream id : result.keyframe_needed) {
      if (id == v1::VIDEO_BITSTREAM_COLOR) request(colour_);
      if (id == v1::VIDEO_BITSTREAM_RIGHT) request(right_);
    }
    return;
  }
  // Skipped by the server under DELIVERY_LATEST: its pictures were decoded all the same (the
  // server decodes every picture it receives). Lost with a call the resilient stream replaced:
  // the new call's decoders ask for an IDR themselves.
  if (result.fate == client::FrameFate::kDropped) return;
  // Replaced after it was encoded, lost or unsent: the server never decoded these pictures.
  request(colour_);
  request(right_);
}

void FrameEncoder::RequestKeyframe() {
  std::lock_guard<std::mutex> lock(mu_);
  if (colour_ != nullptr) colour_->force_idr = true;
  if (right_ != nullptr) right_->force_idr = true;
}

void FrameEncoder::SetBitrate(std::int64_t bits_per_second) {
  std::lock_guard<std::mutex> lock(mu_);
  bitrate_bps_ = bits_per_second;
}

void FrameEncoder::SetStreamBitrate(std::int64_t stream_bps, std::size_t other_bytes_per_frame) {
  const double fps = options_.encoder.fps;
  const double pictures = static_cast<double>(stream_bps) - 8.0 * fps * other_bytes_per_frame;
  // The floor keeps the encoder's own check (a kilobit per picture, two pictures a pair) and some
  // colour when the other images take the whole link (frames are then replaced: the window).
  const double floor = std::max(0.1 * static_cast<double>(stream_bps), 2000.0 * fps);
  double bps = std::max(pictures, floor);
  // The encoder's own bitrate (a one-frame VBV's cap) is the most the pictures take.
  if (options_.encoder.bitrate_bps > 0) {
    bps = std::min(bps, static_cast<double>(options_.encoder.bitrate_bps));
  }
  SetBitrate(static_cast<std::int64_t>(bps));
}

std::uint64_t FrameEncoder::keyframes_sent() const {
  std::lock_guard<std::mutex> lock(mu_);
  return keyframes_sent_;
}

std::uint64_t FrameEncoder::keyframes_requested() const {
  std::lock_guard<std::mutex> lock(mu_);
  return keyframes_requested_;
}

std::uint64_t FrameEncoder::last_bytes() const {
  std::lock_guard<std::mutex> lock(mu_);
  return last_bytes_;
}

}  // namespace cloudcast::video
