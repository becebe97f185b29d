// The half-resolution floor of the client library's adaptive JPEG coder: the halving itself
// (cloudcast/client/half_resolution.h, which cloudcast-load's FrameStore uses too) and
// AdaptiveJpegCoder going to half resolution under a low target and back when it rises.
#include "cloudcast/client/half_resolution.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "cloudcast/client/adaptive_jpeg_coder.h"
#include "cloudcast/sources/uplink.h"
#include "support/synthetic_frame.h"

namespace cloudcast::client {
namespace {

TEST(HalfResolutionTest, SamplesMeasurementsAndAveragesColour) {
  // 4x2 pixels of 2 bytes; every second pixel of every second row.
  const std::uint16_t disparity[8] = {1, 2, 3, 4, 5, 6, 7, 8};
  std::uint16_t half[2] = {0, 0};
  SampleHalf(reinterpret_cast<const std::uint8_t*>(disparity), 8, 4, 2, 2,
             reinterpret_cast<std::uint8_t*>(half), 4);
  EXPECT_EQ(half[0], 1);
  EXPECT_EQ(half[1], 3);
  // 2x2 pixels of one channel, then an odd column and row left out (3x3 -> 1x1).
  const std::uint8_t grey[9] = {10, 20, 99, 30, 41, 99, 99, 99, 99};
  std::uint8_t mean = 0;
  AverageHalf(grey, 3, 3, 3, 1, &mean, 1);
  EXPECT_EQ(mean, 25);  // (10 + 20 + 30 + 41 + 2) / 4, rounded
}

TEST(HalfResolutionTest, TheCameraHalvesWhatIsInPixels) {
  v1::CameraModel full;
  full.set_fx(600);
  full.set_fy(500);
  full.set_cx(320);
  full.set_baseline(0.1);
  full.set_disparity_offset(4);
  const v1::CameraModel half = HalfResolutionCamera(full, /*disparity=*/true);
  EXPECT_EQ(half.fx(), 300);
  EXPECT_EQ(half.fy(), 250);
  EXPECT_EQ(half.cx(), 160);
  EXPECT_FALSE(half.has_cy());  // unset: the image's centre at either resolution
  EXPECT_EQ(half.disparity_scale(), 0.5);
  EXPECT_EQ(half.disparity_offset(), 2);
  EXPECT_FALSE(half.has_baseline());  // the stream's applies
  const v1::CameraModel depth = HalfResolutionCamera(full, /*disparity=*/false);
  EXPECT_FALSE(depth.has_disparity_scale());
  EXPECT_FALSE(depth.has_disparity_offset());
}

TEST(HalfResolutionTest, RefusesWhatItCannotHalve) {
  HalfResolutionFrame half;
  const std::string file = "not raw";
  const absl::Status s = half.Make(DisparityFrame{EncodedImage{file}, EncodedImage{file}});
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("disparity"), std::string::npos) << s;
}

// Under a target below even the lossless disparity map, the next frame goes at half resolution
// with a halved camera (no JPEG quality could help); when the target rises the frames come back.
TEST(AdaptiveJpegCoderTest, FallsToHalfResolutionAndComesBack) {
  const testing::SyntheticFrame f = testing::MakeSyntheticFrame(320, 240);
  sources::UplinkFrame uplink;
  ASSERT_TRUE(uplink.Encode(f.frame, sources::UplinkOptions{}).ok());
  AdaptiveJpegOptions options;
  options.fps = 30;
  options.stream_camera.set_fx(400);
  AdaptiveJpegCoder coder(options);
  auto encode = [&](std::int64_t bps) {
    coder.SetStreamBitrate(bps, 0);
    absl::StatusOr<FrameInput> coded = coder.Encode(uplink.input(), 0);
    EXPECT_TRUE(coded.ok()) << coded.status();
  };
  encode(50'000'000);
  const std::size_t full_bytes = coder.last_bytes();
  EXPECT_FALSE(coder.last_half());
  EXPECT_EQ(coder.last_resolution().divisor, 1);
  EXPECT_FALSE(coder.last_resolution().camera.has_value());
  ASSERT_GT(coder.last_geometry_bytes(), 83u);
  encode(20'000);  // 83 bytes a frame: under the lossless disparity alone
  ASSERT_TRUE(coder.last_half()) << "the disparity alone is over the budget";
  EXPECT_EQ(coder.last_quality(), options.min_quality);
  EXPECT_LT(coder.last_bytes(), full_bytes / 2);
  const FrameCoder::Resolution half = coder.last_resolution();
  EXPECT_EQ(half.divisor, 2);
  ASSERT_TRUE(half.camera.has_value());
  EXPECT_EQ(half.camera->fx(), 200);
  EXPECT_EQ(half.camera->disparity_scale(), 0.5);
  for (int i = 0; i < 5; ++i) encode(20'000);
  EXPECT_TRUE(coder.last_half()) << "the target still carries no full-resolution frame";
  encode(50'000'000);
  encode(50'000'000);
  EXPECT_FALSE(coder.last_half());
  EXPECT_EQ(coder.last_resolution().divisor, 1);
}

// When the disparity fits the budget but the frame does not, the quality goes down first and
// only at its floor does the resolution.
TEST(AdaptiveJpegCoderTest, LowersTheQualityBeforeTheResolution) {
  testing::SyntheticFrame f = testing::MakeSyntheticFrame(320, 240);
  f.frame.images[0].setTo(100);  // a flat disparity map: a few bytes compressed
  sources::UplinkFrame uplink;
  ASSERT_TRUE(uplink.Encode(f.frame, sources::UplinkOptions{}).ok());
  AdaptiveJpegOptions options;
  options.fps = 1;  // the target is the budget in bits
  AdaptiveJpegCoder coder(options);
  coder.SetStreamBitrate(50'000'000, 0);
  ASSERT_TRUE(coder.Encode(uplink.input(), 0).ok());
  const std::size_t geometry = coder.last_geometry_bytes();
  ASSERT_LT(geometry, 1000u);
  std::vector<int> qualities;
  for (int i = 0; i < 40 && !coder.last_half(); ++i) {
    qualities.push_back(coder.last_quality());
    coder.SetStreamBitrate(static_cast<std::int64_t>(8 * (geometry + 20)), 0);
    ASSERT_TRUE(coder.Encode(uplink.input(), 0).ok());
  }
  ASSERT_TRUE(coder.last_half());
  ASSERT_GE(qualities.size(), 3u) << "the quality went down before the resolution";
  EXPECT_EQ(qualities.back(), options.min_quality);
  EXPECT_TRUE(std::is_sorted(qualities.rbegin(), qualities.rend()));
}

}  // namespace
}  // namespace cloudcast::client
