#include "cloudcast/video/decoder.h"

#include <algorithm>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "libav.h"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavutil/frame.h>
}

namespace cloudcast::video {

namespace {
// Debian's Abseil has its own string_view, which StrCat takes; std::string converts to both.
std::string S(std::string_view v) { return std::string(v); }
}  // namespace

using internal::LibavError;

std::uint64_t DecoderMemoryBytes(const SequenceHeader& sps, ColorEncoding output) {
  const std::uint64_t w = sps.coded_width, h = sps.coded_height;
  const std::uint64_t mbs = (w / 16) * (h / 16);
  // One picture: the planes with libavcodec's padding (4:2:0 planes even for grey, which it fills
  // with mid-grey; three full planes for 4:4:4), and its motion vectors, reference indices and
  // macroblock types.
  const std::uint64_t padded_row = (w + 64 + 63) / 64 * 64;
  const std::uint64_t planes_x2 = sps.chroma_format_idc == 3 ? 6 : 3;
  const std::uint64_t picture = padded_row * (h + 64) * planes_x2 / 2 + mbs * 640;
  // The references, the picture being decoded, the one held for output, one spare in the pool.
  const std::uint64_t pictures = std::max<std::uint64_t>(sps.max_num_ref_frames, 1) + 3;
  const std::uint64_t tables = mbs * 512;  // per-context macroblock state
  const std::uint64_t out = std::uint64_t{sps.width} * sps.height * BytesPerPixel(output);
  constexpr std::uint64_t kFixed = std::uint64_t{1} << 20;  // contexts, slice state
  return pictures * picture + tables + out + kFixed;
}

struct Decoder::Impl {
  Options options;
  AVCodecContext* ctx = nullptr;
  AVPacket* packet = nullptr;
  AVFrame* frame = nullptr;
  std::vector<std::uint8_t> input;   // the access unit with libavcodec's zero padding
  std::vector<std::uint8_t> output;  // the converted picture Decode points at
  bool awaiting_idr = true;
  std::uint32_t width = 0, height = 0;  // the stream's, from its first sequence header
  std::uint64_t charged = 0;

  ~Impl() {
    av_frame_free(&frame);
    av_packet_free(&packet);
    avcodec_free_context(&ctx);
    if (charged > 0 && options.release) options.release(charged);
  }

  absl::Status Open() {
    internal::RouteLibavLog();
    const AVCodec* codec = avcodec_find_decoder(AV_CODEC_ID_H264);  // libavcodec's own
    if (codec == nullptr) return absl::FailedPreconditionError("libavcodec has no H.264 decoder");
    ctx = avcodec_alloc_context3(codec);
    packet = av_packet_alloc();
    frame = av_frame_alloc();
    if (ctx == nullptr || packet == nullptr || frame == nullptr) {
      return absl::ResourceExhaustedError("cannot allocate the decoder's context");
    }
    ctx->thread_count = 1;  // one core per frame: the server runs frames side by side
    ctx->flags |= AV_CODEC_FLAG_LOW_DELAY;
    ctx->flags2 &= ~AV_CODEC_FLAG2_SHOW_ALL;
    ctx->flags &= ~AV_CODEC_FLAG_OUTPUT_CORRUPT;
    // Stop at the first damaged slice and say so, instead of concealing it.
    ctx->err_recognition = AV_EF_EXPLODE | AV_EF_BITSTREAM | AV_EF_BUFFER | AV_EF_CRCCHECK;
    if (const int rc = avcodec_open2(ctx, codec, nullptr); rc < 0) {
      return absl::InternalError(
          absl::StrCat("cannot open libavcodec's H.264 decoder: ", LibavError(rc)));
    }
    return absl::OkStatus();
  }

