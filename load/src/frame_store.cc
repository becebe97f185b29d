#include "cloudcast/load/frame_store.h"

#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <cmath>
#include <variant>

#include <opencv2/core/mat.hpp>

#include "absl/status/status.h"
#include "cloudcast/client/half_resolution.h"
#include "cloudcast/load/thread_cpu.h"
#include "cloudcast/proto/convert.h"

namespace cloudcast::load {
namespace {

// Protobuf wire format: tag = field << 3 | type; type 0 varint, 2 length-delimited.
constexpr std::uint8_t kRequestFrameTag = (2 << 3) | 2;  // StreamRequest.frame
constexpr std::uint8_t kSequenceTag = (1 << 3) | 0;      // Frame.sequence
constexpr std::uint8_t kCaptureTimeTag = (2 << 3) | 0;   // Frame.capture_time_unix_ns

std::size_t PutVarint(std::uint64_t v, std::uint8_t* out) {
  std::size_t n = 0;
  while (v >= 0x80) {
    out[n++] = static_cast<std::uint8_t>(v | 0x80);
    v >>= 7;
  }
  out[n++] = static_cast<std::uint8_t>(v);
  return n;
}

std::size_t VarintSize(std::uint64_t v) {
  std::size_t n = 1;
  while (v >= 0x80) {
    v >>= 7;
    ++n;
  }
  return n;
}

// A StreamRequest{frame} on the wire: a few header bytes (the request's tag and length, then
// Frame.sequence and Frame.capture_time_unix_ns), the shared `tail` as it is, then `fields` (more
// of the Frame's fields; null: none), copied.
grpc::ByteBuffer Framed(const std::string& tail, std::uint64_t sequence,
                        std::int64_t capture_time_unix_ns, const std::string* fields) {
  const auto time = static_cast<std::uint64_t>(capture_time_unix_ns);  // int64 as varint
  const std::size_t extra = fields != nullptr ? fields->size() : 0;
  const std::size_t frame_bytes =
      1 + VarintSize(sequence) + 1 + VarintSize(time) + tail.size() + extra;
  std::uint8_t header[1 + 10 + 1 + 10 + 1 + 10];
  std::size_t n = 0;
  header[n++] = kRequestFrameTag;
  n += PutVarint(frame_bytes, header + n);
  header[n++] = kSequenceTag;
  n += PutVarint(sequence, header + n);
  header[n++] = kCaptureTimeTag;
  n += PutVarint(time, header + n);
  grpc::Slice slices[3] = {grpc::Slice(header, n),
                           grpc::Slice(tail.data(), tail.size(), grpc::Slice::STATIC_SLICE),
                           extra > 0 ? grpc::Slice(fields->data(), extra) : grpc::Slice()};
  return grpc::ByteBuffer(slices, extra > 0 ? 3 : 2);
}

// A short name of the source for the description.
std::string Label(const sources::SourceInfo& info) {
  if (info.kind == "tsukuba") return "New Tsukuba";
  if (info.kind == "glob") return "images";
  return info.kind;
}

// `frame` at half its width and height, as the client library's floor makes it
// (cloudcast/client/half_resolution.h): depth and disparity every second pixel, colour averaged
// over each 2x2 block.
sources::SourceFrame HalfResolution(const sources::SourceFrame& frame) {
  sources::SourceFrame half = frame;
  const std::vector<sources::ImageRole>& roles = sources::RolesOf(frame.kind);
  for (std::size_t i = 0; i < half.images.size() && i < roles.size(); ++i) {
    const cv::Mat& full = frame.images[i];
    const bool measurement =
        roles[i] == sources::ImageRole::kDisparity || roles[i] == sources::ImageRole::kDepth;
    cv::Mat out(static_cast<int>(client::HalfSize(full.rows)),
                static_cast<int>(client::HalfSize(full.cols)), full.type());
    const auto cols = static_cast<std::uint32_t>(full.cols);
    const auto rows = static_cast<std::uint32_t>(full.rows);
    if (measurement) {
      client::SampleHalf(full.data, full.step, cols, rows, full.elemSize(), out.data, out.step);
    } else {
      client::AverageHalf(full.data, full.step, cols, rows, full.channels(), out.data, out.step);
    }
    half.images[i] = out;
  }
  return half;
}

// The pictures FrameEncoder made of a frame, into the proto frame holding its raw images.
absl::Status PutPictures(const client::FrameInput& coded, v1::Frame* f) {
  const auto picture = [](const client::ColorInput& image) -> const v1::VideoPicture* {
    const auto* v = std::get_if<client::PrecodedVideo>(&image);
    return v == nullptr ? nullptr : v->message;
  };
  const v1::VideoPicture* colour = nullptr;
  const v1::VideoPicture* right = nullptr;
  if (const auto* d = std::get_if<client::DisparityFrame>(&coded)) {
    colour = picture(d->colour);
  } else if (const auto* d = std::get_if<client::DepthFrame>(&coded)) {
    colour = picture(d->colour);
  } else {
    const auto& pair = std::get<client::StereoFrame>(coded);
    colour = picture(pair.left);
    right = picture(pair.right);
    if (right == nullptr) return absl::InternalError("the encoder left the right image raw");
    *f->mutable_right()->mutable_video() = *right;
  }
  if (colour == nullptr) return absl::InternalError("the encoder left the colour image raw");
  *f->mutable_color()->mutable_video() = *colour;
  return absl::OkStatus();
}

std::string VideoSettings(const video::FrameEncoderOptions& v, sources::FrameKind kind) {
  const video::EncoderOptions& e = v.encoder;
  std::string rate = e.qp == 0  ? std::string("lossless (qp 0)")
                     : e.crf > 0 ? fmt::format("crf {:g} <= {:g} Mbit/s", e.crf, e.bitrate_bps / 1e6)
                                 : fmt::format("{:g} Mbit/s", e.bitrate_bps / 1e6);
  if (!e.x264_params.empty()) rate += ", x264 " + e.x264_params;
  std::string pictures = v.grey                                            ? "grey 4:0:0"
                         : v.colour_kind == video::PictureKind::kColour444 ? "colour 4:4:4"
                                                                           : "colour 4:2:0";
  if (kind == sources::FrameKind::kStereo) {
    pictures += v.interleave_stereo ? ", pairs interleaved" : ", a bitstream per view";
  }
  const std::string keyframes = e.keyframe_interval > 0
                                    ? fmt::format("IDR every {}", e.keyframe_interval)
                                    : std::string("IDR when asked");
  return fmt::format("{} {}, {}, {}", e.preset, rate, pictures, keyframes);
}

// The serialized size of a frame's disparity or depth field.
double GeometryBytes(const v1::Frame& f) {
  return static_cast<double>(f.has_depth() ? f.depth().ByteSizeLong()
                                           : f.disparity().ByteSizeLong());
}

// The near-lossless bound against what the frames are and how they travel.
absl::Status CheckNearLossless(const FrameSourceOptions& o) {
  const double bound = o.uplink.max_point_error;
  if (bound == 0) return absl::OkStatus();
  if (!std::isfinite(bound) || bound < 0) {
    return absl::InvalidArgumentError(fmt::format(
        "--max-point-error is {}: it must be a finite distance in metres >= 0 (0 = lossless)",
        bound));
  }
  if (o.kind == sources::FrameKind::kStereo) {
    return absl::InvalidArgumentError(
        "--max-point-error applies to disparity and depth frames (--input disparity or depth): "
        "a stereo pair carries no disparity to quantize (the server matches the pair)");
  }
  if (o.jpeg_ladder.empty() && !o.video && o.uplink.encoding == sources::Uplink::kRaw) {
    return absl::InvalidArgumentError(
        "--max-point-error needs an encoding that compresses the disparity or depth (--encoding "
        "zstd, png, jpeg or h264, or --rate-control): raw frames carry every value's bytes as "
        "they are, so the bound would save nothing");
  }
  if (!o.stream_camera) {
    return absl::InvalidArgumentError(
        "--max-point-error needs the stream's camera (FrameSourceOptions::stream_camera): each "
        "frame is quantized with the camera the server processes it with");
  }
  return absl::OkStatus();
}

}  // namespace

// What the bound saved, frame by frame: the frame just encoded with the bound (the quantizer's
// counts are still that frame's) beside the same frame encoded without it.
struct FrameStore::Savings {
  double bytes[2] = {}, lossless[2] = {};  // [0] full resolution, [1] half
  std::size_t frames[2] = {};
  std::uint64_t values = 0, changed = 0;

