#include "cloudcast/video/codecs.h"

#include <algorithm>
#include <array>
#include <cstring>
#include <string>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "cloudcast/core/checks.h"
#include "cloudcast/video/decoder.h"
#include "libav.h"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavutil/dict.h>
#include <libavutil/frame.h>
#include <libavutil/opt.h>
#include <libavutil/pixdesc.h>
}

namespace cloudcast::video {

namespace {

// Debian's Abseil has its own string_view, which StrCat takes; std::string converts to both.
std::string S(std::string_view v) { return std::string(v); }

using internal::LibavError;

const std::vector<CodecInfo>& Table() {
  static const std::vector<CodecInfo> table = {
      {Codec::kH264, "h264", "H.264", "libx264", "h264",
       "x264 preset: ultrafast, superfast, veryfast, faster, fast, medium", 51, true, true, true},
      {Codec::kHevc, "hevc", "HEVC", "libx265", "hevc",
       "x265 preset: ultrafast, superfast, veryfast, faster, fast, medium", 51, true, true, true},
      {Codec::kVp9, "vp9", "VP9", "libvpx-vp9", "vp9",
       "libvpx cpu-used in realtime mode, 5 (slowest) to 8 (fastest: FFmpeg 5.1's limit)", 63, true,
       false, true},
      {Codec::kAv1, "av1", "AV1", "libaom-av1", "libdav1d",
       "libaom cpu-used in realtime mode, 7 (slowest) to 10 (fastest)", 63, false, true, true},
  };
  return table;
}

// --- each codec's latency settings: the one place they are written ---------------------------
//
// Each sets what video::Encoder sets for x264 in the codec's own terms: no B-frames, no
// lookahead, one thread, headers before every keyframe, no scene-cut keyframes, a keyframe every
// keyframe_interval pictures, and the rate (lossless, crf, or a bitrate with a one-frame VBV,
// crf capped by it when both are given). The context's common fields (size, pixel format, time
// base, gop, max_b_frames 0, thread_count, bit_rate / rc_max_rate / rc_buffer_size) are set by
// the caller before.

using Dict = AVDictionary*;

absl::Status ParsePreset(const EncoderOptions& o, int lo, int hi, int* value) {
  if (!absl::SimpleAtoi(o.preset, value) || *value < lo || *value > hi) {
    return absl::InvalidArgumentError(
        absl::StrCat("options.preset is '", o.preset, "'; a number from ", lo, " to ", hi));
  }
  return absl::OkStatus();
}

absl::Status ConfigureHevc(const EncoderOptions& o, AVCodecContext* ctx, Dict* d) {
  static constexpr std::array<std::string_view, 6> kPresets = {"ultrafast", "superfast", "veryfast",
                                                               "faster",    "fast",      "medium"};
  if (std::find(kPresets.begin(), kPresets.end(), o.preset) == kPresets.end()) {
    return absl::InvalidArgumentError(
        absl::StrCat("options.preset is '", o.preset,
                     "'; x265's ultrafast, superfast, veryfast, faster, fast or medium"));
  }
  (void)ctx;  // the rate is in the context already
  av_dict_set(d, "preset", o.preset.c_str(), 0);
  av_dict_set(d, "tune", "zerolatency", 0);
  av_dict_set(d, "forced-idr", "1", 0);
  if (o.qp < 0 && o.crf > 0) av_dict_set(d, "crf", std::to_string(o.crf).c_str(), 0);
  // pools=none: no worker pool (no wavefront threads); frame-threads=1: one picture at a time.
  // x265 still runs that picture on a thread of its own while the caller waits: one core busy.
  std::string params =
      "bframes=0:rc-lookahead=0:frame-threads=1:pools=none:repeat-headers=1:scenecut=0:"
      "open-gop=0:log-level=error";
  if (o.qp == 0) absl::StrAppend(&params, ":lossless=1");
  if (o.keyframe_interval > 0) {
    absl::StrAppend(&params, ":keyint=", o.keyframe_interval, ":min-keyint=", o.keyframe_interval);
  } else {
    absl::StrAppend(&params, ":keyint=-1");  // x265: infinite
  }
  if (o.refs > 0) absl::StrAppend(&params, ":ref=", o.refs);
  av_dict_set(d, "x265-params", params.c_str(), 0);
  return absl::OkStatus();
}

absl::Status ConfigureVp9(const EncoderOptions& o, AVCodecContext* ctx, Dict* d) {
  int speed = 0;
  if (absl::Status s = ParsePreset(o, 5, 8, &speed); !s.ok()) return s;
  av_dict_set(d, "deadline", "realtime", 0);
  av_dict_set_int(d, "cpu-used", speed, 0);
  av_dict_set_int(d, "lag-in-frames", 0, 0);  // no lookahead, no alt-ref: each picture at once
  av_dict_set_int(d, "row-mt", 1, 0);
  av_dict_set_int(d, "tile-columns", 0, 0);  // one thread: tiles would cost bits and buy nothing
  av_dict_set_int(d, "error-resilient", 0, 0);
  if (o.qp == 0) {
    av_dict_set_int(d, "lossless", 1, 0);
  } else if (o.crf > 0) {
    // crf with no bitrate: constant quality (VPX_Q).
    av_dict_set_int(d, "crf", static_cast<int>(o.crf), 0);
  } else {
    // A bitrate alone: CBR, whose buffer (rc_buffer_size / bit_rate) is one frame.
    ctx->rc_min_rate = ctx->bit_rate;
  }
  ctx->keyint_min = ctx->gop_size;
  return absl::OkStatus();
}

absl::Status ConfigureAv1(const EncoderOptions& o, AVCodecContext* ctx, Dict* d) {
  int speed = 0;
  if (absl::Status s = ParsePreset(o, 7, 10, &speed); !s.ok()) return s;
  // libaom's real-time mode (what WebRTC's AV1 uses). Not SVT-AV1: FFmpeg 5.1's libsvtav1
  // wrapper fetches a packet only when a picture is sent, and SVT-AV1 1.4 in low delay gave each
  // picture's three pictures later (docs/video.md): latency "one picture in, its bytes out"
  // rules out.
  av_dict_set(d, "usage", "realtime", 0);
  // FFmpeg 5.1's own cpu-used option stops at 8; libaom's real-time speeds go to 10.
  av_dict_set(d, "aom-params", absl::StrCat("cpu-used=", speed).c_str(), 0);
  av_dict_set_int(d, "lag-in-frames", 0, 0);
  av_dict_set_int(d, "row-mt", 1, 0);
  av_dict_set_int(d, "tile-columns", 0, 0);
  if (o.crf > 0) {
    av_dict_set_int(d, "crf", static_cast<int>(o.crf), 0);  // no bitrate: constant quality
  } else {
    ctx->rc_min_rate = ctx->bit_rate;  // CBR, its buffer one frame
  }
  ctx->keyint_min = ctx->gop_size;
  return absl::OkStatus();
}

using Configure = absl::Status (*)(const EncoderOptions&, AVCodecContext*, Dict*);
Configure ConfigureOf(Codec c) {
  switch (c) {
    case Codec::kHevc:
      return ConfigureHevc;
    case Codec::kVp9:
      return ConfigureVp9;
    case Codec::kAv1:
      return ConfigureAv1;
    case Codec::kH264:
      break;
  }
  return nullptr;
}

absl::Status CheckOptions(const CodecInfo& info, const EncoderOptions& o) {
  if (absl::Status s = check::ImageSize("options", o.width, o.height, o.limits); !s.ok()) return s;
  if (o.width % 2 != 0 || o.height % 2 != 0) {
    return absl::InvalidArgumentError(absl::StrCat("options.", o.width % 2 ? "width" : "height",
                                                   ": ", o.width, "x", o.height,
                                                   " must be even in both sides (4:2:0)"));
  }
  if (absl::Status s = check::InRange("options.fps", o.fps, 1, 240); !s.ok()) return s;
  if (o.qp > 0 || o.qp < -1) {
    return absl::InvalidArgumentError(absl::StrCat("options.qp is ", o.qp, "; ", info.label,
                                                   " here takes -1 (off) or 0 (lossless)"));
  }
  if (o.qp == 0 && !info.lossless) {
    return absl::InvalidArgumentError(
        absl::StrCat("options.qp is 0 (lossless), which ", info.encoder, " does not offer"));
  }
  if (!(o.crf >= 0 && o.crf <= info.max_crf)) {
    return absl::InvalidArgumentError(absl::StrCat("options.crf is ", o.crf, "; 0 (off) or 1 to ",
                                                   info.max_crf, " for ", info.label));
  }
  if (absl::Status s = check::InRange("options.bitrate_bps", o.bitrate_bps, 0, 1'000'000'000);
      !s.ok()) {
    return s;
  }
  if (o.qp < 0 && o.crf <= 0 && o.bitrate_bps / o.fps < 1000) {
    return absl::InvalidArgumentError(
        absl::StrCat("options.bitrate_bps is ", o.bitrate_bps,
                     " and neither qp nor crf is set: at least 1000 bits a frame are needed"));
  }
  if (o.qp < 0 && o.crf > 0 && o.bitrate_bps > 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("options.bitrate_bps is ", o.bitrate_bps, " with crf ", o.crf,
                     ": a bitrate cap on constant quality is H.264's only here; 0 with crf"));
  }
  if (absl::Status s = check::InRange("options.keyframe_interval", o.keyframe_interval, 0, 100000);
      !s.ok()) {
    return s;
  }
  if (o.threads != 1) {
    return absl::InvalidArgumentError(absl::StrCat("options.threads is ", o.threads, "; ",
                                                   info.label, " is measured on one thread only"));
  }
  if (absl::Status s = check::InRange("options.refs", o.refs, 0, 16); !s.ok()) return s;
  if (!o.x264_params.empty()) {
    return absl::InvalidArgumentError("options.x264_params: for H.264 only");
  }
  if (o.intra_refresh) {
    return absl::InvalidArgumentError("options.intra_refresh: for H.264 only");
  }
  if (o.kind == PictureKind::kColour444 && !info.colour444) {
    return absl::InvalidArgumentError(
        absl::StrCat("options.kind is colour444, which ", info.encoder, " does not code"));
  }
  return absl::OkStatus();
}

// H.264: the uplink's own encoder and the server's decoder, as they are.
class H264Stream final : public CodecStream {
 public:
  H264Stream(std::unique_ptr<Encoder> encoder, ColorEncoding decoded)
      : encoder_(std::move(encoder)), decoder_(DecoderOptions(decoded)) {}
  absl::Status Encode(const ColorView& image, std::string_view field, std::string* bytes) override {
    if (absl::Status s = encoder_->Encode(image, {}, field, &picture_); !s.ok()) return s;
    bytes->swap(picture_.bytes);
    return absl::OkStatus();
  }
  absl::Status Decode(std::string_view bytes, std::string_view field, ColorView* out) override {
    return decoder_.Decode(bytes, field, out);
  }
  std::string Describe() const override {
    return absl::StrCat("libx264 ", encoder_->options().preset);
  }

