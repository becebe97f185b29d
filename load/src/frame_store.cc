#include "cloudcast/load/frame_store.h"

#include <glob.h>
#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <opencv2/core/mat.hpp>

#include "absl/status/status.h"
#include "cloudcast/client/opencv.h"
#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/datasets/tsukuba.h"
#include "cloudcast/io/image_io.h"
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

int CvType(DisparityEncoding e) {
  switch (e) {
    case DisparityEncoding::kU8:
      return CV_8UC1;
    case DisparityEncoding::kU16:
      return CV_16UC1;
    case DisparityEncoding::kF32:
      return CV_32FC1;
  }
  return CV_8UC1;
}

cv::Mat MatOf(const DisparityView& v) {
  return cv::Mat(static_cast<int>(v.height), static_cast<int>(v.width), CvType(v.encoding),
                 const_cast<void*>(static_cast<const void*>(v.data)), v.stride_bytes);
}

cv::Mat MatOf(const ColorView& v) {
  const int channels = static_cast<int>(BytesPerPixel(v.encoding));
  cv::Mat m(static_cast<int>(v.height), static_cast<int>(v.width), CV_8UC(channels),
            const_cast<void*>(static_cast<const void*>(v.data)), v.stride_bytes);
  return m;
}

// One frame's images as the uplink sends them. PNG keeps a float disparity only as 16-bit, so a
// float disparity stays raw under --encoding png/jpeg (the server takes mixed frames).
absl::StatusOr<v1::Frame> MakeFrame(const DisparityView& disparity, const ColorView& colour,
                                    const std::string& frame_id, const FrameSourceOptions& o) {
  v1::Frame frame;
  frame.set_frame_id(frame_id);
  if (o.uplink == Uplink::kZstd) {
    const convert::Compression z;
    if (auto s = convert::ToProto(disparity, z, "disparity",
                                  frame.mutable_disparity()->mutable_compressed());
        !s.ok()) {
      return s;
    }
    if (auto s =
            convert::ToProto(colour, z, "colour", frame.mutable_colour()->mutable_compressed());
        !s.ok()) {
      return s;
    }
    return frame;
  }
  const bool encode_disparity =
      o.uplink != Uplink::kRaw && disparity.encoding != DisparityEncoding::kF32;
  if (encode_disparity) {
    auto png = client::EncodePng(MatOf(disparity), o.png_compression);
    if (!png.ok()) return png.status();
    frame.mutable_disparity()->set_encoded(std::move(*png));
  } else if (auto s =
                 convert::ToProto(disparity, "disparity", frame.mutable_disparity()->mutable_raw());
             !s.ok()) {
    return s;
  }
  if (o.uplink == Uplink::kRaw || colour.encoding == ColorEncoding::kRGBA8 ||
      colour.encoding == ColorEncoding::kRGB8) {
    if (auto s = convert::ToProto(colour, "colour", frame.mutable_colour()->mutable_raw());
        !s.ok()) {
      return s;
    }
  } else {
    auto bytes = o.uplink == Uplink::kJpeg ? client::EncodeJpeg(MatOf(colour), o.jpeg_quality)
                                           : client::EncodePng(MatOf(colour), o.png_compression);
    if (!bytes.ok()) return bytes.status();
    frame.mutable_colour()->set_encoded(std::move(*bytes));
  }
  return frame;
}

// Natural order: "f2" before "f10".
bool NaturalLess(const std::string& a, const std::string& b) {
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (std::isdigit(static_cast<unsigned char>(a[i])) &&
        std::isdigit(static_cast<unsigned char>(b[j]))) {
      std::size_t i2 = i, j2 = j;
      while (i2 < a.size() && std::isdigit(static_cast<unsigned char>(a[i2]))) ++i2;
      while (j2 < b.size() && std::isdigit(static_cast<unsigned char>(b[j2]))) ++j2;
      const std::string na = a.substr(i, i2 - i), nb = b.substr(j, j2 - j);
      const std::size_t za = na.find_first_not_of('0'), zb = nb.find_first_not_of('0');
      const std::string ta = za == std::string::npos ? "" : na.substr(za);
      const std::string tb = zb == std::string::npos ? "" : nb.substr(zb);
      if (ta.size() != tb.size()) return ta.size() < tb.size();
      if (ta != tb) return ta < tb;
      i = i2;
      j = j2;
    } else {
      if (a[i] != b[j]) return a[i] < b[j];
      ++i;
      ++j;
    }
  }
  return a.size() - i < b.size() - j;
}

absl::StatusOr<std::vector<std::string>> Glob(const std::string& flag, const std::string& pattern) {
  glob_t g{};
  const int rc = ::glob(pattern.c_str(), 0, nullptr, &g);
  std::vector<std::string> out;
  if (rc == 0) {
    for (std::size_t i = 0; i < g.gl_pathc; ++i) out.emplace_back(g.gl_pathv[i]);
  }
  globfree(&g);
  if (out.empty())
    return absl::NotFoundError(fmt::format("{} '{}' matches no file", flag, pattern));
  std::sort(out.begin(), out.end(), NaturalLess);
  return out;
}

}  // namespace

