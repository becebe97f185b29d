#include "cloudcast/load/frame_store.h"

#include <spdlog/fmt/fmt.h>

#include <algorithm>

#include "absl/status/status.h"

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

// A short name of the source for the description.
std::string Label(const sources::SourceInfo& info) {
  if (info.kind == "tsukuba") return "New Tsukuba";
  if (info.kind == "glob") return "images";
  return info.kind;
}

}  // namespace

absl::StatusOr<FrameStore> FrameStore::Prepare(const FrameSourceOptions& o) {
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
  if (!o.jpeg_ladder.empty()) store.levels_.resize(o.jpeg_ladder.size());
  sources::SourceFrame frame;
  sources::UplinkFrame uplink;
  auto encode = [&](const sources::UplinkOptions& options, v1::Frame* f) {
    if (absl::Status s = uplink.Encode(frame, options); !s.ok()) return s;
    f->set_frame_id(frame.name);
    return uplink.ToProto(f);
  };
  for (std::uint64_t i = 0; i < frames; ++i) {
    auto got = (*source)->Next(&frame);
    if (!got.ok()) return got.status();
    if (!*got) break;
    if (o.jpeg_ladder.empty()) {
      v1::Frame f;
      if (absl::Status s = encode(o.uplink, &f); !s.ok()) return s;
      store.AddTail(f);
      continue;
    }
    // The ladder: the geometry lossless once, the colour at every quality.
    sources::UplinkOptions lossless = o.uplink;
    lossless.encoding = sources::Uplink::kZstd;
    v1::Frame geometry;
    if (absl::Status s = encode(lossless, &geometry); !s.ok()) return s;
    for (std::size_t level = 0; level < o.jpeg_ladder.size(); ++level) {
      sources::UplinkOptions jpeg = o.uplink;
      jpeg.encoding = sources::Uplink::kJpeg;
      jpeg.jpeg_quality = o.jpeg_ladder[level];
      v1::Frame f;
      if (absl::Status s = encode(jpeg, &f); !s.ok()) return s;
      if (geometry.has_disparity()) *f.mutable_disparity() = geometry.disparity();
      if (geometry.has_depth()) *f.mutable_depth() = geometry.depth();
      store.AddTail(f, level);
    }
  }
  store.camera_ = info.camera;
  store.kind_ = o.kind;
  if (o.jpeg_ladder.empty()) {
    store.description_ =
        fmt::format("{} ({} {} frames, {}x{}), {}, {:.0f} KB per frame", Label(info), store.size(),
                    sources::Name(o.kind), info.width, info.height,
                    sources::Name(o.uplink.encoding), store.MeanRequestBytes() / 1024);
  } else {
    store.description_ = fmt::format(
        "{} ({} {} frames, {}x{}), adaptive: lossless geometry, JPEG colour at quality {} to {}, "
        "{:.0f} to {:.0f} KB per frame",
        Label(info), store.size(), sources::Name(o.kind), info.width, info.height,
        o.jpeg_ladder.front(), o.jpeg_ladder.back(), store.MeanRequestBytes(0) / 1024,
        store.MeanRequestBytes(store.levels() - 1) / 1024);
  }
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

void FrameStore::AddTail(const v1::Frame& frame, std::size_t level) {
  v1::Frame tail = frame;
  tail.clear_sequence();
  tail.clear_capture_time_unix_ns();
  levels_[level].push_back(std::make_shared<const std::string>(tail.SerializeAsString()));
}

grpc::ByteBuffer FrameStore::Request(std::size_t index, std::uint64_t sequence,
                                     std::int64_t capture_time_unix_ns, std::size_t level) const {
  const auto& tails = levels_[std::min(level, levels_.size() - 1)];
  const std::string& tail = *tails[index % tails.size()];
  const auto time = static_cast<std::uint64_t>(capture_time_unix_ns);  // int64 as varint
  const std::size_t frame_bytes = 1 + VarintSize(sequence) + 1 + VarintSize(time) + tail.size();
  std::uint8_t header[1 + 10 + 1 + 10 + 1 + 10];
  std::size_t n = 0;
  header[n++] = kRequestFrameTag;
  n += PutVarint(frame_bytes, header + n);
  header[n++] = kSequenceTag;
  n += PutVarint(sequence, header + n);
  header[n++] = kCaptureTimeTag;
  n += PutVarint(time, header + n);
  grpc::Slice slices[2] = {grpc::Slice(header, n),
                           grpc::Slice(tail.data(), tail.size(), grpc::Slice::STATIC_SLICE)};
  return grpc::ByteBuffer(slices, 2);
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

}  // namespace cloudcast::load