 private:
  static Decoder::Options DecoderOptions(ColorEncoding decoded) {
    Decoder::Options o;
    o.output = decoded;
    return o;
  }
  std::unique_ptr<Encoder> encoder_;
  Decoder decoder_;
  EncodedPicture picture_;
};

// Any other codec: libavcodec's encoder with the codec's settings, and its decoder.
class LibavStream final : public CodecStream {
 public:
  ~LibavStream() override {
    av_packet_free(&packet_);
    av_frame_free(&frame_);
    av_frame_free(&decoded_);
    avcodec_free_context(&enc_);
    avcodec_free_context(&dec_);
  }

  absl::Status Open(const CodecInfo& info, const EncoderOptions& o, ColorEncoding decoded) {
    info_ = &info;
    options_ = o;
    decoded_encoding_ = decoded;
    internal::RouteLibavLog();
    const AVCodec* encoder = avcodec_find_encoder_by_name(info.encoder);
    const AVCodec* decoder = avcodec_find_decoder_by_name(info.decoder);
    if (encoder == nullptr || decoder == nullptr) {
      return absl::FailedPreconditionError(
          absl::StrCat("this libavcodec has no ", encoder == nullptr ? info.encoder : info.decoder,
                       encoder == nullptr ? " encoder" : " decoder", " (", info.label, ")"));
    }
    enc_ = avcodec_alloc_context3(encoder);
    dec_ = avcodec_alloc_context3(decoder);
    frame_ = av_frame_alloc();
    decoded_ = av_frame_alloc();
    packet_ = av_packet_alloc();
    if (enc_ == nullptr || dec_ == nullptr || frame_ == nullptr || decoded_ == nullptr ||
        packet_ == nullptr) {
      return absl::ResourceExhaustedError("cannot allocate the codec's contexts");
    }
    enc_->width = static_cast<int>(o.width);
    enc_->height = static_cast<int>(o.height);
    enc_->pix_fmt = o.kind == PictureKind::kGrey
                        ? (info.grey ? AV_PIX_FMT_GRAY8 : AV_PIX_FMT_YUV420P)
                    : o.kind == PictureKind::kColour444 ? AV_PIX_FMT_YUV444P
                                                        : AV_PIX_FMT_YUV420P;
    enc_->time_base = AVRational{1, o.fps};
    enc_->framerate = AVRational{o.fps, 1};
    enc_->gop_size = o.keyframe_interval > 0 ? o.keyframe_interval : (1 << 30);
    enc_->max_b_frames = 0;
    enc_->thread_count = 1;
    if (o.kind != PictureKind::kGrey) {
      enc_->colorspace = AVCOL_SPC_SMPTE170M;
      enc_->color_range = AVCOL_RANGE_MPEG;
    }
    // A bitrate (CheckOptions: only without qp and crf) with the one-frame VBV, as
    // video::Encoder's; otherwise none at all (libavcodec's default is 200 kbit/s).
    enc_->bit_rate = 0;
    if (o.qp < 0 && o.crf <= 0) {
      enc_->bit_rate = o.bitrate_bps;
      enc_->rc_max_rate = o.bitrate_bps;
      enc_->rc_buffer_size = static_cast<int>(o.bitrate_bps / o.fps);
    }
    AVDictionary* dict = nullptr;
    if (absl::Status s = ConfigureOf(info.codec)(o, enc_, &dict); !s.ok()) {
      av_dict_free(&dict);
      return s;
    }
    internal::ClearLibavMessage();
    int rc = avcodec_open2(enc_, encoder, &dict);
    std::string unused;
    if (const AVDictionaryEntry* e = av_dict_get(dict, "", nullptr, AV_DICT_IGNORE_SUFFIX)) {
      unused = e->key;
    }
    av_dict_free(&dict);
    if (rc < 0) {
      const std::string why = internal::TakeLibavMessage();
      return absl::InvalidArgumentError(absl::StrCat(info.encoder, " refused the options (preset '",
                                                     o.preset, "'): ", LibavError(rc),
                                                     why.empty() ? "" : " (" + why + ")"));
    }
    if (!unused.empty()) {
      return absl::InternalError(
          absl::StrCat(info.encoder, " did not take the option '", unused, "'"));
    }
    // The wrappers warn of a *-params entry their library cannot parse, and open anyway.
    if (const std::string why = internal::TakeLibavWarning();
        why.find("rror parsing") != std::string::npos ||
        why.find("nknown option") != std::string::npos) {
      return absl::InternalError(absl::StrCat(info.encoder, ": ", why));
    }
    frame_->format = enc_->pix_fmt;
    frame_->width = enc_->width;
    frame_->height = enc_->height;
    if (av_frame_get_buffer(frame_, 0) < 0) {
      return absl::ResourceExhaustedError("cannot allocate the encoder's picture");
    }
    dec_->thread_count = 1;  // one core, as the server decodes
    dec_->flags |= AV_CODEC_FLAG_LOW_DELAY;
    if ((rc = avcodec_open2(dec_, decoder, nullptr)) < 0) {
      return absl::InternalError(
          absl::StrCat("cannot open the ", info.decoder, " decoder: ", LibavError(rc)));
    }
    return absl::OkStatus();
  }

