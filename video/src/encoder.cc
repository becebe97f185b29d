#include "cloudcast/video/encoder.h"

#include <cstring>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/checks.h"
#include "libav.h"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavutil/dict.h>
#include <libavutil/frame.h>
#include <libavutil/opt.h>
}

namespace cloudcast::video {

namespace {
// Debian's Abseil has its own string_view, which StrCat takes; std::string converts to both.
std::string S(std::string_view v) { return std::string(v); }
}  // namespace

using internal::LibavError;

std::string_view Name(PictureKind kind) {
  switch (kind) {
    case PictureKind::kGrey:
      return "grey";
    case PictureKind::kColour:
      return "colour";
    case PictureKind::kColour444:
      return "colour444";
  }
  return "?";
}

struct Encoder::Impl {
  EncoderOptions options;
  AVCodecContext* ctx = nullptr;
  AVFrame* frame = nullptr;
  AVPacket* packet = nullptr;
  std::vector<std::uint8_t> staging;  // a view given as separate rows, made contiguous
  internal::PackedToYuv to_yuv;       // colour
  std::int64_t next_index = 0;
  std::int64_t bitrate = 0;

  ~Impl() {
    av_packet_free(&packet);
    av_frame_free(&frame);
    avcodec_free_context(&ctx);
  }

  // The rate control fields of the context for `bps`; libavcodec's libx264 wrapper reconfigures
  // x264 when they change between frames.
  void SetBitrate(std::int64_t bps) {
    bitrate = bps;
    if (options.qp >= 0 || bps <= 0) return;
    if (options.crf <= 0) ctx->bit_rate = bps;
    ctx->rc_max_rate = bps;
    ctx->rc_buffer_size = static_cast<int>(bps / options.fps);  // one frame
  }
};

namespace {

absl::Status CheckOptions(const EncoderOptions& o) {
  if (absl::Status s = check::ImageSize("options", o.width, o.height, o.limits); !s.ok()) return s;
  if (o.width % 2 != 0 || o.height % 2 != 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "options.", o.width % 2 ? "width" : "height", ": ", o.width, "x", o.height,
        " must be even in both sides (H.264 4:2:0 and x264's 4:0:0 code pairs of rows and "
        "columns)"));
  }
  if (absl::Status s = check::InRange("options.fps", o.fps, 1, 240); !s.ok()) return s;
  if (absl::Status s = check::InRange("options.qp", o.qp, -1, 51); !s.ok()) return s;
  if (!(o.crf >= 0 && o.crf <= 51)) {
    return absl::InvalidArgumentError(
        absl::StrCat("options.crf is ", o.crf, "; 0 (off) or 1 to 51"));
  }
  if (absl::Status s = check::InRange("options.bitrate_bps", o.bitrate_bps, 0, 1'000'000'000);
      !s.ok()) {
    return s;
  }
  if (o.qp < 0 && o.crf <= 0 && o.bitrate_bps <= 0) {
    return absl::InvalidArgumentError(
        "options.bitrate_bps is 0, and neither qp nor crf is set: the encoder needs one of them");
  }
  if (o.bitrate_bps > 0 && o.bitrate_bps / o.fps < 1000) {
    return absl::InvalidArgumentError(absl::StrCat("options.bitrate_bps is ", o.bitrate_bps,
                                                   ": under 1000 bits a frame at ", o.fps,
                                                   " frames/s"));
  }
  if (absl::Status s = check::InRange("options.keyframe_interval", o.keyframe_interval, 0, 100000);
      !s.ok()) {
    return s;
  }
  if (absl::Status s = check::InRange("options.threads", o.threads, 1, 64); !s.ok()) return s;
  if (absl::Status s = check::InRange("options.refs", o.refs, 0, 16); !s.ok()) return s;
  if (o.preset.empty()) return absl::InvalidArgumentError("options.preset is empty");
  return absl::OkStatus();
}

// Whether an Annex B access unit holds an IDR slice (nal_unit_type 5): a look at the byte after
// each start code.
bool ContainsIdr(std::string_view au) {
  for (std::size_t i = 0; i + 3 < au.size(); ++i) {
    if (au[i] == 0 && au[i + 1] == 0 && au[i + 2] == 1) {
      if ((static_cast<std::uint8_t>(au[i + 3]) & 31) == 5) return true;
      i += 2;
    }
  }
  return false;
}

}  // namespace