  absl::Status Add(const sources::SourceFrame& from, sources::UplinkOptions options,
                   const v1::Frame& bounded, sources::UplinkFrame* uplink, bool half) {
    values += uplink->quantize_stats().valid;
    changed += uplink->quantize_stats().changed;
    options.max_point_error = 0;
    v1::Frame lossless_frame;
    if (absl::Status s = uplink->Encode(from, options); !s.ok()) return s;
    if (absl::Status s = uplink->ToProto(&lossless_frame); !s.ok()) return s;
    bytes[half] += GeometryBytes(bounded);
    lossless[half] += GeometryBytes(lossless_frame);
    ++frames[half];
    return absl::OkStatus();
  }

  NearLosslessSummary Summary(double bound, sources::FrameKind kind,
                              double request_bytes) const {
    auto mean = [&](const double* sum, int i) {
      return frames[i] > 0 ? sum[i] / static_cast<double>(frames[i]) : 0.0;
    };
    NearLosslessSummary n;
    n.max_point_error = bound;
    n.geometry = kind == sources::FrameKind::kDepth ? "depth" : "disparity";
    n.geometry_bytes = mean(bytes, 0);
    n.geometry_bytes_lossless = mean(lossless, 0);
    n.request_bytes = request_bytes;
    n.request_bytes_lossless = request_bytes + n.geometry_bytes_lossless - n.geometry_bytes;
    n.half_geometry_bytes = mean(bytes, 1);
    n.half_geometry_bytes_lossless = mean(lossless, 1);
    n.values = values;
    n.changed = changed;
    return n;
  }
};

std::string Describe(const NearLosslessSummary& n) {
  return fmt::format(
      "near-lossless <= {:g} m a point: {} {:.1f} KB a frame (lossless {:.1f} KB), {:.0f}% of "
      "its values changed",
      n.max_point_error, n.geometry, n.geometry_bytes / 1024, n.geometry_bytes_lossless / 1024,
      n.values > 0 ? 100.0 * static_cast<double>(n.changed) / static_cast<double>(n.values) : 0.0);
}

v1::CameraModel FrameStore::HalfCamera() const {
  return client::HalfResolutionCamera(*stream_camera_, kind_ == sources::FrameKind::kDisparity);
}

namespace {

// Up to `frames` of the source's frames, kept (cloned: a source may reuse its buffers).
absl::StatusOr<std::vector<sources::SourceFrame>> KeepFrames(sources::FrameSource& source,
                                                             std::uint64_t frames) {
  std::vector<sources::SourceFrame> originals;
  sources::SourceFrame frame;
  for (std::uint64_t i = 0; i < frames; ++i) {
    auto got = source.Next(&frame);
    if (!got.ok()) return got.status();
    if (!*got) break;
    sources::SourceFrame copy = frame;
    for (cv::Mat& m : copy.images) m = m.clone();
    copy.keep_alive.reset();
    originals.push_back(std::move(copy));
  }
  if (originals.empty()) return absl::InvalidArgumentError("the source gave no frames");
  return originals;
}

// How a video frame's images go: the encoder takes raw views of the colour (the geometry left
// unquantized there); disparity and depth go compressed (zstd), lossless or within the bound, as
// a robot whose uplink is thin enough to want video sends them.
struct VideoUplinks {
  explicit VideoUplinks(const sources::UplinkOptions& options) : raw(options), zstd(options) {
    raw.encoding = sources::Uplink::kRaw;
    raw.max_point_error = 0;
    zstd.encoding = sources::Uplink::kZstd;
  }
  sources::UplinkOptions raw, zstd;
};

}  // namespace

absl::Status FrameStore::VideoGeometry(const sources::SourceFrame& original,
                                       const sources::UplinkOptions& zstd, Savings* savings,
                                       sources::UplinkFrame* scratch, v1::Frame* frame) {
  frame->set_frame_id(original.name);
  if (absl::Status s = scratch->Encode(original, zstd); !s.ok()) return s;
  if (absl::Status s = scratch->ToProto(frame); !s.ok()) return s;
  if (zstd.max_point_error > 0) return savings->Add(original, zstd, *frame, scratch, false);
  return absl::OkStatus();
}

absl::Status FrameStore::PrepareLiveVideo(const FrameSourceOptions& o,
                                          const sources::UplinkOptions& uplink_options,
                                          sources::FrameSource& source, std::uint64_t frames,
                                          Savings* savings) {
  auto originals = KeepFrames(source, frames);
  if (!originals.ok()) return originals.status();
  // Each frame's tail: its geometry as PrepareVideo sends it, its colour images left out for
  // the pictures each send appends.
  const VideoUplinks uplinks(uplink_options);
  sources::UplinkFrame geometry;
  for (const sources::SourceFrame& original : *originals) {
    v1::Frame f;
    if (absl::Status s = VideoGeometry(original, uplinks.zstd, savings, &geometry, &f); !s.ok()) {
      return s;
    }
    f.clear_color();
    if (f.has_right()) f.clear_right();
    AddTail(f);
  }
  LiveVideo live;
  live.originals = *std::move(originals);
  live.raw = uplinks.raw;
  live.encoder = *o.video;
  live.settings = VideoSettings(*o.video, o.kind);
  live_video_ = std::move(live);
  return absl::OkStatus();
}

absl::Status FrameStore::PrepareVideo(const FrameSourceOptions& o,
                                      const sources::UplinkOptions& uplink_options,
                                      sources::FrameSource& source, std::uint64_t frames,
                                      Savings* savings) {
  // The source's frames, kept to be cycled.
  auto kept = KeepFrames(source, frames);
  if (!kept.ok()) return kept.status();
  const std::vector<sources::SourceFrame>& originals = *kept;
  const int interval =
      o.video->encoder.keyframe_interval > 0 ? o.video->encoder.keyframe_interval : 60;
  const std::size_t n = originals.size();
  std::size_t length = (n + interval - 1) / interval * interval;
  length = std::max(n, std::min(length, kMaxVideoSequence));

  VideoSequence sequence;
  sequence.length = length;
  sequence.source_frames = n;
  sequence.settings = VideoSettings(*o.video, o.kind);
  video::FrameEncoder encoder(*o.video);
  const VideoUplinks uplinks(uplink_options);
  sources::UplinkFrame uplink, geometry;
  std::vector<double> encode_ms;
  double video_bytes = 0;
  for (std::size_t i = 0; i < length; ++i) {
    const sources::SourceFrame& original = originals[i % n];
    if (absl::Status s = uplink.Encode(original, uplinks.raw); !s.ok()) return s;
    const double before = ThreadCpuMs();
    auto coded = encoder.Encode(uplink.input(), i);
    encode_ms.push_back(ThreadCpuMs() - before);
    if (!coded.ok()) {
      return absl::InvalidArgumentError("--encoding h264: " +
                                        std::string(coded.status().message()));
    }
    v1::Frame f;
    if (absl::Status s = VideoGeometry(original, uplinks.zstd, savings, &geometry, &f); !s.ok()) {
      return s;
    }
    if (absl::Status s = PutPictures(*coded, &f); !s.ok()) return s;
    sequence.keyframe.push_back(f.color().video().keyframe());
    video_bytes += static_cast<double>(encoder.last_bytes());
    AddTail(f);
  }
  if (!sequence.keyframe.front()) {
    return absl::InternalError("the video sequence does not start with an IDR");
  }
  std::vector<double> sorted = encode_ms;
  std::sort(sorted.begin(), sorted.end());
  sequence.encode_ms_median = sorted[sorted.size() / 2];
  double sum = 0;
  for (double ms : encode_ms) sum += ms;
  sequence.encode_ms_mean = sum / static_cast<double>(encode_ms.size());
  sequence.video_bytes_mean = video_bytes / static_cast<double>(length);
  video_ = std::move(sequence);
  return absl::OkStatus();
}

absl::StatusOr<FrameStore> FrameStore::Prepare(const FrameSourceOptions& o) {
  if (absl::Status s = CheckNearLossless(o); !s.ok()) return s;
  sources::SourceSpec spec = o.source;
  spec.synthetic_encoding = DisparityEncoding::kU16;
  sources::SourceOptions options;
  options.kind = o.kind;
  options.focal = o.focal;
  options.baseline = o.baseline;
  auto source = sources::OpenSource(spec, options);
  if (!source.ok()) return source.status();
  const sources::SourceInfo& info = (*source)->info();
  const std::uint64_t frames =
      info.frames_per_pass.value_or(static_cast<std::uint64_t>(std::max(1, o.synthetic_frames)));
  FrameStore store;
  store.camera_ = info.camera;
  store.kind_ = o.kind;
  if (o.stream_camera) {
    auto stream = o.stream_camera(info.camera);
    if (!stream.ok()) return stream.status();
    store.stream_camera_ = *std::move(stream);
  }
  // How full- and half-resolution frames travel. With a bound, each is quantized with the camera
  // the server processes it with: the stream's, and the half levels' own (Frame.camera, halved)
  // over it, as the server applies it; both resolved for the frame's size by the quantizer.
  const double bound = o.uplink.max_point_error;
  sources::UplinkOptions full = o.uplink, half = o.uplink;
  if (bound > 0) {
    full.camera = FrameSettings{};
    if (absl::Status s = convert::ApplyCamera(*store.stream_camera_, "config.camera", &full.camera);
        !s.ok()) {
      return s;
    }
    half.camera = full.camera;
    if (absl::Status s = convert::ApplyCamera(store.HalfCamera(), "frame.camera", &half.camera);
        !s.ok()) {
      return s;
    }
  }
  Savings savings;
  auto summarize = [&] {
    if (bound == 0) return;
    store.near_lossless_ = savings.Summary(bound, o.kind, store.MeanRequestBytes(0));
    store.description_ += ", " + Describe(*store.near_lossless_);
  };
  if (o.video) {
    if (!o.jpeg_ladder.empty()) {
      return absl::InvalidArgumentError("--encoding h264 has no JPEG ladder (--rate-control)");
    }
    const absl::Status prepared = o.live_video
                                      ? store.PrepareLiveVideo(o, full, **source, frames, &savings)
                                      : store.PrepareVideo(o, full, **source, frames, &savings);
    if (!prepared.ok()) return prepared;
    store.encoding_ = std::string(video::kH264);
    const std::string frames_text =
        fmt::format("{} ({} {} frames, {}x{})", Label(info),
                    o.live_video ? store.size() : store.video_->source_frames,
                    sources::Name(o.kind), info.width, info.height);
    store.description_ =
        o.live_video
            ? fmt::format(
                  "{}, h264 encoded live per stream at its rate controller's bitrate "
                  "({}), {:.1f} KB of geometry per frame",
                  frames_text, store.live_video_->settings, store.MeanRequestBytes() / 1024)
            : fmt::format(
                  "{}, h264 ({}; a sequence of {} frames, {:.1f} KB of pictures a frame, "
                  "encoded once in {:.2f} ms a frame), {:.0f} KB per frame",
                  frames_text, store.video_->settings, store.video_->length,
                  store.video_->video_bytes_mean / 1024, store.video_->encode_ms_median,
                  store.MeanRequestBytes() / 1024);
    summarize();
    return store;
  }
  store.encoding_ = o.jpeg_ladder.empty() ? sources::Name(o.uplink.encoding) : "adaptive";
  const bool halves = !o.jpeg_ladder.empty() && !o.half_resolution_ladder.empty() &&
                      (o.kind == sources::FrameKind::kDisparity ||
                       o.kind == sources::FrameKind::kDepth);
  if (!o.jpeg_ladder.empty()) {
    store.levels_.resize(o.jpeg_ladder.size() + (halves ? o.half_resolution_ladder.size() : 0));
  }
  sources::SourceFrame frame;
  sources::UplinkFrame uplink;
  auto encode_frame = [&](const sources::SourceFrame& from, const sources::UplinkOptions& options,
                          v1::Frame* f) {
    if (absl::Status s = uplink.Encode(from, options); !s.ok()) return s;
    f->set_frame_id(from.name);
    return uplink.ToProto(f);
  };
  // The frame at every quality of `ladder`, from level `first`: the colour as JPEG, the
  // geometry compressed (zstd; encoded once), lossless or within the bound. Half-resolution
  // frames carry their camera once the stream's is known (else SetStreamCamera sets it).
  auto add_ladder = [&](const sources::SourceFrame& from, const std::vector<int>& ladder,
                        std::size_t first, bool is_half) -> absl::Status {
    const sources::UplinkOptions& options = is_half ? half : full;
    sources::UplinkOptions zstd = options;
    zstd.encoding = sources::Uplink::kZstd;
    v1::Frame geometry;
    if (absl::Status s = encode_frame(from, zstd, &geometry); !s.ok()) return s;
    if (bound > 0) {
      if (absl::Status s = savings.Add(from, zstd, geometry, &uplink, is_half); !s.ok()) return s;
    }
    for (std::size_t level = 0; level < ladder.size(); ++level) {
      sources::UplinkOptions jpeg = options;
      jpeg.encoding = sources::Uplink::kJpeg;
      jpeg.jpeg_quality = ladder[level];
      jpeg.max_point_error = 0;  // its geometry is replaced by the one above
      v1::Frame f;
      if (absl::Status s = encode_frame(from, jpeg, &f); !s.ok()) return s;
      if (geometry.has_disparity()) *f.mutable_disparity() = geometry.disparity();
      if (geometry.has_depth()) *f.mutable_depth() = geometry.depth();
      if (is_half && store.stream_camera_) *f.mutable_camera() = store.HalfCamera();
      store.AddTail(f, first + level);
    }
    return absl::OkStatus();
  };
  if (halves) store.first_half_level_ = o.jpeg_ladder.size();
  for (std::uint64_t i = 0; i < frames; ++i) {
    auto got = (*source)->Next(&frame);
    if (!got.ok()) return got.status();
    if (!*got) break;
    if (o.jpeg_ladder.empty()) {
      v1::Frame f;
      if (absl::Status s = encode_frame(frame, full, &f); !s.ok()) return s;
      if (bound > 0) {
        if (absl::Status s = savings.Add(frame, full, f, &uplink, false); !s.ok()) return s;
      }
      store.AddTail(f);
      continue;
    }
    if (absl::Status s = add_ladder(frame, o.jpeg_ladder, 0, false); !s.ok()) return s;
    if (halves) {
      if (absl::Status s = add_ladder(HalfResolution(frame), o.half_resolution_ladder,
                                      o.jpeg_ladder.size(), true);
          !s.ok()) {
        return s;
      }
    }
  }
  if (o.jpeg_ladder.empty()) {
    store.description_ =
        fmt::format("{} ({} {} frames, {}x{}), {}, {:.0f} KB per frame", Label(info), store.size(),
                    sources::Name(o.kind), info.width, info.height,
                    sources::Name(o.uplink.encoding), store.MeanRequestBytes() / 1024);
  } else {
    store.description_ = fmt::format(
        "{} ({} {} frames, {}x{}), adaptive: {} geometry, JPEG colour at quality {} to {}{}, "
        "{:.0f} to {:.0f} KB per frame",
        Label(info), store.size(), sources::Name(o.kind), info.width, info.height,
        bound > 0 ? "near-lossless" : "lossless", o.jpeg_ladder.front(), o.jpeg_ladder.back(),
        halves ? fmt::format(", then at half resolution, {} to {}",
                             o.half_resolution_ladder.front(), o.half_resolution_ladder.back())
               : "",
        store.MeanRequestBytes(0) / 1024, store.MeanRequestBytes(store.levels() - 1) / 1024);
  }
  summarize();
  return store;
}

FrameStore FrameStore::FromFrames(const std::vector<v1::Frame>& frames, const CameraModel& camera,
                                  const std::string& description) {
  FrameStore store;
  for (const v1::Frame& f : frames) store.AddTail(f);
  store.camera_ = camera;
  store.description_ = description;
  return store;
}

absl::Status FrameStore::SetStreamCamera(const v1::CameraModel& stream) {
  if (stream_camera_) {
    if (stream_camera_->SerializeAsString() == stream.SerializeAsString()) {
      return absl::OkStatus();
    }
    return absl::FailedPreconditionError(
        "the frames were prepared for the stream camera { " + stream_camera_->ShortDebugString() +
        " } (their half-resolution camera and any --max-point-error quantization), not { " +
        stream.ShortDebugString() + " }");
  }
  stream_camera_ = stream;
  if (first_half_level_ == 0) return absl::OkStatus();
  const v1::CameraModel half = HalfCamera();
  for (std::size_t level = first_half_level_; level < levels_.size(); ++level) {
    for (std::shared_ptr<const std::string>& tail : levels_[level]) {
      v1::Frame frame;
      frame.ParseFromString(*tail);
      *frame.mutable_camera() = half;
      tail = std::make_shared<const std::string>(frame.SerializeAsString());
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<FrameStore> FrameStore::FromVideoFrames(const std::vector<v1::Frame>& frames,
                                                       const CameraModel& camera,
                                                       const std::string& description) {
  if (frames.empty() || !frames.front().color().video().keyframe()) {
    return absl::InvalidArgumentError("a video store starts with an IDR");
  }
  FrameStore store = FromFrames(frames, camera, description);
  VideoSequence sequence;
  sequence.length = sequence.source_frames = frames.size();
  for (const v1::Frame& f : frames) sequence.keyframe.push_back(f.color().video().keyframe());
  store.video_ = std::move(sequence);
  store.encoding_ = std::string(video::kH264);
  return store;
}

void FrameStore::AddTail(const v1::Frame& frame, std::size_t level) {
  v1::Frame tail = frame;
  tail.clear_sequence();
  tail.clear_capture_time_unix_ns();
  levels_[level].push_back(std::make_shared<const std::string>(tail.SerializeAsString()));
}

grpc::ByteBuffer FrameStore::Request(std::size_t index, std::uint64_t sequence,
                                     std::int64_t capture_time_unix_ns, std::size_t level) const {
  const auto& tails = levels_[std::min(level, levels_.size() - 1)];
  return Framed(*tails[index % tails.size()], sequence, capture_time_unix_ns, nullptr);
}

grpc::ByteBuffer FrameStore::RequestWith(std::size_t index, std::uint64_t sequence,
                                         std::int64_t capture_time_unix_ns,
                                         const std::string& fields) const {
  const auto& tails = levels_.front();
  return Framed(*tails[index % tails.size()], sequence, capture_time_unix_ns, &fields);
}

std::size_t FrameStore::RequestBytes(std::size_t index) const {
  return levels_.front()[index % size()]->size() + 16;
}

double FrameStore::MeanRequestBytes() const { return MeanRequestBytes(0); }

double FrameStore::MeanRequestBytes(std::size_t level) const {
  const auto& tails = levels_[level];
  if (tails.empty()) return 0;
  double sum = 0;
  for (const auto& t : tails) sum += static_cast<double>(t->size() + 16);
  return sum / static_cast<double>(tails.size());
}

std::size_t FrameStore::LevelFor(double budget_bytes) const {
  for (std::size_t level = 0; level < levels_.size(); ++level) {
    if (MeanRequestBytes(level) <= budget_bytes) return level;
  }
  return levels_.size() - 1;
}

grpc::ByteBuffer SerializeConfig(const v1::StreamConfig& config) {
  v1::StreamRequest request;
  *request.mutable_config() = config;
  const std::string bytes = request.SerializeAsString();
  grpc::Slice slice(bytes.data(), bytes.size());
  return grpc::ByteBuffer(&slice, 1);
}

absl::StatusOr<std::string> PictureFields(const client::FrameInput& coded) {
  v1::Frame pictures;
  if (absl::Status s = PutPictures(coded, &pictures); !s.ok()) return s;
  return pictures.SerializeAsString();
}

}  // namespace cloudcast::load