  absl::Status Fail(absl::Status s) {
    awaiting_idr = true;
    if (ctx != nullptr) avcodec_flush_buffers(ctx);
    return s;
  }
};

Decoder::Decoder(Options options) : impl_(std::make_unique<Impl>()) {
  impl_->options = std::move(options);
}
Decoder::~Decoder() = default;

bool Decoder::needs_keyframe() const { return impl_->awaiting_idr; }
void Decoder::RequireKeyframe() { impl_->Fail(absl::OkStatus()).IgnoreError(); }
std::uint64_t Decoder::charged_bytes() const { return impl_->charged; }
bool Decoder::opened() const { return impl_->ctx != nullptr; }
std::uint32_t Decoder::width() const { return impl_->width; }
std::uint32_t Decoder::height() const { return impl_->height; }

absl::Status Decoder::Decode(std::string_view access_unit, std::string_view field, ColorView* out) {
  Impl& m = *impl_;
  const Options& o = m.options;
  auto info = InspectAccessUnit(access_unit, field, o.limits);
  if (!info.ok()) return m.Fail(info.status());
  if (!info->has_slices) {
    return m.Fail(absl::InvalidArgumentError(absl::StrCat(
        S(field), " carries no picture (no slice NAL unit); an access unit is one picture")));
  }
  if (m.awaiting_idr && !info->idr) {
    return m.Fail(absl::FailedPreconditionError(absl::StrCat(
        S(field), " is not a keyframe (no IDR slice), and the stream has none to decode it from ",
        m.width == 0 ? "(it has not started)" : "(after an error or a gap)",
        ": not decoded; the client must send an IDR")));
  }
  if (info->sps) {
    const SequenceHeader& sps = *info->sps;
    const std::string sps_field = absl::StrCat(S(field), ".sps");
    if ((o.width != 0 && sps.width != o.width) || (o.height != 0 && sps.height != o.height)) {
      return m.Fail(absl::InvalidArgumentError(
          absl::StrCat(sps_field, ": the sequence header says ", sps.width, "x", sps.height,
                       " but the stream's images are ", o.width, "x", o.height)));
    }
    if (m.width != 0 && (sps.width != m.width || sps.height != m.height)) {
      return m.Fail(absl::InvalidArgumentError(absl::StrCat(
          sps_field, ": the picture size changes mid-stream, from ", m.width, "x", m.height, " to ",
          sps.width, "x", sps.height, "; a new size needs a new stream")));
    }
    // Charged before any decoder is opened or fed for this size.
    const std::uint64_t need = DecoderMemoryBytes(sps, o.output);
    if (need > m.charged) {
      if (o.charge) {
        if (absl::Status s = o.charge(need - m.charged); !s.ok()) return m.Fail(s);
      }
      m.charged = need;
    }
    m.width = sps.width;
    m.height = sps.height;
  } else if (m.width == 0) {
    return m.Fail(absl::FailedPreconditionError(
        absl::StrCat(S(field),
                     ": an IDR without a sequence header (SPS), and none came before it: the first "
                     "access unit of a stream must carry its SPS and PPS")));
  }
  if (m.ctx == nullptr) {
    if (absl::Status s = m.Open(); !s.ok()) return m.Fail(s);
  }

  m.input.assign(access_unit.begin(), access_unit.end());
  m.input.resize(access_unit.size() + AV_INPUT_BUFFER_PADDING_SIZE, 0);
  m.packet->data = m.input.data();
  m.packet->size = static_cast<int>(access_unit.size());
  internal::ClearLibavMessage();
  const auto libav_failure = [&](const char* what, int rc) {
    const std::string why = internal::TakeLibavMessage();
    return m.Fail(absl::InvalidArgumentError(
        absl::StrCat(S(field), ": ", what, rc < 0 ? absl::StrCat(" (", LibavError(rc), ")") : "",
                     why.empty() ? "" : absl::StrCat(": libavcodec: ", why),
                     "; the stream needs an IDR to go on")));
  };
  int rc = avcodec_send_packet(m.ctx, m.packet);
  av_packet_unref(m.packet);  // not ref-counted: drops the pointers only
  if (rc < 0) return libav_failure("the H.264 bitstream is corrupt or truncated", rc);
  int pictures = 0;
  bool damaged = false;
  while (true) {
    av_frame_unref(m.frame);
    rc = avcodec_receive_frame(m.ctx, m.frame);
    if (rc == AVERROR(EAGAIN)) break;
    if (rc < 0) return libav_failure("the H.264 bitstream is corrupt or truncated", rc);
    ++pictures;
    damaged |= m.frame->decode_error_flags != 0 || (m.frame->flags & AV_FRAME_FLAG_CORRUPT) != 0;
    if (pictures == 1) break;  // a second one would wait for the next call; see below
  }
  if (pictures == 0 || damaged) {
    return libav_failure(pictures == 0 ? "the access unit decoded to no picture (a slice missing "
                                         "or cut short)"
                                       : "the picture is damaged (libavcodec concealed errors: "
                                         "a slice is corrupt or missing)",
                         0);
  }
  const AVFrame* f = m.frame;
  if (static_cast<std::uint32_t>(f->width) != m.width ||
      static_cast<std::uint32_t>(f->height) != m.height) {
    return libav_failure(absl::StrCat("the picture decoded at ", f->width, "x", f->height,
                                      ", not the sequence header's size")
                             .c_str(),
                         0);
  }
  internal::YuvPlanes planes;
  if (!internal::PlanesOf(*f, &planes)) {
    return libav_failure("the picture is not 8-bit 4:0:0, 4:2:0 or 4:4:4", 0);
  }
  const std::size_t row = std::size_t{m.width} * BytesPerPixel(o.output);
  m.output.resize(row * m.height);
  if (absl::Status s =
          internal::YuvToPacked(planes, static_cast<int>(m.width), static_cast<int>(m.height),
                                o.output, m.output.data(), static_cast<int>(row));
      !s.ok()) {
    return m.Fail(s);
  }
  av_frame_unref(m.frame);
  m.awaiting_idr = false;
  *out = ColorView{};
  out->data = m.output.data();
  out->size_bytes = m.output.size();
  out->width = m.width;
  out->height = m.height;
  out->stride_bytes = row;
  out->encoding = o.output;
  return absl::OkStatus();
}

}  // namespace cloudcast::video