absl::StatusOr<std::unique_ptr<Encoder>> Encoder::Make(const EncoderOptions& options) {
  if (absl::Status s = CheckOptions(options); !s.ok()) return s;
  internal::RouteLibavLog();
  const AVCodec* codec = avcodec_find_encoder_by_name("libx264");
  if (codec == nullptr) {
    return absl::FailedPreconditionError(
        "this libavcodec has no libx264 encoder (Debian's libavcodec59 has; see docs/video.md)");
  }
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  AVCodecContext* ctx = impl->ctx = avcodec_alloc_context3(codec);
  impl->frame = av_frame_alloc();
  impl->packet = av_packet_alloc();
  if (ctx == nullptr || impl->frame == nullptr || impl->packet == nullptr) {
    return absl::ResourceExhaustedError("cannot allocate the encoder's context");
  }
  ctx->width = static_cast<int>(options.width);
  ctx->height = static_cast<int>(options.height);
  ctx->pix_fmt = options.kind == PictureKind::kGrey        ? AV_PIX_FMT_GRAY8
                 : options.kind == PictureKind::kColour444 ? AV_PIX_FMT_YUV444P
                                                           : AV_PIX_FMT_YUV420P;
  ctx->time_base = AVRational{1, options.fps};
  ctx->framerate = AVRational{options.fps, 1};
  ctx->gop_size = options.keyframe_interval > 0 ? options.keyframe_interval : 1 << 30;
  ctx->max_b_frames = 0;
  ctx->thread_count = options.threads;
  ctx->thread_type = FF_THREAD_SLICE;
  if (options.refs > 0) ctx->refs = options.refs;
  if (options.kind != PictureKind::kGrey) {
    ctx->colorspace = AVCOL_SPC_SMPTE170M;
    ctx->color_range = AVCOL_RANGE_MPEG;
  }
  impl->SetBitrate(options.bitrate_bps);

  AVDictionary* dict = nullptr;
  av_dict_set(&dict, "preset", options.preset.c_str(), 0);
  av_dict_set(&dict, "tune", "zerolatency", 0);
  av_dict_set(&dict, "forced-idr", "1", 0);  // a keyframe asked for is an IDR, where decoders start
  if (options.qp >= 0) {
    av_dict_set_int(&dict, "qp", options.qp, 0);
  } else if (options.crf > 0) {
    av_dict_set(&dict, "crf", std::to_string(options.crf).c_str(), 0);
  }
  if (options.intra_refresh) av_dict_set(&dict, "intra-refresh", "1", 0);
  // What zerolatency implies, said explicitly: no lookahead of any kind, no B-frames, headers
  // before every IDR (a late joiner needs them), no scene-cut IDRs (their size is not the rate
  // controller's to plan), slices rather than frames across threads.
  std::string params = absl::StrCat(
      "rc-lookahead=0:sync-lookahead=0:bframes=0:repeat-headers=1:scenecut=0:sliced-threads=",
      options.threads > 1 ? 1 : 0);
  if (options.keyframe_interval > 0) {
    absl::StrAppend(&params, ":keyint=", options.keyframe_interval,
                    ":min-keyint=", options.keyframe_interval);
  } else {
    absl::StrAppend(&params, ":keyint=infinite");
  }
  if (!options.x264_params.empty()) absl::StrAppend(&params, ":", options.x264_params);
  av_dict_set(&dict, "x264-params", params.c_str(), 0);
  internal::ClearLibavMessage();
  const int rc = avcodec_open2(ctx, codec, &dict);
  std::string unused;
  if (dict != nullptr) {
    const AVDictionaryEntry* e = av_dict_get(dict, "", nullptr, AV_DICT_IGNORE_SUFFIX);
    if (e != nullptr) unused = e->key;
  }
  av_dict_free(&dict);
  if (rc < 0) {
    const std::string why = internal::TakeLibavMessage();
    return absl::InvalidArgumentError(
        absl::StrCat("libx264 refused the options (preset '", options.preset,
                     "'): ", LibavError(rc), why.empty() ? "" : absl::StrCat(" (", why, ")")));
  }
  if (!unused.empty()) {
    return absl::InternalError(absl::StrCat("libx264 did not take the option '", unused, "'"));
  }
  // libavcodec warns of an x264-params entry x264 cannot parse, and opens anyway: refuse it here.
  const std::string why = internal::TakeLibavWarning();
  if (!options.x264_params.empty() && why.find("Error parsing option") != std::string::npos) {
    return absl::InvalidArgumentError(
        absl::StrCat("options.x264_params '", options.x264_params, "': libx264: ", why));
  }
  AVFrame* f = impl->frame;
  f->format = ctx->pix_fmt;
  f->width = ctx->width;
  f->height = ctx->height;
  if (av_frame_get_buffer(f, 0) < 0) {
    return absl::ResourceExhaustedError("cannot allocate the encoder's picture");
  }
  return std::unique_ptr<Encoder>(new Encoder(std::move(impl)));
}