  absl::Status Encode(const ColorView& image, std::string_view field, std::string* bytes) override {
    const EncoderOptions& o = options_;
    if (absl::Status s = ValidateView(image, o.limits, field); !s.ok()) return s;
    if (image.width != o.width || image.height != o.height) {
      return absl::InvalidArgumentError(absl::StrCat(S(field), " is ", image.width, "x",
                                                     image.height, " but the stream is ", o.width,
                                                     "x", o.height));
    }
    if (o.kind == PictureKind::kGrey && image.encoding != ColorEncoding::kMono8) {
      return absl::InvalidArgumentError(absl::StrCat(S(field), ": a grey stream takes mono8"));
    }
    if (av_frame_make_writable(frame_) < 0) {
      return absl::ResourceExhaustedError("cannot allocate the encoder's picture");
    }
    const std::size_t row_bytes = image.width * BytesPerPixel(image.encoding);
    staging_.resize(row_bytes * image.height);
    for (std::uint32_t v = 0; v < image.height; ++v) {
      std::memcpy(staging_.data() + v * row_bytes, image.row(v), row_bytes);
    }
    if (o.kind == PictureKind::kGrey) {
      for (std::uint32_t v = 0; v < image.height; ++v) {
        std::memcpy(frame_->data[0] + std::size_t{v} * frame_->linesize[0],
                    staging_.data() + v * row_bytes, image.width);
      }
      if (enc_->pix_fmt == AV_PIX_FMT_YUV420P) {  // grey as 4:2:0: chroma flat, nearly free
        for (int p = 1; p < 3; ++p) {
          std::memset(frame_->data[p], 128,
                      static_cast<std::size_t>(frame_->linesize[p]) * ((image.height + 1) / 2));
        }
      }
    } else {
      internal::YuvPlanes planes;
      internal::PlanesOf(*frame_, &planes);  // the encoder's own 4:2:0 or 4:4:4
      if (absl::Status s = to_yuv_.Convert(staging_.data(), static_cast<int>(row_bytes),
                                           image.encoding, static_cast<int>(image.width),
                                           static_cast<int>(image.height), planes);
          !s.ok()) {
        return s;
      }
    }
    frame_->pts = next_pts_++;
    internal::ClearLibavMessage();
    int rc = avcodec_send_frame(enc_, frame_);
    if (rc < 0) {
      return absl::InternalError(absl::StrCat(S(field), ": ", info_->encoder,
                                              " refused the picture: ", LibavError(rc), " ",
                                              internal::TakeLibavMessage()));
    }
    rc = avcodec_receive_packet(enc_, packet_);
    if (rc == AVERROR(EAGAIN)) {
      return absl::InternalError(absl::StrCat(S(field), ": ", info_->encoder,
                                              " held the picture instead of coding it at once"));
    }
    if (rc < 0) {
      return absl::InternalError(absl::StrCat(S(field), ": ", info_->encoder, " failed: ",
                                              LibavError(rc), " ", internal::TakeLibavMessage()));
    }
    bytes->assign(reinterpret_cast<const char*>(packet_->data),
                  static_cast<std::size_t>(packet_->size));
    av_packet_unref(packet_);
    return absl::OkStatus();
  }

