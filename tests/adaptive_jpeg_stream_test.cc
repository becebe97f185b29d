// A rate-controlled client stream to a real server on 127.0.0.1 (AdaptiveJpegCoder as the
// stream's coder, the target held low): its half-resolution frames carry a halved camera and make
// the same surface as its full-resolution ones, as FleetTest.HalfResolutionLevelsMakeTheSameSurface
// checks for cloudcast-load's ladder.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <vector>

#include "cloudcast/client/adaptive_jpeg_coder.h"
#include "cloudcast/client/client.h"
#include "cloudcast/proto/convert.h"
#include "cloudcast/sources/uplink.h"
#include "support/server_fixture.h"
#include "support/synthetic_frame.h"

namespace cloudcast::client {
namespace {

// A rate-controlled stream whose target is held low: after a few frames it sends them at half
// resolution (Result::resolution_divisor 2), a quarter of the pixels reach the server, and the
// cloud keeps the full-resolution cloud's extent (each frame's own camera is halved to match).
TEST(AdaptiveJpegStreamTest, HalfResolutionFramesMakeTheSameSurface) {
  auto server = testing::StartTestServer();
  ASSERT_NE(server, nullptr);
  const testing::SyntheticFrame f = testing::MakeSyntheticFrame(320, 240);
  StreamConfig config;
  convert::SetCamera(f.camera, &config);
  config.mutable_camera()->clear_cx();  // the image's centre, at either resolution
  config.mutable_camera()->clear_cy();
  config.mutable_passthrough()->set_enabled(false);  // the whole scene
  config.set_delivery(v1::DELIVERY_ALL);             // every frame answered, in order

  AdaptiveJpegOptions jpeg;
  jpeg.fps = 30;
  jpeg.stream_camera = config.camera();
  auto coder = std::make_shared<AdaptiveJpegCoder>(jpeg);
  StreamOptions options;
  options.coder = coder;
  options.rate_control = RateControlOptions{};
  // 100 kbit/s whatever the link: 417 bytes a frame at 30 fps.
  options.rate_control->start_bps = options.rate_control->min_bps = options.rate_control->max_bps =
      100e3;
  auto client = Client::Connect(server->address());
  ASSERT_TRUE(client.ok()) << client.status();
  auto stream = (*client)->OpenStream(config, std::move(options));
  ASSERT_TRUE(stream.ok()) << stream.status();

  sources::UplinkFrame uplink;
  ASSERT_TRUE(uplink.Encode(f.frame, sources::UplinkOptions{}).ok());  // raw: the coder encodes
  constexpr int kFrames = 24;
  struct Summary {
    std::size_t pixels = 0, points = 0;
    double lo[3] = {1e9, 1e9, 1e9}, hi[3] = {-1e9, -1e9, -1e9};
  };
  std::vector<Summary> full, half;
  for (int i = 0; i < kFrames; ++i) {
    ASSERT_TRUE((*stream)->Send(uplink.input(), FrameMeta{}).ok());
    Result r;
    ASSERT_TRUE((*stream)->Read(&r));
    ASSERT_TRUE(r.ok()) << r.status;
    Summary s;
    s.pixels = r.reply.counts().pixels();
    s.points = r.cloud.size();
    for (const Point& p : r.cloud.points) {
      const double v[3] = {p.x, p.y, p.z};
      for (int a = 0; a < 3; ++a) {
        s.lo[a] = std::min(s.lo[a], v[a]);
        s.hi[a] = std::max(s.hi[a], v[a]);
      }
    }
    ASSERT_TRUE(r.resolution_divisor == 1 || r.resolution_divisor == 2);
    (r.resolution_divisor == 2 ? half : full).push_back(s);
  }
  ASSERT_TRUE((*stream)->CloseSend().ok());
  EXPECT_TRUE((*stream)->Finish().ok());
  ASSERT_FALSE(full.empty());
  ASSERT_FALSE(half.empty()) << "no frame went at half resolution under a 100 kbit/s target";
  std::printf("frames at full resolution %zu, at half %zu; points full %zu, half %zu\n",
              full.size(), half.size(), full.front().points, half.back().points);
  for (const Summary& s : full) EXPECT_EQ(s.pixels, 320u * 240);
  for (const Summary& s : half) EXPECT_EQ(s.pixels, 160u * 120);
  ASSERT_GT(full.front().points, 100u);
  ASSERT_GT(half.back().points, 100u);
  for (int a = 0; a < 3; ++a) {
    const double extent = full.front().hi[a] - full.front().lo[a];
    ASSERT_GT(extent, 0) << a;
    EXPECT_NEAR(half.back().lo[a], full.front().lo[a], 0.05 * extent) << "axis " << a;
    EXPECT_NEAR(half.back().hi[a], full.front().hi[a], 0.05 * extent) << "axis " << a;
  }
}

}  // namespace
}  // namespace cloudcast::client
