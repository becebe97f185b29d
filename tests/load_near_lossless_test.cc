// cloudcast-load --max-point-error (issue 27 item 5): the frame store quantizes each prepared
// frame's disparity or depth with the camera the server will process that frame with. Checked on
// every frame of every store here: each valid pixel's point, as the server's own conversion makes
// it from the frame's bytes (decoded from the request, the stream's camera with the frame's own
// over it), within the bound of the lossless store's point, validity kept; the half-resolution
// levels of the rate-control ladder against their own (halved) camera; the bytes saved as the
// report gives them; and the frames the bound cannot apply to refused, naming the flag.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "cloudcast/client/half_resolution.h"
#include "cloudcast/core/filters.h"
#include "cloudcast/core/frame_codec.h"
#include "cloudcast/core/limits.h"
#include "cloudcast/core/near_lossless.h"
#include "cloudcast/core/settings.h"
#include "cloudcast/load/frame_store.h"
#include "cloudcast/load/report.h"
#include "cloudcast/proto/convert.h"
#include "support/frame_store_requests.h"

namespace cloudcast::load {
namespace {

constexpr double kLeaf = 0.03;  // the server's default voxel leaf, metres

FrameSourceOptions Synthetic(sources::FrameKind kind, double bound,
                             sources::Uplink encoding = sources::Uplink::kZstd) {
  FrameSourceOptions o;
  o.source.synthetic_width = 160;
  o.source.synthetic_height = 120;
  o.synthetic_frames = 3;
  o.kind = kind;
  o.uplink.encoding = encoding;
  o.uplink.max_point_error = bound;
  o.stream_camera = testing::LoadStreamCamera;
  return o;
}

FrameSourceOptions Ladder(sources::FrameKind kind, double bound) {
  FrameSourceOptions o = Synthetic(kind, bound);
  o.jpeg_ladder = {90, 50};
  o.half_resolution_ladder = {70};
  return o;
}

// A decoded disparity or depth map of a request, and the camera the server converts it with.
struct Geometry {
  PlaneDecompressor decompressor;
  DisparityView disparity;
  DepthView depth;
  bool is_depth = false;
  CameraModel camera;
  std::uint32_t width = 0, height = 0;
};

// Decodes frame `index` at `level` of `store` as the server does: its compressed disparity or
// depth, and its camera: the stream's, the frame's own over it, resolved for its size.
void Decode(const FrameStore& store, std::size_t index, std::size_t level, Geometry* g) {
  const v1::Frame frame = testing::ParsedRequest(store, index, 1, 1, level).frame();
  ASSERT_TRUE(store.stream_camera().has_value());
  FrameSettings settings;
  ASSERT_TRUE(convert::ApplyCamera(*store.stream_camera(), "config.camera", &settings).ok());
  if (frame.has_camera()) {
    ASSERT_TRUE(convert::ApplyCamera(frame.camera(), "frame.camera", &settings).ok());
  }
  const Limits limits;
  if (frame.has_depth()) {
    ASSERT_TRUE(frame.depth().has_compressed()) << "depth lossless-coded (zstd)";
    ASSERT_TRUE(convert::DecodeCompressed(frame.depth().compressed(), "depth", limits,
                                          &g->decompressor, &g->depth)
                    .ok());
    g->is_depth = true;
    g->width = g->depth.width;
    g->height = g->depth.height;
  } else {
    ASSERT_TRUE(frame.disparity().has_compressed()) << "disparity lossless-coded (zstd)";
    ASSERT_TRUE(convert::DecodeCompressed(frame.disparity().compressed(), "disparity", limits,
                                          &g->decompressor, &g->disparity)
                    .ok());
    g->width = g->disparity.width;
    g->height = g->disparity.height;
  }
  g->camera = settings.PipelineFor(g->width, g->height).camera;
}

PointCloud Points(const Geometry& g) {
  std::vector<std::uint8_t> grey(std::size_t{g.width} * g.height, 128);
  const ColorView colour{grey.data(), grey.size(), g.width, g.height, g.width,
                         ColorEncoding::kMono8};
  PointCloud cloud;
  const absl::Status s = g.is_depth ? ConvertToOrganized(g.camera, g.depth, colour, &cloud)
                                    : ConvertToOrganized(g.camera, g.disparity, colour, &cloud);
  EXPECT_TRUE(s.ok()) << s;
  return cloud;
}

struct Moved {
  std::size_t valid = 0, moved = 0, over = 0, validity_changed = 0;
  double worst = 0;
};

Moved Compare(const PointCloud& lossless, const PointCloud& near, double bound) {
  Moved m;
  EXPECT_EQ(lossless.size(), near.size());
  for (std::size_t i = 0; i < lossless.size() && i < near.size(); ++i) {
    const Point& a = lossless.points[i];
    const Point& b = near.points[i];
    const bool va = std::isfinite(a.z), vb = std::isfinite(b.z);
    if (va != vb) {
      ++m.validity_changed;
      continue;
    }
    if (!va) continue;
    ++m.valid;
    const double dx = double{a.x} - b.x, dy = double{a.y} - b.y, dz = double{a.z} - b.z;
    const double e = std::sqrt(dx * dx + dy * dy + dz * dz);
    m.worst = std::max(m.worst, e);
    m.over += e > bound;
    m.moved += e > 0;
  }
  return m;
}

// Every frame of `levels` of `near` against the same frame of `lossless`: the same camera, every
// point within `bound`, validity kept, some points moved. Returns the points moved.
std::size_t ExpectEveryFrameWithinBound(const FrameStore& lossless, const FrameStore& near,
                                        const std::vector<std::size_t>& levels, double bound) {
  std::size_t moved = 0;
  EXPECT_EQ(lossless.size(), near.size());
  for (std::size_t level : levels) {
    for (std::size_t i = 0; i < near.size(); ++i) {
      SCOPED_TRACE("frame " + std::to_string(i) + " level " + std::to_string(level));
      Geometry a, b;
      Decode(lossless, i, level, &a);
      Decode(near, i, level, &b);
      EXPECT_EQ(a.camera.fx, b.camera.fx);
      EXPECT_EQ(a.width, b.width);
      const Moved m = Compare(Points(a), Points(b), bound);
      EXPECT_GT(m.valid, a.width * a.height / 4) << "a frame mostly of points";
      EXPECT_EQ(m.validity_changed, 0u);
      EXPECT_EQ(m.over, 0u) << "worst " << m.worst << " m against a bound of " << bound;
      moved += m.moved;
    }
  }
  return moved;
}

TEST(LoadNearLossless, EveryZstdFrameWithinTheBoundDisparityAndDepth) {
  for (sources::FrameKind kind : {sources::FrameKind::kDisparity, sources::FrameKind::kDepth}) {
    SCOPED_TRACE(sources::Name(kind));
    for (double bound : {kLeaf / 4, kLeaf}) {
      SCOPED_TRACE(bound);
      const FrameStore lossless = FrameStore::Prepare(Synthetic(kind, 0)).value();
      const FrameStore near = FrameStore::Prepare(Synthetic(kind, bound)).value();
      EXPECT_FALSE(lossless.near_lossless().has_value());
      ASSERT_TRUE(near.near_lossless().has_value());
      const std::size_t moved = ExpectEveryFrameWithinBound(lossless, near, {0}, bound);
      EXPECT_GT(moved, 0u) << "the bound changed nothing";
      // What the report gives: fewer bytes with the bound, and its lossless figure is the
      // lossless store's (to the byte or two of a length prefix).
      const NearLosslessSummary& n = *near.near_lossless();
      EXPECT_EQ(n.max_point_error, bound);
      EXPECT_EQ(n.geometry, kind == sources::FrameKind::kDepth ? "depth" : "disparity");
      std::printf("%s at %g m: %.0f bytes a frame (lossless %.0f), %.0f%% of values changed\n",
                  n.geometry.c_str(), bound, n.geometry_bytes, n.geometry_bytes_lossless,
                  100.0 * static_cast<double>(n.changed) / static_cast<double>(n.values));
      // At the leaf, fewer bytes. (A quarter of it changes an eighth of this small synthetic
      // disparity's values, whose smooth rows the steps it makes can cost a few bytes more.)
      if (bound == kLeaf) {
        EXPECT_LT(n.geometry_bytes, n.geometry_bytes_lossless);
        EXPECT_LT(near.MeanRequestBytes(0), lossless.MeanRequestBytes(0));
      }
      EXPECT_DOUBLE_EQ(n.request_bytes, near.MeanRequestBytes(0));
      EXPECT_NEAR(n.request_bytes_lossless, lossless.MeanRequestBytes(0), 4);
      EXPECT_GT(n.values, 0u);
      EXPECT_GT(n.changed, 0u);
      EXPECT_LE(n.changed, n.values);
      EXPECT_EQ(n.half_geometry_bytes, 0);
      EXPECT_NE(near.description().find("near-lossless <= "), std::string::npos)
          << near.description();
      const std::string table = [&] {
        Report report;
        report.near_lossless = near.near_lossless();
        return GhzJson(report)["encoding"]["nearLossless"].dump();
      }();
      EXPECT_NE(table.find("\"geometryBytesPerFrameLossless\""), std::string::npos) << table;
    }
  }
}

// The rate-control ladder: full-resolution levels quantized with the stream's camera, the
// half-resolution levels with their own (HalfResolutionCamera of the stream's, which they carry),
// each checked on every frame with the camera the server would use for it.
TEST(LoadNearLossless, HalfResolutionLevelsAreQuantizedWithTheHalvedCamera) {
  for (sources::FrameKind kind : {sources::FrameKind::kDisparity, sources::FrameKind::kDepth}) {
    SCOPED_TRACE(sources::Name(kind));
    const FrameStore lossless = FrameStore::Prepare(Ladder(kind, 0)).value();
    const FrameStore near = FrameStore::Prepare(Ladder(kind, kLeaf)).value();
    ASSERT_EQ(near.levels(), 3u);
    const v1::CameraModel half = client::HalfResolutionCamera(
        *near.stream_camera(), kind == sources::FrameKind::kDisparity);
    for (std::size_t i = 0; i < near.size(); ++i) {
      const v1::Frame f = testing::ParsedRequest(near, i, 1, 1, 2).frame();
      ASSERT_TRUE(f.has_camera()) << "a half-resolution frame carries its camera";
      EXPECT_EQ(f.camera().SerializeAsString(), half.SerializeAsString());
      EXPECT_EQ(f.has_depth() ? f.depth().compressed().width() : f.disparity().compressed().width(),
                80u);
      EXPECT_FALSE(testing::ParsedRequest(near, i, 1, 1, 0).frame().has_camera());
    }
    EXPECT_GT(ExpectEveryFrameWithinBound(lossless, near, {0, 1, 2}, kLeaf), 0u);
    const NearLosslessSummary& n = *near.near_lossless();
    EXPECT_GT(n.half_geometry_bytes, 0);
    EXPECT_LT(n.half_geometry_bytes, n.half_geometry_bytes_lossless);
    EXPECT_LT(n.half_geometry_bytes, n.geometry_bytes);
    EXPECT_LT(near.MeanRequestBytes(2), lossless.MeanRequestBytes(2));
    // The camera matters: the same half-resolution maps quantized with the stream's full camera
    // (the mistake this guards against: a ray's angle taken at half its size) move some points
    // past the bound as the server converts them, with their own camera.
    std::size_t over_with_full_camera = 0;
    PointErrorQuantizer quantizer;
    FrameSettings stream;
    ASSERT_TRUE(convert::ApplyCamera(*near.stream_camera(), "config.camera", &stream).ok());
    for (std::size_t i = 0; i < lossless.size(); ++i) {
      Geometry g;
      Decode(lossless, i, 2, &g);
      const CameraModel wrong = stream.PipelineFor(g.width, g.height).camera;
      Geometry q;
      q.is_depth = g.is_depth;
      q.camera = g.camera;
      q.width = g.width;
      q.height = g.height;
      if (g.is_depth) {
        ASSERT_TRUE(quantizer.Quantize(g.depth, wrong, kLeaf, "depth", &q.depth).ok());
      } else {
        ASSERT_TRUE(quantizer.Quantize(g.disparity, wrong, kLeaf, "disparity", &q.disparity).ok());
      }
      over_with_full_camera += Compare(Points(g), Points(q), kLeaf).over;
    }
    EXPECT_GT(over_with_full_camera, 0u) << "this check cannot tell the cameras apart";
  }
}

// --encoding h264: the colour goes as video, the geometry compressed within the bound; every
// frame of the picture sequence checked.
TEST(LoadNearLossless, VideoFramesCarryTheBoundedGeometry) {
  auto video = [](double bound) {
    FrameSourceOptions o = Synthetic(sources::FrameKind::kDisparity, bound);
    video::FrameEncoderOptions v;
    v.encoder.preset = "ultrafast";
    v.encoder.crf = 20;
    v.encoder.keyframe_interval = 3;
    o.video = v;
    return FrameStore::Prepare(o).value();
  };
  const FrameStore lossless = video(0), near = video(kLeaf);
  ASSERT_TRUE(near.video().has_value());
  EXPECT_GT(ExpectEveryFrameWithinBound(lossless, near, {0}, kLeaf), 0u);
  ASSERT_TRUE(near.near_lossless().has_value());
  EXPECT_LT(near.near_lossless()->geometry_bytes, near.near_lossless()->geometry_bytes_lossless);
}

// png and jpeg: the geometry is a PNG file of the quantized map, smaller than the lossless one.
TEST(LoadNearLossless, PngGeometryShrinks) {
  for (sources::Uplink encoding : {sources::Uplink::kPng, sources::Uplink::kJpeg}) {
    SCOPED_TRACE(sources::Name(encoding));
    const FrameStore near =
        FrameStore::Prepare(Synthetic(sources::FrameKind::kDisparity, kLeaf, encoding)).value();
    const FrameStore lossless =
        FrameStore::Prepare(Synthetic(sources::FrameKind::kDisparity, 0, encoding)).value();
    ASSERT_TRUE(near.near_lossless().has_value());
    EXPECT_LT(near.near_lossless()->geometry_bytes, near.near_lossless()->geometry_bytes_lossless);
    EXPECT_LT(near.MeanRequestBytes(0), lossless.MeanRequestBytes(0));
    EXPECT_FALSE(testing::ParsedRequest(near, 0, 1, 1).frame().disparity().encoded().empty());
  }
}

TEST(LoadNearLossless, FramesTheBoundCannotApplyToAreRefusedNamingTheFlag) {
  struct Case {
    std::string what;
    FrameSourceOptions options;
    std::string message;
  };
  std::vector<Case> cases;
  cases.push_back({"stereo", Synthetic(sources::FrameKind::kStereo, kLeaf), "stereo pair"});
  cases.push_back({"raw", Synthetic(sources::FrameKind::kDisparity, kLeaf, sources::Uplink::kRaw),
                   "--encoding zstd"});
  cases.push_back({"negative", Synthetic(sources::FrameKind::kDisparity, -1), ">= 0"});
  cases.push_back({"nan", Synthetic(sources::FrameKind::kDisparity, std::nan("")), ">= 0"});
  cases.push_back({"infinite", Synthetic(sources::FrameKind::kDisparity, INFINITY), "finite"});
  Case no_camera{"no camera", Synthetic(sources::FrameKind::kDisparity, kLeaf), "camera"};
  no_camera.options.stream_camera = nullptr;
  cases.push_back(no_camera);
  Case bad_camera{"bad camera", Synthetic(sources::FrameKind::kDisparity, kLeaf), "config.camera.fx"};
  bad_camera.options.stream_camera = [](const CameraModel& c) -> absl::StatusOr<v1::CameraModel> {
    v1::CameraModel m = testing::LoadStreamCamera(c).value();
    m.set_fx(-1);
    return m;
  };
  cases.push_back(bad_camera);
  for (const Case& c : cases) {
    auto store = FrameStore::Prepare(c.options);
    ASSERT_FALSE(store.ok()) << c.what;
    EXPECT_TRUE(absl::IsInvalidArgument(store.status())) << c.what << ": " << store.status();
    EXPECT_NE(store.status().message().find(c.message), std::string::npos)
        << c.what << ": " << store.status();
    if (c.what != "bad camera") {
      EXPECT_NE(store.status().message().find("--max-point-error"), std::string::npos)
          << c.what << ": " << store.status();
    }
  }
  // A store quantized for one stream camera takes no other.
  FrameStore store = FrameStore::Prepare(Ladder(sources::FrameKind::kDisparity, kLeaf)).value();
  EXPECT_TRUE(store.SetStreamCamera(*store.stream_camera()).ok());
  v1::CameraModel other = *store.stream_camera();
  other.set_fx(other.fx() * 2);
  EXPECT_TRUE(absl::IsFailedPrecondition(store.SetStreamCamera(other)));
}

}  // namespace
}  // namespace cloudcast::load