  absl::Status Decode(std::string_view bytes, std::string_view field, ColorView* out) override {
    input_.assign(bytes.begin(), bytes.end());
    input_.resize(bytes.size() + AV_INPUT_BUFFER_PADDING_SIZE, 0);
    packet_->data = input_.data();
    packet_->size = static_cast<int>(bytes.size());
    internal::ClearLibavMessage();
    int rc = avcodec_send_packet(dec_, packet_);
    packet_->data = nullptr;
    packet_->size = 0;
    if (rc < 0) {
      return absl::InvalidArgumentError(absl::StrCat(
          S(field), ": ", info_->decoder, ": ", LibavError(rc), " ", internal::TakeLibavMessage()));
    }
    av_frame_unref(decoded_);
    rc = avcodec_receive_frame(dec_, decoded_);
    if (rc == AVERROR(EAGAIN)) {
      return absl::InternalError(
          absl::StrCat(S(field), ": the ", info_->decoder, " decoder held the picture back"));
    }
    if (rc < 0) {
      return absl::InvalidArgumentError(absl::StrCat(
          S(field), ": ", info_->decoder, ": ", LibavError(rc), " ", internal::TakeLibavMessage()));
    }
    const AVFrame* f = decoded_;
    if (static_cast<std::uint32_t>(f->width) != options_.width ||
        static_cast<std::uint32_t>(f->height) != options_.height) {
      return absl::InternalError(absl::StrCat(S(field), ": decoded ", f->width, "x", f->height));
    }
    const std::size_t bpp = BytesPerPixel(decoded_encoding_);
    const std::size_t row = std::size_t{options_.width} * bpp;
    output_.resize(row * options_.height);
    internal::YuvPlanes planes;
    if (!internal::PlanesOf(*f, &planes)) {
      const char* format = av_get_pix_fmt_name(static_cast<AVPixelFormat>(f->format));
      return absl::InternalError(absl::StrCat(S(field), ": decoded a picture in ",
                                              format != nullptr ? format : "an unknown format",
                                              ", not 8-bit grey, 4:2:0 or 4:4:4"));
    }
    if (absl::Status s = internal::YuvToPacked(planes, static_cast<int>(options_.width),
                                               static_cast<int>(options_.height), decoded_encoding_,
                                               output_.data(), static_cast<int>(row));
        !s.ok()) {
      return s;
    }
    av_frame_unref(decoded_);
    *out = ColorView{};
    out->data = output_.data();
    out->size_bytes = output_.size();
    out->width = options_.width;
    out->height = options_.height;
    out->stride_bytes = row;
    out->encoding = decoded_encoding_;
    return absl::OkStatus();
  }

