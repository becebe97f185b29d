// Every kind of frame (disparity map, depth image, stereo pair) through a real server on
// loopback with the client library: the clouds equal the core pipeline's within the Draco bound,
// kinds mix on one stream, and malformed frames of each kind get errors naming the field.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <string>
#include <vector>

#include "cloudcast/client/client.h"
#include "cloudcast/client/config.h"
#include "cloudcast/client/opencv.h"
#include "cloudcast/core/frame_codec.h"
#include "cloudcast/core/pipeline.h"
#include "cloudcast/datasets/tsukuba.h"
#include "cloudcast/stereo/grey.h"
#include "cloudcast/stereo/matcher.h"
#include "stereo_stage.h"  // server/src
#include "support/client_fixture.h"
#include "support/server_fixture.h"
#include "support/stereo_support.h"
#include "support/test_support.h"

namespace cloudcast {
namespace {

using client::DepthFrame;
using client::DisparityFrame;
using client::Result;
using client::StereoFrame;
using testing::CloudsMatch;
using testing::CloudTolerance;

// A depth camera's frame: a floor and a wall from 2.5 m to 11 m with holes (0), in millimetres
// or metres, and a colour image.
struct DepthImage {
  std::vector<std::uint8_t> depth, colour;
  DepthView depth_view;
  ColorView colour_view;
  cv::Mat mat;  // the depth as a cv::Mat (CV_16UC1 or CV_32FC1), for encoded files
};

DepthImage MakeDepth(std::uint32_t w, std::uint32_t h, DepthEncoding e, unsigned seed) {
  std::mt19937 rng(seed);
  DepthImage f;
  f.mat = cv::Mat(static_cast<int>(h), static_cast<int>(w),
                  e == DepthEncoding::kU16 ? CV_16UC1 : CV_32FC1);
  for (std::uint32_t v = 0; v < h; ++v) {
    for (std::uint32_t u = 0; u < w; ++u) {
      const double metres = 2.5 + 8.5 * (h - 1 - v) / (h - 1) + 0.3 * std::sin(u * 0.1);
      const bool hole = rng() % 17 == 0;
      if (e == DepthEncoding::kU16) {
        f.mat.at<std::uint16_t>(v, u) = hole ? 0 : static_cast<std::uint16_t>(metres * 1000);
      } else {
        f.mat.at<float>(v, u) = hole ? std::nanf("") : static_cast<float>(metres);
      }
    }
  }
  f.depth.assign(f.mat.datastart, f.mat.dataend);
  f.colour.resize(std::size_t{w} * h * 3);
  for (std::size_t i = 0; i < f.colour.size(); ++i) f.colour[i] = static_cast<std::uint8_t>(rng());
  f.depth_view = DepthView{f.depth.data(), f.depth.size(), w, h, w * BytesPerPixel(e), e};
  f.colour_view = ColorView{f.colour.data(), f.colour.size(), w, h, w * 3u, ColorEncoding::kBGR8};
  return f;
}

PipelineOptions Options(std::uint32_t w, std::uint32_t h) {
  PipelineOptions o;
  o.camera.fx = 525;
  o.camera.fy = 525;
  o.camera.cx = w / 2.0 - 0.5;
  o.camera.cy = h / 2.0 - 0.5;
  o.voxel.SetLeaf(0.05f);
  return o;
}

PointCloud Reference(const PipelineOptions& o, const DepthView& depth, const ColorView& colour) {
  Pipeline pipeline;
  PointCloud cloud;
  EXPECT_TRUE(pipeline.Run(o, depth, colour, &cloud).ok());
  return cloud;
}

using FrameKindsTest = testing::SharedServerClientTest;

TEST_F(FrameKindsTest, GetInfoListsDepthEncodingsAndStereoMatchers) {
  absl::StatusOr<v1::ServerInfo> info = client_->GetInfo();
  ASSERT_TRUE(info.ok()) << info.status();
  ASSERT_EQ(info->depth_encodings_size(), 2);
  EXPECT_EQ(info->depth_encodings(0), v1::DEPTH_U16);
  EXPECT_EQ(info->depth_encodings(1), v1::DEPTH_F32);
  EXPECT_EQ(info->stereo_matchers_size(), 5);
  EXPECT_EQ(info->defaults().stereo().matcher(), v1::STEREO_MATCHER_SGM);
  EXPECT_EQ(info->defaults().stereo().num_disparities(), 128);
  EXPECT_FALSE(info->defaults().camera().has_depth_scale());  // REP 118's units by encoding
}

// Raw, compressed and encoded (PNG 16-bit, TIFF float) depth images, 16-bit millimetres and
// float metres: each cloud is the core pipeline's, within the bound the reply states.
TEST_F(FrameKindsTest, DepthFramesOfEveryUplinkEqualThePipeline) {
  const std::uint32_t w = 160, h = 120;
  const PipelineOptions options = Options(w, h);
  for (DepthEncoding e : {DepthEncoding::kU16, DepthEncoding::kF32}) {
    const DepthImage f = MakeDepth(w, h, e, 5);
    const PointCloud reference = Reference(options, f.depth_view, f.colour_view);
    ASSERT_GT(reference.size(), 500u);
    std::vector<std::uint8_t> file;
    ASSERT_TRUE(cv::imencode(e == DepthEncoding::kU16 ? ".png" : ".tiff", f.mat, file));
    const std::string encoded(file.begin(), file.end());
    const std::vector<std::pair<std::string, client::DepthInput>> uplinks = {
        {"raw", f.depth_view},
        {"compressed", client::Compressed(f.depth_view)},
        {"encoded", client::EncodedImage{encoded}}};
    for (const auto& [name, input] : uplinks) {
      SCOPED_TRACE(std::string(Name(e)) + " " + name);
      absl::StatusOr<Result> r =
          client_->Process(DepthFrame{input, f.colour_view}, client::MakeStreamConfig(options));
      ASSERT_TRUE(r.ok()) << r.status();
      EXPECT_EQ(r->reply.counts().pixels(), std::uint64_t{w} * h);
      EXPECT_EQ(r->reply.counts().after_voxel_grid(), reference.size());
      EXPECT_TRUE(CloudsMatch(reference, r->cloud,
                              CloudTolerance::DracoBound(r->reply.position_error_bound())));
    }
  }
}

// One stream, the kinds in turn: each reply is its own frame's cloud, in order.
TEST_F(FrameKindsTest, KindsMixOnOneStream) {
  const std::uint32_t w = 96, h = 72;
  const PipelineOptions options = Options(w, h);
  const DepthImage depth = MakeDepth(w, h, DepthEncoding::kU16, 9);
  std::mt19937 rng(4);
  testing::TestFrame disparity =
      testing::RandomFrame(rng, w, h, DisparityEncoding::kU8, ColorEncoding::kBGR8, 50, 200);
  // Every frame answered: the default (latest) would drop the frames sent while one is in work.
  v1::StreamConfig config = client::MakeStreamConfig(options);
  config.set_delivery(v1::DELIVERY_ALL);
  auto stream = client_->OpenStream(config);
  ASSERT_TRUE(stream.ok()) << stream.status();
  for (int i = 0; i < 4; ++i) {
    if (i % 2 == 0) {
      ASSERT_TRUE((*stream)->Send(DepthFrame{depth.depth_view, depth.colour_view}).ok());
    } else {
      ASSERT_TRUE((*stream)->Send(DisparityFrame{disparity.disparity, disparity.colour}).ok());
    }
  }
  Pipeline pipeline;
  for (int i = 0; i < 4; ++i) {
    Result r;
    ASSERT_TRUE((*stream)->Read(&r));
    ASSERT_TRUE(r.ok()) << r.status;
    PointCloud reference;
    if (i % 2 == 0) {
      ASSERT_TRUE(pipeline.Run(options, depth.depth_view, depth.colour_view, &reference).ok());
    } else {
      ASSERT_TRUE(pipeline.Run(options, disparity.disparity, disparity.colour, &reference).ok());
    }
    EXPECT_EQ(r.sequence, static_cast<std::uint64_t>(i));
    EXPECT_TRUE(
        CloudsMatch(reference, r.cloud, CloudTolerance::DracoBound(r.reply.position_error_bound())))
        << "frame " << i;
  }
  EXPECT_TRUE((*stream)->Finish().ok());
}

TEST_F(FrameKindsTest, BadDepthFramesGetErrorsNamingTheField) {
  const DepthImage f = MakeDepth(32, 24, DepthEncoding::kU16, 1);
  const DepthImage small = MakeDepth(16, 24, DepthEncoding::kU16, 1);
  struct Case {
    std::string name;
    v1::ProcessRequest request;
    absl::StatusCode code;
    std::string message_has;
  };
  std::vector<Case> cases;
  auto base = [&]() {
    v1::ProcessRequest r;
    EXPECT_TRUE(
        convert::ToProto(f.depth_view, "depth", r.mutable_frame()->mutable_depth()->mutable_raw())
            .ok());
    EXPECT_TRUE(
        convert::ToProto(f.colour_view, "colour", r.mutable_frame()->mutable_color()->mutable_raw())
            .ok());
    return r;
  };
  {
    Case c{"unspecified encoding", base(), absl::StatusCode::kInvalidArgument,
           "frame.depth.raw.encoding"};
    c.request.mutable_frame()->mutable_depth()->mutable_raw()->set_encoding(
        v1::DEPTH_ENCODING_UNSPECIFIED);
    cases.push_back(c);
  }
  {
    Case c{"short pixels", base(), absl::StatusCode::kInvalidArgument, "frame.depth.raw.pixels"};
    c.request.mutable_frame()->mutable_depth()->mutable_raw()->mutable_pixels()->resize(100);
    cases.push_back(c);
  }
  {
    Case c{"sizes differ", base(), absl::StatusCode::kInvalidArgument,
           "frame.color is 32x24 but frame.depth is 16x24"};
    EXPECT_TRUE(convert::ToProto(small.depth_view, "depth",
                                 c.request.mutable_frame()->mutable_depth()->mutable_raw())
                    .ok());
    cases.push_back(c);
  }
  {
    Case c{"jpeg depth", base(), absl::StatusCode::kInvalidArgument,
           "frame.depth.encoded is a JPEG"};
    cv::Mat grey(24, 32, CV_8UC1, cv::Scalar(9));
    std::vector<std::uint8_t> jpeg;
    ASSERT_TRUE(cv::imencode(".jpg", grey, jpeg));
    c.request.mutable_frame()->mutable_depth()->set_encoded(jpeg.data(), jpeg.size());
    cases.push_back(c);
  }
  {
    Case c{"8-bit png depth", base(), absl::StatusCode::kInvalidArgument,
           "a depth image must be 16-bit unsigned"};
    cv::Mat grey(24, 32, CV_8UC1, cv::Scalar(9));
    std::vector<std::uint8_t> png;
    ASSERT_TRUE(cv::imencode(".png", grey, png));
    c.request.mutable_frame()->mutable_depth()->set_encoded(png.data(), png.size());
    cases.push_back(c);
  }
  {
    Case c{"no geometry", base(), absl::StatusCode::kInvalidArgument,
           "frame.disparity is missing, and so are frame.depth and frame.right"};
    c.request.mutable_frame()->clear_depth();
    cases.push_back(c);
  }
  {
    Case c{"zero depth scale", base(), absl::StatusCode::kInvalidArgument,
           "config.camera.depth_scale"};
    c.request.mutable_config()->mutable_camera()->set_depth_scale(0);
    cases.push_back(c);
  }
  auto stub = testing::NewStub(shared_server());
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    grpc::ClientContext context;
    v1::CloudReply reply;
    const grpc::Status s = stub->Process(&context, c.request, &reply);
    EXPECT_EQ(static_cast<int>(s.error_code()), static_cast<int>(c.code)) << s.error_message();
    EXPECT_NE(s.error_message().find(c.message_has), std::string::npos) << s.error_message();
  }
}

// What the server computes for a stereo pair, here: grey, our matcher, the pipeline reading its
// output with the camera's scale set to the matcher's.
PointCloud StereoReference(const PipelineOptions& o, const StereoParams& params,
                           const ColorView& left, const ColorView& right,
                           stereo::DisparityMap16* disparity = nullptr) {
  stereo::GreyImage gl, gr;
  EXPECT_TRUE(stereo::ToGrey(left, &gl).ok());
  EXPECT_TRUE(stereo::ToGrey(right, &gr).ok());
  auto matcher = stereo::MakeMatcher(params);
  EXPECT_TRUE(matcher.ok()) << matcher.status();
  stereo::DisparityMap16 map;
  EXPECT_TRUE((*matcher)->Compute(gl.view(), gr.view(), &map).ok());
  PipelineOptions matched = o;
  matched.camera = stereo::ForMatcherOutput(o.camera);
  Pipeline pipeline;
  PointCloud cloud;
  EXPECT_TRUE(pipeline.Run(matched, map.view(), left, &cloud).ok());
  if (disparity != nullptr) *disparity = std::move(map);
  return cloud;
}

// A New Tsukuba pair (the paper's camera: f = 615, baseline 10 cm; z in metres), every matcher:
// the cloud is what the matcher and the pipeline give here, and the disparity map comes back on
// request, exactly.
TEST_F(FrameKindsTest, StereoPairsAreMatchedByEveryMatcher) {
  auto frame = tsukuba::LoadStereo(tsukuba::DefaultDir(), "00001");
  if (!frame.ok()) GTEST_SKIP() << "New Tsukuba data not found: " << frame.status();
  PipelineOptions options;
  options.camera = CameraModel::PclCompatible(640, 480, 615);
  options.camera.baseline = 0.1;
  options.passthrough.min = 0.3f;  // z = 61.5 / d: 0.42 to 0.8 m
  options.passthrough.max = 1.2f;
  options.voxel.SetLeaf(0.005f);
  for (StereoMatcher m : AllStereoMatchers()) {
    SCOPED_TRACE(std::string(Name(m)));
    StereoParams params;
    params.matcher = m;
    if (m == StereoMatcher::kOpenCvBm) params.block_size = 15;
    params.return_disparity = m == StereoMatcher::kSgm;
    v1::StreamConfig config = client::MakeStreamConfig(options);
    convert::SetStereo(params, &config);
    absl::StatusOr<Result> r =
        client_->Process(StereoFrame{frame->left.view(), frame->right.view()}, config);
    ASSERT_TRUE(r.ok()) << r.status();
    stereo::DisparityMap16 disparity;
    const PointCloud reference =
        StereoReference(options, params, frame->left.view(), frame->right.view(), &disparity);
    EXPECT_GT(reference.size(), 2000u);
    EXPECT_EQ(r->reply.counts().after_voxel_grid(), reference.size());
    EXPECT_TRUE(CloudsMatch(reference, r->cloud,
                            CloudTolerance::DracoBound(r->reply.position_error_bound())));
    EXPECT_GT(r->reply.times().match_us(), 0u);
    EXPECT_EQ(r->reply.times().rectify_us(), 0u);
    if (params.return_disparity) {
      ASSERT_TRUE(r->reply.has_disparity());
      PlaneDecompressor decompressor;
      DisparityView back;
      ASSERT_TRUE(convert::DecodeCompressed(r->reply.disparity(), "disparity", Limits{},
                                            &decompressor, &back)
                      .ok());
      ASSERT_EQ(back.encoding, DisparityEncoding::kU16);
      ASSERT_EQ(back.size_bytes, disparity.values.size() * 2);
      EXPECT_EQ(std::memcmp(back.data, disparity.values.data(), back.size_bytes), 0);
    } else {
      EXPECT_FALSE(r->reply.has_disparity());
    }
  }
}

// A pair sent with its calibration (identity rotation, the baseline along x, no distortion): the
// server rectifies it (a remap that keeps it as it is, up to interpolation) and matches it with
// the rectified camera, which replaces the stream's.
TEST_F(FrameKindsTest, CalibratedPairsAreRectifiedAndMatchedWithTheRectifiedCamera) {
  const testing::SyntheticPair pair = testing::ShiftedPair(160, 120, {12.0, 20.0}, 7);
  PipelineOptions options;
  options.camera.fx = 1;  // replaced by the calibration's
  options.passthrough.enabled = false;
  options.voxel.enabled = false;
  StereoParams params;
  params.num_disparities = 32;
  params.has_calibration = true;
  StereoCalibration& k = params.calibration;
  k.width = 160;
  k.height = 120;
  k.left_k = k.right_k = {200, 0, 80, 0, 200, 60, 0, 0, 1};
  k.r = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  k.t = {-0.2, 0, 0};
  v1::StreamConfig config = client::MakeStreamConfig(options);
  convert::SetStereo(params, &config);
  auto stream = client_->OpenStream(config);
  ASSERT_TRUE(stream.ok()) << stream.status();
  for (int i = 0; i < 3; ++i) {
    ASSERT_TRUE((*stream)->Send(StereoFrame{pair.left.view(), pair.right.view()}).ok());
    Result r;
    ASSERT_TRUE((*stream)->Read(&r));
    ASSERT_TRUE(r.ok()) << r.status;
    EXPECT_GT(r.reply.times().rectify_us(), 0u);
    ASSERT_GT(r.cloud.size(), 10000u);
    // z = f B / d with the calibration's f = 200 and B = 0.2: 40 / 12 and 40 / 20 m.
    std::size_t near_truth = 0;
    for (const Point& p : r.cloud.points) {
      near_truth += std::fabs(p.z - 40.0f / 12) < 0.05f || std::fabs(p.z - 2.0f) < 0.05f;
    }
    EXPECT_GT(near_truth, r.cloud.size() * 9 / 10);
  }
  EXPECT_TRUE((*stream)->Finish().ok());
}

TEST_F(FrameKindsTest, BadStereoFramesAndConfigsGetErrorsNamingTheField) {
  const testing::SyntheticPair pair = testing::ShiftedPair(64, 48, {8.0}, 3);
  const testing::SyntheticPair small = testing::ShiftedPair(32, 48, {8.0}, 3);
  auto process = [&](const client::FrameInput& input, const StereoParams& params,
                     const PipelineOptions& options = PipelineOptions{}) {
    v1::StreamConfig config = client::MakeStreamConfig(options);
    convert::SetStereo(params, &config);
    return client_->Process(input, config).status();
  };
  StereoParams ok;
  ok.num_disparities = 16;
  struct Case {
    std::string name;
    absl::Status status;
    absl::StatusCode code;
    std::string message_has;
  };
  StereoParams too_many = ok;
  too_many.num_disparities = 100;
  StereoParams bad_block = ok;
  bad_block.block_size = 9;
  StereoParams bad_p2 = ok;
  bad_p2.p2 = 40;
  StereoParams bad_rotation = ok;
  bad_rotation.has_calibration = true;
  bad_rotation.calibration.width = 64;
  bad_rotation.calibration.height = 48;
  bad_rotation.calibration.left_k =
      bad_rotation.calibration.right_k = {100, 0, 32, 0, 100, 24, 0, 0, 1};
  bad_rotation.calibration.r = {2, 0, 0, 0, 1, 0, 0, 0, 1};
  bad_rotation.calibration.t = {-0.1, 0, 0};
  StereoParams wrong_size = bad_rotation;
  wrong_size.calibration.r = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  wrong_size.calibration.width = 80;
  StereoParams huge = ok;
  huge.num_disparities = 512;
  const testing::SyntheticPair big = testing::ShiftedPair(640, 480, {8.0}, 3);
  const StereoFrame good{pair.left.view(), pair.right.view()};
  const std::vector<Case> cases = {
      {"right of another size", process(StereoFrame{pair.left.view(), small.right.view()}, ok),
       absl::StatusCode::kInvalidArgument, "frame.right is 32x48 but frame.color is 64x48"},
      {"num_disparities", process(good, too_many), absl::StatusCode::kInvalidArgument,
       "config.stereo.num_disparities is 100; it must be a positive multiple of 16"},
      {"block_size", process(good, bad_block), absl::StatusCode::kInvalidArgument,
       "config.stereo.block_size is 9"},
      {"p2", process(good, bad_p2), absl::StatusCode::kInvalidArgument, "config.stereo.p2"},
      {"rotation", process(good, bad_rotation), absl::StatusCode::kInvalidArgument,
       "config.stereo.calibration.r is not a rotation"},
      {"calibration size", process(good, wrong_size), absl::StatusCode::kInvalidArgument,
       "config.stereo.calibration is for 80x48 images"},
      {"volume", process(StereoFrame{big.left.view(), big.right.view()}, huge),
       absl::StatusCode::kResourceExhausted, "ServerLimits.max_stereo_volume"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    EXPECT_EQ(c.status.code(), c.code) << c.status;
    EXPECT_NE(c.status.message().find(c.message_has), std::string::npos) << c.status;
  }
}

// Maps are built once per calibration and shared: the same rectifier comes back until the
// calibration falls out of the few most recently used.
TEST(RectifierCacheTest, BuildsOncePerCalibrationAndKeepsTheMostRecent) {
  server::RectifierCache cache(2);
  auto calibration = [](double baseline) {
    StereoCalibration k;
    k.width = 64;
    k.height = 48;
    k.left_k = k.right_k = {100, 0, 32, 0, 100, 24, 0, 0, 1};
    k.r = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    k.t = {-baseline, 0, 0};
    return k;
  };
  auto a = cache.Get(calibration(0.1));
  ASSERT_TRUE(a.ok()) << a.status();
  auto again = cache.Get(calibration(0.1));
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(a->get(), again->get());
  ASSERT_TRUE(cache.Get(calibration(0.2)).ok());
  ASSERT_TRUE(cache.Get(calibration(0.3)).ok());  // evicts 0.1, the least recently used
  EXPECT_EQ(cache.size(), 2u);
  auto rebuilt = cache.Get(calibration(0.1));
  ASSERT_TRUE(rebuilt.ok());
  EXPECT_NE(rebuilt->get(), a->get());
  EXPECT_NEAR((*rebuilt)->camera().baseline, 0.1, 1e-9);
}

TEST(FrameKindsMatTest, DepthAndStereoMatsBecomeFramesOrNameWhatIsWrong) {
  cv::Mat mm(4, 6, CV_16UC1, cv::Scalar(1500)), metres(4, 6, CV_32FC1, cv::Scalar(1.5));
  cv::Mat bgr(4, 6, CV_8UC3, cv::Scalar(1, 2, 3)), grey(4, 6, CV_8UC1, cv::Scalar(7));
  auto d = client::DepthFromMat(mm);
  ASSERT_TRUE(d.ok()) << d.status();
  EXPECT_EQ(std::get<DepthView>(*d).encoding, DepthEncoding::kU16);
  EXPECT_EQ(std::get<DepthView>(*d).stride_bytes, 12u);
  auto f = client::DepthFromMat(metres);
  ASSERT_TRUE(f.ok());
  EXPECT_EQ(std::get<DepthView>(*f).encoding, DepthEncoding::kF32);
  const absl::Status bad = client::DepthFromMat(grey).status();
  EXPECT_NE(bad.message().find("depth Mat has type CV_8UC1"), std::string::npos) << bad;
  auto frame = client::DepthFrameFromMats(mm, bgr);
  ASSERT_TRUE(frame.ok());
  EXPECT_TRUE(std::holds_alternative<DepthFrame>(*frame));
  auto pair = client::StereoFrameFromMats(grey, bgr);
  ASSERT_TRUE(pair.ok());
  EXPECT_TRUE(std::holds_alternative<client::StereoFrame>(*pair));
  const absl::Status bad_right = client::StereoFrameFromMats(grey, metres).status();
  EXPECT_NE(bad_right.message().find("right Mat has type CV_32FC1"), std::string::npos)
      << bad_right;
}

}  // namespace
}  // namespace cloudcast