bool ParseUplink(const std::string& name, Uplink* out) {
  if (name == "raw")
    *out = Uplink::kRaw;
  else if (name == "png")
    *out = Uplink::kPng;
  else if (name == "jpeg")
    *out = Uplink::kJpeg;
  else if (name == "zstd")
    *out = Uplink::kZstd;
  else
    return false;
  return true;
}

const char* Name(Uplink uplink) {
  switch (uplink) {
    case Uplink::kRaw:
      return "raw";
    case Uplink::kPng:
      return "png";
    case Uplink::kJpeg:
      return "jpeg";
    case Uplink::kZstd:
      return "zstd";
  }
  return "raw";
}

absl::StatusOr<FrameStore> FrameStore::Prepare(const FrameSourceOptions& o) {
  FrameStore store;
  std::uint32_t width = 0, height = 0;
  std::string kind;
  FrameSourceOptions options = o;
  const bool none = o.tsukuba_dir.empty() && o.disparity_glob.empty() && o.synthetic_width == 0;
  if (none && tsukuba::Present(tsukuba::DefaultDir())) options.tsukuba_dir = tsukuba::DefaultDir();
  if (none && options.tsukuba_dir.empty()) {
    options.synthetic_width = 640;
    options.synthetic_height = 480;
  }

  if (!options.tsukuba_dir.empty() || !options.disparity_glob.empty()) {
    std::vector<std::string> disparities, colours;
    if (!options.tsukuba_dir.empty()) {
      const std::string& dir = options.tsukuba_dir;
      auto d = Glob("--tsukuba", dir + "/groundtruth/disparity_maps/left/*.png");
      if (!d.ok()) return d.status();
      auto c = Glob("--tsukuba", dir + "/illumination/" + options.illumination + "/left/*.png");
      if (!c.ok()) return c.status();
      disparities = std::move(*d);
      colours = std::move(*c);
      kind = "New Tsukuba";
    } else {
      if (options.colour_glob.empty()) {
        return absl::InvalidArgumentError("--disparity-glob needs --colour-glob");
      }
      auto d = Glob("--disparity-glob", options.disparity_glob);
      if (!d.ok()) return d.status();
      auto c = Glob("--colour-glob", options.colour_glob);
      if (!c.ok()) return c.status();
      disparities = std::move(*d);
      colours = std::move(*c);
      kind = "images";
    }
    if (disparities.size() != colours.size()) {
      return absl::InvalidArgumentError(
          fmt::format("{} disparity images but {} colour images: they pair up one to one",
                      disparities.size(), colours.size()));
    }
    for (std::size_t i = 0; i < disparities.size(); ++i) {
      auto d = LoadDisparity(disparities[i]);
      if (!d.ok()) return d.status();
      auto c = LoadColor(colours[i]);
      if (!c.ok()) return c.status();
      const std::string id = std::filesystem::path(disparities[i]).stem().string();
      auto frame = MakeFrame(d->view(), c->view(), id, options);
      if (!frame.ok()) return frame.status();
      store.AddTail(*frame);
      width = d->width;
      height = d->height;
    }
    store.camera_ = CameraModel::PclCompatible(width, height, 615);
  } else {
    const SyntheticScene scene = SyntheticScene::Default();
    for (int i = 0; i < std::max(1, options.synthetic_frames); ++i) {
      SyntheticOptions so;
      so.width = options.synthetic_width;
      so.height = options.synthetic_height;
      so.frame = static_cast<std::uint64_t>(i);
      so.disparity_encoding = DisparityEncoding::kU16;
      auto rendered = scene.Render(so);
      if (!rendered.ok()) return rendered.status();
      auto frame = MakeFrame(rendered->disparity_view(), rendered->colour_view(),
                             "synthetic_" + std::to_string(i), options);
      if (!frame.ok()) return frame.status();
      store.AddTail(*frame);
      store.camera_ = rendered->camera;
    }
    width = options.synthetic_width;
    height = options.synthetic_height;
    kind = "synthetic";
  }
  store.description_ =
      fmt::format("{} ({} frames, {}x{}), {}, {:.0f} KB per frame", kind, store.size(), width,
                  height, Name(options.uplink), store.MeanRequestBytes() / 1024);
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

void FrameStore::AddTail(const v1::Frame& frame) {
  v1::Frame tail = frame;
  tail.clear_sequence();
  tail.clear_capture_time_unix_ns();
  tails_.push_back(std::make_shared<const std::string>(tail.SerializeAsString()));
}

grpc::ByteBuffer FrameStore::Request(std::size_t index, std::uint64_t sequence,
                                     std::int64_t capture_time_unix_ns) const {
  const std::string& tail = *tails_[index % tails_.size()];
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
  return tails_[index % tails_.size()]->size() + 16;
}

double FrameStore::MeanRequestBytes() const {
  if (tails_.empty()) return 0;
  double sum = 0;
  for (const auto& t : tails_) sum += static_cast<double>(t->size() + 16);
  return sum / static_cast<double>(tails_.size());
}

grpc::ByteBuffer SerializeConfig(const v1::StreamConfig& config) {
  v1::StreamRequest request;
  *request.mutable_config() = config;
  const std::string bytes = request.SerializeAsString();
  grpc::Slice slice(bytes.data(), bytes.size());
  return grpc::ByteBuffer(&slice, 1);
}

}  // namespace cloudcast::load