  std::string Describe() const override {
    return absl::StrCat(info_->encoder, " ", options_.preset);
  }

 private:
  const CodecInfo* info_ = nullptr;
  EncoderOptions options_;
  ColorEncoding decoded_encoding_ = ColorEncoding::kMono8;
  AVCodecContext* enc_ = nullptr;
  AVCodecContext* dec_ = nullptr;
  AVFrame* frame_ = nullptr;
  AVFrame* decoded_ = nullptr;
  AVPacket* packet_ = nullptr;
  internal::PackedToYuv to_yuv_;
  std::vector<std::uint8_t> staging_, input_, output_;
  std::int64_t next_pts_ = 0;
};

}  // namespace

const std::vector<CodecInfo>& Codecs() { return Table(); }

const CodecInfo* FindCodec(std::string_view key) {
  for (const CodecInfo& c : Table()) {
    if (std::string_view(c.key) == key) return &c;
  }
  return nullptr;
}

const CodecInfo& Info(Codec codec) {
  for (const CodecInfo& c : Table()) {
    if (c.codec == codec) return c;
  }
  return Table().front();
}

bool Available(Codec codec) {
  const CodecInfo& info = Info(codec);
  return avcodec_find_encoder_by_name(info.encoder) != nullptr &&
         avcodec_find_decoder_by_name(info.decoder) != nullptr;
}

absl::StatusOr<std::unique_ptr<CodecStream>> CodecStream::Open(Codec codec,
                                                               const EncoderOptions& options,
                                                               ColorEncoding decoded) {
  if (decoded != ColorEncoding::kMono8 && decoded != ColorEncoding::kBGR8 &&
      decoded != ColorEncoding::kRGB8) {
    return absl::InvalidArgumentError("decoded: mono8, bgr8 or rgb8");
  }
  const CodecInfo& info = Info(codec);
  if (codec == Codec::kH264) {
    auto encoder = Encoder::Make(options);
    if (!encoder.ok()) return encoder.status();
    return std::unique_ptr<CodecStream>(new H264Stream(*std::move(encoder), decoded));
  }
  if (absl::Status s = CheckOptions(info, options); !s.ok()) return s;
  auto stream = std::make_unique<LibavStream>();
  if (absl::Status s = stream->Open(info, options, decoded); !s.ok()) return s;
  return std::unique_ptr<CodecStream>(std::move(stream));
}

}  // namespace cloudcast::video