Encoder::Encoder(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Encoder::~Encoder() = default;
const EncoderOptions& Encoder::options() const { return impl_->options; }

absl::Status Encoder::Encode(const ColorView& image, const FrameControl& control,
                             std::string_view field, EncodedPicture* out) {
  Impl& m = *impl_;
  const EncoderOptions& o = m.options;
  if (absl::Status s = ValidateView(image, o.limits, field); !s.ok()) return s;
  if (image.width != o.width || image.height != o.height) {
    return absl::InvalidArgumentError(
        absl::StrCat(S(field), " is ", image.width, "x", image.height, " but the stream is ",
                     o.width, "x", o.height, "; a new size needs a new encoder (and stream)"));
  }
  if (o.kind == PictureKind::kGrey && image.encoding != ColorEncoding::kMono8) {
    return absl::InvalidArgumentError(
        absl::StrCat(S(field), ".encoding is ", S(cloudcast::Name(image.encoding)),
                     "; a grey stream takes mono8 (stereo::ToGrey converts)"));
  }
  if (control.bitrate_bps < 0 || (control.bitrate_bps > 0 && control.bitrate_bps / o.fps < 1000)) {
    return absl::InvalidArgumentError(absl::StrCat(S(field), ": control.bitrate_bps is ",
                                                   control.bitrate_bps,
                                                   "; 0 (unchanged) or at least ", 1000 * o.fps));
  }
  if (control.bitrate_bps > 0 && control.bitrate_bps != m.bitrate) {
    if (o.qp < 0 && o.bitrate_bps <= 0 && o.crf > 0) {
      return absl::InvalidArgumentError(absl::StrCat(
          S(field),
          ": control.bitrate_bps needs a stream opened with a bitrate (options.bitrate_bps: "
          "the VBV is set up when the encoder opens)"));
    }
    m.SetBitrate(control.bitrate_bps);
  }
  AVFrame* f = m.frame;
  if (av_frame_make_writable(f) < 0) {
    return absl::ResourceExhaustedError("cannot allocate the encoder's picture");
  }
  // A view given as rows in pieces (the server's) is copied into one buffer first.
  const std::uint8_t* src = image.row(0);
  int src_stride = static_cast<int>(image.stride_bytes);
  const std::size_t row_bytes = image.width * BytesPerPixel(image.encoding);
  if (image.rows != nullptr) {
    m.staging.resize(row_bytes * image.height);
    for (std::uint32_t v = 0; v < image.height; ++v) {
      std::memcpy(m.staging.data() + v * row_bytes, image.row(v), row_bytes);
    }
    src = m.staging.data();
    src_stride = static_cast<int>(row_bytes);
  }
  if (o.kind == PictureKind::kGrey) {
    for (std::uint32_t v = 0; v < image.height; ++v) {
      std::memcpy(f->data[0] + v * f->linesize[0], src + std::size_t{v} * src_stride, image.width);
    }
  } else {
    internal::YuvPlanes planes;
    internal::PlanesOf(*f, &planes);  // the context's own 4:2:0 or 4:4:4
    if (absl::Status s =
            m.to_yuv.Convert(src, src_stride, image.encoding, static_cast<int>(image.width),
                             static_cast<int>(image.height), planes);
        !s.ok()) {
      return s;
    }
  }
  f->pts = m.next_index;
  f->pict_type = control.keyframe ? AV_PICTURE_TYPE_I : AV_PICTURE_TYPE_NONE;
  internal::ClearLibavMessage();
  int rc = avcodec_send_frame(m.ctx, f);
  if (rc < 0) {
    return absl::InternalError(absl::StrCat(S(field), ": libx264 refused the picture: ",
                                            LibavError(rc), " ", internal::TakeLibavMessage()));
  }
  rc = avcodec_receive_packet(m.ctx, m.packet);
  if (rc == AVERROR(EAGAIN)) {
    // Latency is the point: an encoder that holds a picture is set up wrongly.
    return absl::InternalError(absl::StrCat(
        S(field),
        ": libx264 held the picture instead of coding it at once (a lookahead or frame "
        "threads are on)"));
  }
  if (rc < 0) {
    return absl::InternalError(absl::StrCat(S(field), ": libx264 failed: ", LibavError(rc), " ",
                                            internal::TakeLibavMessage()));
  }
  out->bytes.assign(reinterpret_cast<const char*>(m.packet->data),
                    static_cast<std::size_t>(m.packet->size));
  // The flag the server acts on: an IDR is where a decoder may start. (x264's own key flag also
  // marks intra-refresh recovery points, where it may not.)
  out->keyframe = ContainsIdr(out->bytes);
  out->index = m.next_index++;
  av_packet_unref(m.packet);
  return absl::OkStatus();
}

}  // namespace cloudcast::video
