// The bridge's conversions, without a master: DisparityImage + CameraInfo to the camera model,
// the invalid-disparity mask, colour views, depth images and stereo pairs to frames, the server's
// disparity map back to a DisparityImage, the PointCloud2 layout, the stream config, the
// diagnostics and the --help text. The node against a real master: ros_bridge_test.py,
// ros_depth_test.py and ros_stereo_test.py.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "bridge_options.h"
#include "cloud_link.h"
#include "cloudcast/proto/convert.h"
#include "depth_input.h"
#include "diagnostics_msg.h"
#include "disparity_input.h"
#include "disparity_output.h"
#include "point_cloud2.h"
#include "ros_params.h"
#include "stereo_input.h"
#ifdef CLOUDCAST_BRIDGE_VIDEO
#include "cloudcast/video/frame_encoder.h"  // ToFrameEncoderOptions's result
#include "cloudcast/video/h264_settings.h"
#endif

namespace cloudcast::ros_bridge {
namespace {

sensor_msgs::CameraInfo TsukubaInfo() {
  sensor_msgs::CameraInfo info;
  info.width = 4;
  info.height = 2;
  info.P = {615, 0, 320, 0, 0, 610, 240, 0, 0, 0, 1, 0};
  return info;
}

// A 4x2 disparity image with these values, rows `step` bytes apart (step >= 16).
stereo_msgs::DisparityImage Disparity(const std::vector<float>& values, std::uint32_t step = 16,
                                      float min_disparity = 4) {
  stereo_msgs::DisparityImage d;
  d.f = 615;
  d.T = 0.1f;
  d.min_disparity = min_disparity;
  d.max_disparity = 255;
  d.image.width = 4;
  d.image.height = 2;
  d.image.encoding = "32FC1";
  d.image.step = step;
  d.image.data.assign(step * 2, 0xEE);
  for (int v = 0; v < 2; ++v) {
    std::memcpy(d.image.data.data() + v * step, values.data() + v * 4, 4 * sizeof(float));
  }
  return d;
}

TEST(CameraFromDisparity, TakesPrincipalPointAndFocalsFromPAndDepthFromFAndT) {
  auto camera = CameraFromDisparity(Disparity(std::vector<float>(8, 10)), TsukubaInfo());
  ASSERT_TRUE(camera.ok()) << camera.status();
  EXPECT_EQ(camera->fx, 615);
  EXPECT_EQ(camera->fy, 610);
  EXPECT_EQ(camera->cx, 320);
  EXPECT_EQ(camera->cy, 240);
  // z = fx * baseline / d = f T / d.
  EXPECT_NEAR(camera->fx * camera->baseline, 615 * 0.1, 1e-5);
  EXPECT_EQ(camera->disparity_scale, 1);
  EXPECT_EQ(camera->disparity_offset, 0);
  EXPECT_TRUE(camera->invalid_disparities.empty());
}

TEST(CameraFromDisparity, KeepsZEqualToFTOverDWhenFDiffersFromPsFx) {
  auto d = Disparity(std::vector<float>(8, 10));
  d.f = 600;  // stereo_image_proc writes the right camera's fx here
  auto camera = CameraFromDisparity(d, TsukubaInfo());
  ASSERT_TRUE(camera.ok()) << camera.status();
  EXPECT_NEAR(camera->fx * camera->baseline, 600 * 0.1, 1e-5);
}

TEST(CameraFromDisparity, ErrorsNameTheField) {
  const auto d = Disparity(std::vector<float>(8, 10));
  const std::map<std::string,
                 std::function<void(stereo_msgs::DisparityImage*, sensor_msgs::CameraInfo*)>>
      cases = {
          {"left/camera_info.P is all zero", [](auto*, auto* i) { i->P = {}; }},
          {"disparity.T is -0.1", [](auto* d, auto*) { d->T = -0.1f; }},
          {"disparity.f is 0", [](auto* d, auto*) { d->f = 0; }},
          {"left/camera_info is 8x2 but disparity.image is 4x2",
           [](auto*, auto* i) { i->width = 8; }},
          {"binning and regions of interest are not supported",
           [](auto*, auto* i) { i->binning_x = 2; }},
      };
  for (const auto& [message, mutate] : cases) {
    auto dd = d;
    auto info = TsukubaInfo();
    mutate(&dd, &info);
    auto camera = CameraFromDisparity(dd, info);
    ASSERT_FALSE(camera.ok()) << message;
    EXPECT_EQ(camera.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_NE(camera.status().message().find(message), std::string::npos)
        << camera.status().message();
  }
}

TEST(MaskedDisparity, BelowMinDisparityNanAndInfinityBecomeNan) {
  const float inf = std::numeric_limits<float>::infinity();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  // Rows 19 bytes apart: not float-aligned, as a ROS message may lay them out.
  auto d = Disparity({3, 4, 77.5f, nan, inf, -inf, 0, 146}, 19);
  std::vector<float> buffer;
  auto view = MaskedDisparity(d, &buffer);
  ASSERT_TRUE(view.ok()) << view.status();
  EXPECT_EQ(view->encoding, DisparityEncoding::kF32);
  EXPECT_EQ(view->stride_bytes, 16u);
  ASSERT_EQ(buffer.size(), 8u);
  EXPECT_TRUE(std::isnan(buffer[0]));  // 3 = min_disparity - 1: stereo_image_proc's invalid
  EXPECT_EQ(buffer[1], 4);             // min_disparity itself is valid (the message's rule)
  EXPECT_EQ(buffer[2], 77.5f);
  for (int i : {3, 4, 5, 6}) EXPECT_TRUE(std::isnan(buffer[i])) << i;
  EXPECT_EQ(buffer[7], 146);
}

TEST(MaskedDisparity, NonPositiveMinDisparityKeepsZeroForTheServerToDrop) {
  auto d = Disparity({-1, 0, 1, 2, 3, 4, 5, 6}, 16, /*min_disparity=*/0);
  std::vector<float> buffer;
  ASSERT_TRUE(MaskedDisparity(d, &buffer).ok());
  EXPECT_TRUE(std::isnan(buffer[0]));
  EXPECT_EQ(buffer[1], 0);  // d' <= 0: no point, by cloudcast's camera model
}

TEST(MaskedDisparity, RefusesOtherEncodingsAndShortData) {
  std::vector<float> buffer;
  auto d = Disparity(std::vector<float>(8, 10));
  d.image.encoding = "16UC1";
  auto v = MaskedDisparity(d, &buffer);
  ASSERT_FALSE(v.ok());
  EXPECT_NE(v.status().message().find("disparity.image.encoding is '16UC1'; must be 32FC1"),
            std::string::npos);
  d = Disparity(std::vector<float>(8, 10));
  d.image.data.resize(20);
  v = MaskedDisparity(d, &buffer);
  ASSERT_FALSE(v.ok());
  EXPECT_NE(v.status().message().find("disparity.image.data holds 20 bytes"), std::string::npos)
      << v.status().message();
}

sensor_msgs::Image Colour(const std::string& encoding, std::uint32_t bytes_per_pixel) {
  sensor_msgs::Image image;
  image.width = 4;
  image.height = 2;
  image.encoding = encoding;
  image.step = 4 * bytes_per_pixel;
  image.data.assign(image.step * 2, 7);
  return image;
}

TEST(ColourFromImage, MapsTheEightBitEncodings) {
  const std::pair<const char*, ColorEncoding> encodings[] = {{"rgb8", ColorEncoding::kRGB8},
                                                             {"bgr8", ColorEncoding::kBGR8},
                                                             {"rgba8", ColorEncoding::kRGBA8},
                                                             {"mono8", ColorEncoding::kMono8}};
  for (const auto& [name, encoding] : encodings) {
    const auto image = Colour(name, BytesPerPixel(encoding));
    auto input = ColourFromImage(image, "left/image_rect_color");
    ASSERT_TRUE(input.ok()) << name << ": " << input.status();
    const auto* view = std::get_if<ColorView>(&*input);
    ASSERT_NE(view, nullptr) << name;
    EXPECT_EQ(view->encoding, encoding);
    EXPECT_EQ(view->data, image.data.data());
    EXPECT_EQ(view->stride_bytes, image.step);
  }
  const auto bgra = Colour("bgra8", 4);
  auto input = ColourFromImage(bgra, "left/image_rect_color");
  ASSERT_TRUE(input.ok());
  EXPECT_NE(std::get_if<client::BgraView>(&*input), nullptr);
}

TEST(ColourFromImage, RefusesOtherEncodingsNamingTheTopic) {
  auto input = ColourFromImage(Colour("yuv422", 2), "left/image_rect_color");
  ASSERT_FALSE(input.ok());
  EXPECT_EQ(input.status().message(),
            "left/image_rect_color.encoding is 'yuv422'; the bridge takes rgb8, bgr8, rgba8, "
            "bgra8 or mono8");
}

TEST(ToFrame, RefusesAColourImageOfAnotherSize) {
  auto colour = Colour("bgr8", 3);
  colour.width = 2;
  colour.step = 6;
  std::vector<float> buffer;
  OutgoingFrame frame;
  auto s = ToFrame(Disparity(std::vector<float>(8, 10)), colour, TsukubaInfo(), &buffer, &frame);
  EXPECT_EQ(s.message(),
            "left/image_rect_color is 2x2 but disparity.image is 4x2; they must be the same size");
}

TEST(ToFrame, KeepsTheDisparitysHeader) {
  auto d = Disparity(std::vector<float>(8, 10));
  d.header.frame_id = "left_optical";
  d.header.stamp = ros::Time(1234, 5678);
  std::vector<float> buffer;
  OutgoingFrame frame;
  ASSERT_TRUE(ToFrame(d, Colour("rgb8", 3), TsukubaInfo(), &buffer, &frame).ok());
  EXPECT_EQ(frame.header.frame_id, "left_optical");
  EXPECT_EQ(ToRos(frame.header).stamp, ros::Time(1234, 5678));
  const auto* images = std::get_if<client::DisparityFrame>(&frame.images);
  ASSERT_NE(images, nullptr);
  EXPECT_NE(std::get_if<DisparityView>(&images->disparity), nullptr);
}

// A 4x2 depth image of `encoding` ("16UC1" or "32FC1") with these values, rows `step` apart.
template <typename T>
sensor_msgs::Image Depth(const std::string& encoding, const std::vector<T>& values,
                         std::uint32_t step = 4 * sizeof(T)) {
  sensor_msgs::Image d;
  d.width = 4;
  d.height = 2;
  d.encoding = encoding;
  d.step = step;
  d.header.frame_id = "rgb_optical";
  d.data.assign(step * 2, 0xEE);
  for (int v = 0; v < 2; ++v) {
    std::memcpy(d.data.data() + v * step, values.data() + v * 4, 4 * sizeof(T));
  }
  return d;
}

TEST(CameraFromDepth, TakesPLikeImageGeometryAndKWhenPIsZero) {
  const auto depth = Depth<std::uint16_t>("16UC1", std::vector<std::uint16_t>(8, 1000));
  auto info = TsukubaInfo();
  info.K = {600, 0, 319.5, 0, 601, 239.5, 0, 0, 1};
  auto camera = CameraFromDepth(depth, info, std::nullopt);
  ASSERT_TRUE(camera.ok()) << camera.status();
  EXPECT_EQ(camera->fx, 615);  // P, as depth_image_proc's image_geometry model reads it
  EXPECT_EQ(camera->fy, 610);
  EXPECT_EQ(camera->cx, 320);
  EXPECT_FALSE(camera->depth_scale.has_value());  // REP 118's, resolved by the server
  info.P = {};
  camera = CameraFromDepth(depth, info, 0.002);
  ASSERT_TRUE(camera.ok()) << camera.status();
  EXPECT_EQ(camera->fx, 600);
  EXPECT_EQ(camera->fy, 601);
  EXPECT_EQ(camera->cx, 319.5);
  EXPECT_EQ(camera->cy, 239.5);
  EXPECT_EQ(camera->depth_scale, 0.002);
  info.K = {};
  camera = CameraFromDepth(depth, info, std::nullopt);
  ASSERT_FALSE(camera.ok());
  EXPECT_EQ(camera.status().message(),
            "rgb/camera_info.P and K are all zero: the camera is not calibrated");
}

TEST(CameraFromDepth, RefusesACameraInfoOfAnotherSize) {
  auto info = TsukubaInfo();
  info.width = 640;
  info.height = 480;
  auto camera = CameraFromDepth(Depth<float>("32FC1", std::vector<float>(8, 1)), info, {});
  ASSERT_FALSE(camera.ok());
  EXPECT_EQ(camera.status().message(),
            "rgb/camera_info is 640x480 but depth_registered/image_rect is 4x2; they must describe "
            "the same pixels");
}

TEST(DepthFromImage, ViewsTheMessagesPixelsWithoutACopy) {
  // Rows 11 bytes apart: not 2-byte aligned, as a ROS message may lay them out.
  const auto u16 = Depth<std::uint16_t>("16UC1", {0, 1, 2, 3, 4, 5, 6, 7}, 11);
  auto view = DepthFromImage(u16);
  ASSERT_TRUE(view.ok()) << view.status();
  EXPECT_EQ(view->encoding, DepthEncoding::kU16);
  EXPECT_EQ(view->data, u16.data.data());
  EXPECT_EQ(view->stride_bytes, 11u);
  EXPECT_EQ(view->size_bytes, 22u);
  const auto f32 = Depth<float>("32FC1", std::vector<float>(8, 1.5f));
  view = DepthFromImage(f32);
  ASSERT_TRUE(view.ok()) << view.status();
  EXPECT_EQ(view->encoding, DepthEncoding::kF32);
}

TEST(DepthFromImage, ErrorsNameTheField) {
  auto d = Depth<std::uint16_t>("mono16", std::vector<std::uint16_t>(8, 1));
  auto view = DepthFromImage(d);
  ASSERT_FALSE(view.ok());
  EXPECT_EQ(view.status().message(),
            "depth_registered/image_rect.encoding is 'mono16'; must be 16UC1 (millimetres) or "
            "32FC1 (metres), REP 118");
  d.encoding = "16UC1";
  d.is_bigendian = 1;
  view = DepthFromImage(d);
  ASSERT_FALSE(view.ok());
  EXPECT_NE(view.status().message().find("depth_registered/image_rect.is_bigendian is 1"),
            std::string::npos);
  d.is_bigendian = 0;
  d.step = 6;
  view = DepthFromImage(d);
  ASSERT_FALSE(view.ok());
  EXPECT_EQ(view.status().message(),
            "depth_registered/image_rect.step is 6, less than width x 2 = 8");
}

TEST(ToDepthFrame, MakesADepthFrameWithTheDepthsHeader) {
  auto depth = Depth<float>("32FC1", std::vector<float>(8, 2));
  depth.header.stamp = ros::Time(12, 34);
  auto colour = Colour("rgb8", 3);
  colour.header.frame_id = "rgb_optical";
  OutgoingFrame frame;
  ASSERT_TRUE(ToDepthFrame(depth, colour, TsukubaInfo(), 1.0, &frame).ok());
  EXPECT_EQ(ToRos(frame.header).stamp, ros::Time(12, 34));
  EXPECT_EQ(frame.camera.depth_scale, 1.0);
  const auto* images = std::get_if<client::DepthFrame>(&frame.images);
  ASSERT_NE(images, nullptr);
  const auto* view = std::get_if<DepthView>(&images->depth);
  ASSERT_NE(view, nullptr);
  EXPECT_EQ(view->data, depth.data.data());
  EXPECT_NE(std::get_if<ColorView>(&images->colour), nullptr);
}

TEST(ToDepthFrame, RefusesAnotherFrameIdOrSize) {
  const auto depth = Depth<float>("32FC1", std::vector<float>(8, 2));
  auto colour = Colour("bgr8", 3);
  colour.header.frame_id = "depth_optical";
  OutgoingFrame frame;
  EXPECT_EQ(ToDepthFrame(depth, colour, TsukubaInfo(), {}, &frame).message(),
            "rgb/image_rect_color.header.frame_id is 'depth_optical' but "
            "depth_registered/image_rect's is 'rgb_optical'; the depth image must be registered "
            "to the colour camera");
  colour.header.frame_id = "rgb_optical";
  colour.height = 1;
  EXPECT_EQ(ToDepthFrame(depth, colour, TsukubaInfo(), {}, &frame).message(),
            "rgb/image_rect_color is 4x1 but depth_registered/image_rect is 4x2; they must be the "
            "same size");
}

sensor_msgs::CameraInfo RightInfo(double tx) {
  auto info = TsukubaInfo();
  info.P[3] = tx;
  return info;
}

TEST(CameraFromStereo, TakesTheBaselineFromTheRightP) {
  auto camera = CameraFromStereo(TsukubaInfo(), RightInfo(-615 * 0.1), 4, 2);
  ASSERT_TRUE(camera.ok()) << camera.status();
  EXPECT_EQ(camera->fx, 615);
  EXPECT_EQ(camera->fy, 610);
  EXPECT_EQ(camera->cx, 320);
  EXPECT_EQ(camera->cy, 240);
  EXPECT_DOUBLE_EQ(camera->baseline, 0.1);
  EXPECT_TRUE(camera->invalid_disparities.empty());
}

TEST(CameraFromStereo, ErrorsNameTheField) {
  auto camera = CameraFromStereo(TsukubaInfo(), RightInfo(0), 4, 2);
  ASSERT_FALSE(camera.ok());
  EXPECT_EQ(camera.status().message(),
            "right/camera_info.P[3] (Tx = -fx * baseline) is 0; must be finite and < 0 (the right "
            "camera of the pair)");
  auto right = RightInfo(-61.5);
  right.P[2] = 330;  // stereo_image_proc would shift the disparities by cx - cx'
  camera = CameraFromStereo(TsukubaInfo(), right, 4, 2);
  ASSERT_FALSE(camera.ok());
  EXPECT_NE(camera.status().message().find(
                "right/camera_info.P has cx = 330 but left/camera_info.P has 320"),
            std::string::npos)
      << camera.status().message();
  right = RightInfo(-61.5);
  right.P = {};
  camera = CameraFromStereo(TsukubaInfo(), right, 4, 2);
  ASSERT_FALSE(camera.ok());
  EXPECT_EQ(camera.status().message(),
            "right/camera_info.P is all zero: the camera is not calibrated");
}

TEST(ToStereoFrame, TakesAColourLeftAndAMonoRight) {
  auto left = Colour("bgr8", 3);
  left.header.frame_id = "left_optical";
  left.header.stamp = ros::Time(5, 6);
  const auto right = Colour("mono8", 1);
  OutgoingFrame frame;
  ASSERT_TRUE(ToStereoFrame(left, right, TsukubaInfo(), RightInfo(-61.5), &frame).ok());
  EXPECT_EQ(frame.header.frame_id, "left_optical");
  EXPECT_EQ(ToRos(frame.header).stamp, ros::Time(5, 6));
  const auto* images = std::get_if<client::StereoFrame>(&frame.images);
  ASSERT_NE(images, nullptr);
  EXPECT_EQ(std::get<ColorView>(images->left).encoding, ColorEncoding::kBGR8);
  EXPECT_EQ(std::get<ColorView>(images->right).encoding, ColorEncoding::kMono8);
  auto small = Colour("mono8", 1);
  small.width = 2;
  small.step = 2;
  EXPECT_EQ(ToStereoFrame(left, small, TsukubaInfo(), RightInfo(-61.5), &frame).message(),
            "right/image_rect is 2x2 but left/image_rect_color is 4x2; they must be the same size");
}

TEST(ToDisparityImage, IsStereoImageProcsMessageFromTheServersFixedPoint) {
  // The server's map: 1/16 pixels, 0 where nothing matched.
  const std::vector<std::uint16_t> raw = {0, 16, 24, 1234, 2336, 0, 17, 65535};
  DisparityView view;
  view.data = raw.data();
  view.size_bytes = raw.size() * 2;
  view.width = 4;
  view.height = 2;
  view.stride_bytes = 8;
  view.encoding = DisparityEncoding::kU16;
  v1::CompressedDisparity compressed;
  ASSERT_TRUE(convert::ToProto(view, convert::Compression{}, "test", &compressed).ok());
  std_msgs::Header header;
  header.frame_id = "left_optical";
  header.stamp = ros::Time(9, 10);
  CameraModel camera;
  camera.fx = 615;
  camera.baseline = 0.1;
  PlaneDecompressor decompressor;
  stereo_msgs::DisparityImage msg;
  ASSERT_TRUE(ToDisparityImage(compressed, header, camera, {4, 160}, &decompressor, &msg).ok());
  EXPECT_EQ(msg.header.frame_id, "left_optical");
  EXPECT_EQ(msg.image.header.stamp, ros::Time(9, 10));
  EXPECT_EQ(msg.f, 615.0f);
  EXPECT_EQ(msg.T, 0.1f);
  EXPECT_EQ(msg.min_disparity, 4.0f);
  EXPECT_EQ(msg.max_disparity, 163.0f);
  EXPECT_EQ(msg.delta_d, 1.0f / 16);
  EXPECT_EQ(msg.image.encoding, "32FC1");
  EXPECT_EQ(msg.image.step, 16u);
  ASSERT_EQ(msg.image.data.size(), 32u);
  std::vector<float> d(8);
  std::memcpy(d.data(), msg.image.data.data(), 32);
  const std::vector<float> expected = {3, 1, 1.5f, 77.125f, 146, 3, 1.0625f, 4095.9375f};
  EXPECT_EQ(d, expected);  // no match: min_disparity - 1, below the message's valid range
  // A map that is not the server's 16-bit one is refused, naming it.
  view.encoding = DisparityEncoding::kU8;
  view.stride_bytes = 4;
  ASSERT_TRUE(convert::ToProto(view, convert::Compression{}, "test", &compressed).ok());
  auto s = ToDisparityImage(compressed, header, camera, {4, 160}, &decompressor, &msg);
  EXPECT_NE(s.message().find("reply.disparity is u8"), std::string::npos) << s.message();
}

TEST(ToPointCloud2, IsCloudcastsPointWithPclsPackedRgbAndNoAlpha) {
  PointCloud cloud;
  cloud.ResizeUnorganized(2);
  cloud.points[0] = {1.5f, -2.0f, 3.25f, PackRgba(10, 20, 30)};
  cloud.points[1] = {0.0f, 0.5f, 8.0f, PackRgba(255, 0, 128)};
  std_msgs::Header header;
  header.frame_id = "cam";
  header.stamp = ros::Time(7, 8);
  sensor_msgs::PointCloud2 msg;
  ToPointCloud2(cloud, header, &msg);
  EXPECT_EQ(msg.header.frame_id, "cam");
  EXPECT_EQ(msg.header.stamp, ros::Time(7, 8));
  EXPECT_EQ(msg.height, 1u);
  EXPECT_EQ(msg.width, 2u);
  EXPECT_TRUE(msg.is_dense);
  EXPECT_EQ(msg.point_step, 16u);
  EXPECT_EQ(msg.row_step, 32u);
  ASSERT_EQ(msg.fields.size(), 4u);
  const char* names[] = {"x", "y", "z", "rgb"};
  for (int i = 0; i < 4; ++i) {
    EXPECT_EQ(msg.fields[i].name, names[i]);
    EXPECT_EQ(msg.fields[i].offset, 4u * i);
    EXPECT_EQ(msg.fields[i].datatype, sensor_msgs::PointField::FLOAT32);
    EXPECT_EQ(msg.fields[i].count, 1u);
  }
  ASSERT_EQ(msg.data.size(), 32u);
  float xyz[3];
  std::uint32_t rgb;
  std::memcpy(xyz, msg.data.data() + 16, 12);
  std::memcpy(&rgb, msg.data.data() + 28, 4);
  EXPECT_EQ(xyz[2], 8.0f);
  EXPECT_EQ(rgb, 0x00FF0080u);  // 0x00RRGGBB, as stereo_image_proc packs it
}

TEST(ConfigFor, AddsTheCameraToTheParameters) {
  client::StreamConfig base;
  base.mutable_voxel_grid()->set_leaf(0.05f);
  CameraModel camera;
  camera.fx = 500;
  camera.cx = 300.5;
  camera.baseline = 0.12;
  camera.invalid_disparities = {};
  const client::StreamConfig config = ConfigFor(base, camera);
  EXPECT_EQ(config.voxel_grid().leaf(), 0.05f);
  EXPECT_EQ(config.camera().fx(), 500);
  EXPECT_EQ(config.camera().cx(), 300.5);
  EXPECT_EQ(config.camera().baseline(), 0.12);
  ASSERT_TRUE(config.camera().has_invalid_disparities());
  EXPECT_EQ(config.camera().invalid_disparities().values_size(), 0);
  CameraModel other = camera;
  EXPECT_TRUE(SameCamera(camera, other));
  other.cy += 1;
  EXPECT_FALSE(SameCamera(camera, other));
  other = camera;
  other.depth_scale = 0.001;
  EXPECT_FALSE(SameCamera(camera, other));  // a new ~depth_scale reconfigures the stream
  EXPECT_EQ(ConfigFor(base, other).camera().depth_scale(), 0.001);
  EXPECT_FALSE(config.camera().has_depth_scale());
}

TEST(BridgeStats, ReportsTheReplysStageTimesAndCounters) {
  BridgeStats stats;
  stats.FrameIn();
  stats.Sent();
  client::Result r;
  r.reply.mutable_times()->set_decode_us(1000);
  r.reply.mutable_times()->set_rectify_us(300);
  r.reply.mutable_times()->set_match_us(20000);
  r.reply.mutable_times()->set_pipeline_us(2500);
  r.reply.mutable_times()->set_encode_us(500);
  r.reply.mutable_times()->set_queue_us(250);
  r.reply.set_point_count(1234);
  r.reply.set_position_error_bound(0.0075f);
  r.times.send = std::chrono::steady_clock::time_point(std::chrono::milliseconds(100));
  r.times.receive = std::chrono::steady_clock::time_point(std::chrono::milliseconds(112));
  stats.Reply(r);
  stats.StreamDropped(3);
  stats.Reconnected();
  stats.StreamClosed();
  stats.StreamDropped(2);
  auto array = ToDiagnosticArray(stats.Report(10.0, "bridge", "127.0.0.1:50051"), ros::Time(10, 0));
  ASSERT_EQ(array.status.size(), 1u);
  const auto& s = array.status[0];
  EXPECT_EQ(s.level, diagnostic_msgs::DiagnosticStatus::OK);
  EXPECT_EQ(s.hardware_id, "127.0.0.1:50051");
  std::map<std::string, std::string> v;
  for (const auto& kv : s.values) v[kv.key] = kv.value;
  EXPECT_EQ(v["decode_ms_mean"], "1.000");
  EXPECT_EQ(v["rectify_ms_mean"], "0.300");
  EXPECT_EQ(v["match_ms_mean"], "20.000");
  EXPECT_EQ(v["pipeline_ms_mean"], "2.500");
  EXPECT_EQ(v["encode_ms_mean"], "0.500");
  EXPECT_EQ(v["queue_ms_mean"], "0.250");
  EXPECT_EQ(v["round_trip_ms_mean"], "12.000");
  EXPECT_EQ(v["points_mean"], "1234");
  EXPECT_EQ(v["frames_dropped"], "5");  // 3 on the closed stream, 2 on the current one
  EXPECT_EQ(v["reconnects"], "1");
  EXPECT_EQ(v["clouds"], "1");
  // The next period starts anew; the failed send makes it an ERROR.
  stats.NotSent(absl::UnavailableError("no stream"));
  auto next = ToDiagnosticArray(stats.Report(11.0, "bridge", "x"), ros::Time(11, 0));
  EXPECT_EQ(next.status[0].level, diagnostic_msgs::DiagnosticStatus::ERROR);
  EXPECT_NE(next.status[0].message.find("no stream"), std::string::npos);
}

// The uplink's bytes (from the server's running count per stream), the quantization a downlink
// cap made the server choose, and the rate controller's estimate.
TEST(BridgeStats, ReportsTheUplinkTheCapsBitsAndTheRateTarget) {
  BridgeStats stats;
  (void)stats.Report(0.0, "bridge", "x");  // the first period starts at 0 s
  const auto reply = [&](std::uint64_t stream_bytes, int color_bits, bool over_cap) {
    client::Result r;
    r.reply.set_stream_bytes_received(stream_bytes);
    r.reply.set_position_bits(11);
    r.reply.set_color_bits(color_bits);
    if (over_cap) r.reply.mutable_over_cap()->set_max_cloud_bytes(1000);
    client::RateEstimate rate;
    rate.target_bps = 2.5e6;
    rate.rtt_ms = 40;
    r.rate = rate;
    stats.Sent();
    stats.Reply(r);
  };
  reply(10000, 8, false);
  reply(30000, 5, true);
  std::map<std::string, std::string> v;
  for (const auto& [key, value] : stats.Report(2.0, "bridge", "x").values) v[key] = value;
  EXPECT_EQ(v["uplink_bytes_per_cloud"], "15000");
  EXPECT_EQ(v["uplink_kbps"], "120");  // 30,000 bytes in 2 s
  EXPECT_EQ(v["position_bits"], "11");
  EXPECT_EQ(v["color_bits"], "5");
  EXPECT_EQ(v["replies_over_cap"], "1");
  EXPECT_EQ(v["target_kbps"], "2500");
  EXPECT_EQ(v["rtt_ms"], "40.000");
  // A new stream (after a lost one) counts from 0 again: all of its total is new.
  reply(4000, 8, false);
  v.clear();
  for (const auto& [key, value] : stats.Report(3.0, "bridge", "x").values) v[key] = value;
  EXPECT_EQ(v["uplink_bytes_per_cloud"], "4000");
  EXPECT_EQ(v["replies_over_cap"], "1");
  // Without rate control no estimate is reported.
  BridgeStats plain;
  client::Result r;
  plain.Reply(r);
  v.clear();
  for (const auto& [key, value] : plain.Report(1.0, "bridge", "x").values) v[key] = value;
  EXPECT_EQ(v.count("target_kbps"), 0u);
}

// ~encoding jpeg: the coder's last quality and resolution after a reply, and the clouds made from
// half-resolution frames; nothing of it without the coder.
TEST(BridgeStats, ReportsTheJpegCodersQualityAndHalfResolution) {
  BridgeStats stats;
  client::Result full;
  stats.Reply(full);
  stats.JpegCoded(55, false);
  client::Result half;
  half.resolution_divisor = 2;
  stats.Reply(half);
  stats.JpegCoded(10, true);
  std::map<std::string, std::string> v;
  for (const auto& [key, value] : stats.Report(1.0, "bridge", "x").values) v[key] = value;
  EXPECT_EQ(v["jpeg_quality"], "10");
  EXPECT_EQ(v["half_resolution"], "true");
  EXPECT_EQ(v["half_resolution_clouds"], "1");
  stats.Reply(full);
  stats.JpegCoded(40, false);
  v.clear();
  for (const auto& [key, value] : stats.Report(2.0, "bridge", "x").values) v[key] = value;
  EXPECT_EQ(v["jpeg_quality"], "40");
  EXPECT_EQ(v["half_resolution"], "false");
  EXPECT_EQ(v["half_resolution_clouds"], "1");  // a total, as clouds
  BridgeStats plain;
  plain.Reply(full);
  v.clear();
  for (const auto& [key, value] : plain.Report(1.0, "bridge", "x").values) v[key] = value;
  EXPECT_EQ(v.count("jpeg_quality"), 0u);
  EXPECT_EQ(v.count("half_resolution"), 0u);
}

// A refusal of the bridge's first call (a wrong token) is reported before any frame comes.
TEST(BridgeStats, ALinkDownFromTheStartIsAnErrorNamingWhy) {
  BridgeStats stats;
  stats.LinkDown(absl::UnauthenticatedError("the bearer token is not valid for this server"));
  auto array = ToDiagnosticArray(stats.Report(1.0, "bridge", "x"), ros::Time(1, 0));
  ASSERT_EQ(array.status.size(), 1u);
  EXPECT_EQ(array.status[0].level, diagnostic_msgs::DiagnosticStatus::ERROR);
  std::map<std::string, std::string> v;
  for (const auto& kv : array.status[0].values) v[kv.key] = kv.value;
  EXPECT_NE(v["last_error"].find("UNAUTHENTICATED"), std::string::npos) << v["last_error"];
  EXPECT_EQ(v["frames_not_sent"], "0");
}

TEST(HelpText, ListsEveryParameter) {
  const std::string help = HelpText();
  for (const ParamDoc& d : ParamDocs()) {
    EXPECT_NE(help.find("~" + d.name + " ("), std::string::npos) << d.name;
  }
  for (const char* topic : {"points2", "depth_registered/image_rect", "rgb/camera_info",
                            "right/image_rect", "right/camera_info", "DisparityImage"}) {
    EXPECT_NE(help.find(topic), std::string::npos) << topic;
  }
  EXPECT_NE(help.find("/diagnostics"), std::string::npos);
}


// ---- The uplink and downlink-cap parameters with ROS 1's spelling ("~name"), through a reader
// of a plain map (the node's reader needs a master; ros/tests/ros_bridge_test.py runs that one).

class MapParams : public ParamReader {
 public:
  struct Value {
    enum { kString, kBool, kInt, kDouble } type;
    std::string s;
    bool b = false;
    int i = 0;
    double d = 0;
  };
  std::map<std::string, Value> values;

  void Set(const std::string& name, const std::string& v) { values[name] = {Value::kString, v}; }
  void Set(const std::string& name, bool v) { values[name] = {Value::kBool, "", v}; }
  void Set(const std::string& name, int v) { values[name] = {Value::kInt, "", false, v}; }
  void Set(const std::string& name, double v) { values[name] = {Value::kDouble, "", false, 0, v}; }

  absl::StatusOr<std::optional<std::string>> String(const std::string& n) const override {
    auto it = values.find(n);
    if (it == values.end()) return std::optional<std::string>();
    if (it->second.type != Value::kString) return absl::InvalidArgumentError(Display(n) + " type");
    return std::optional<std::string>(it->second.s);
  }
  absl::StatusOr<std::optional<bool>> Bool(const std::string& n) const override {
    auto it = values.find(n);
    if (it == values.end()) return std::optional<bool>();
    if (it->second.type != Value::kBool) return absl::InvalidArgumentError(Display(n) + " type");
    return std::optional<bool>(it->second.b);
  }
  absl::StatusOr<std::optional<int>> Int(const std::string& n) const override {
    auto it = values.find(n);
    if (it == values.end()) return std::optional<int>();
    if (it->second.type != Value::kInt) return absl::InvalidArgumentError(Display(n) + " type");
    return std::optional<int>(it->second.i);
  }
  absl::StatusOr<std::optional<double>> Double(const std::string& n) const override {
    auto it = values.find(n);
    if (it == values.end()) return std::optional<double>();
    if (it->second.type == Value::kInt) return std::optional<double>(it->second.i);
    if (it->second.type != Value::kDouble) return absl::InvalidArgumentError(Display(n) + " type");
    return std::optional<double>(it->second.d);
  }
  std::vector<std::string> Names() const override {
    std::vector<std::string> out;
    for (const auto& [name, value] : values) out.push_back(name);
    return out;
  }
  std::string Display(const std::string& name) const override { return "~" + name; }
};

std::string ErrorOf(const MapParams& p) {
  auto o = ReadBridgeOptions(p, "cloudcast-ros-bridge");
  return o.ok() ? "(accepted)" : std::string(o.status().message());
}

TEST(BridgeParams, UplinkAndCapErrorsNameTheRos1Parameter) {
  MapParams p;
  p.Set("encoding", std::string("jpeg2000"));
  EXPECT_EQ(ErrorOf(p), "~encoding is 'jpeg2000'; must be raw, zstd, h264 or jpeg");
  p.values.clear();
  p.Set("h264/preset", std::string("ultrafast"));
  EXPECT_EQ(ErrorOf(p),
            "~h264/preset is set but ~encoding is 'raw'; it applies to ~encoding h264 only");
  p.values.clear();
  p.Set("encoding", std::string("raw"));
  p.Set("compress", true);
  EXPECT_EQ(ErrorOf(p),
            "~compress is true (the old name of ~encoding zstd) but ~encoding is 'raw'; drop "
            "~compress");
  p.values.clear();
  p.Set("draco/max_reply_kb", 0.05);
  EXPECT_EQ(ErrorOf(p).rfind("~draco/max_reply_kb is 0.05; it must be 0 (no cap)", 0), 0u)
      << ErrorOf(p);
  p.values.clear();
  p.Set("draco/max_reply_kb", 30.0);
  p.Set("draco/min_color_bits", 12);
  EXPECT_EQ(ErrorOf(p), "~draco/min_color_bits is 12; must be in 1..8");
  p.values.clear();
  p.Set("draco/cap_min_points", 2);
  EXPECT_EQ(ErrorOf(p),
            "~draco/cap_min_points needs ~draco/max_reply_kb or ~rate_control (a cap to meet)");
  p.Set("draco/max_reply_kb", 30.0);
  p.Set("draco/cap_min_points", 100);
  EXPECT_EQ(ErrorOf(p), "~draco/cap_min_points is 100; must be in 0..64");
  if (HasVideoEncoder()) {
    p.values.clear();
    p.Set("encoding", std::string("h264"));
    p.Set("h264/mbps", 2000.0);
    EXPECT_EQ(ErrorOf(p), "~h264/mbps is 2000; must be a bitrate in [0.05, 1000] Mbit/s");
    p.values.clear();
    p.Set("encoding", std::string("h264"));
    p.Set("h264/x264_params", std::string("partitions=all:rc-lookahead=20"));
    EXPECT_EQ(ErrorOf(p),
              "~h264/x264_params 'partitions=all:rc-lookahead=20': 'rc-lookahead' is the "
              "encoder's own (latency and rate control: the --h264-* settings)");
    p.Set("h264/x264_params", std::string("partitions=all::ref=4"));
    EXPECT_EQ(ErrorOf(p), "~h264/x264_params 'partitions=all::ref=4': an empty option "
                          "(key=value:key=value)");
    p.values.clear();
    p.Set("encoding", std::string("h264"));
    p.Set("h264/lossless", true);
    p.Set("h264/crf", 4.0);
    EXPECT_EQ(ErrorOf(p), "~h264/lossless is true but ~h264/crf is set; a lossless stream has no "
                          "quality or bitrate to set");
  }
}

#ifdef CLOUDCAST_BRIDGE_VIDEO
// h264/lossless and h264/x264_params reach the encoder: qp 0, the options after ours.
TEST(BridgeParams, LosslessH264AndX264OptionsReachTheEncoder) {
  MapParams p;
  p.Set("encoding", std::string("h264"));
  p.Set("h264/lossless", true);
  p.Set("h264/x264_params", std::string("partitions=all:ref=4"));
  auto o = ReadBridgeOptions(p, "cloudcast-ros-bridge");
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_TRUE(o->h264.lossless);
  const video::FrameEncoderOptions e = video::ToFrameEncoderOptions(o->h264, 30);
  EXPECT_EQ(e.encoder.qp, 0);
  EXPECT_EQ(e.encoder.crf, 0);
  EXPECT_EQ(e.encoder.x264_params, "partitions=all:ref=4");
}
#endif

TEST(BridgeParams, H264AndTheCapReachTheStream) {
  MapParams p;
  p.Set("compress", true);
  auto o = ReadBridgeOptions(p, "cloudcast-ros-bridge");
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_EQ(o->uplink, Uplink::kZstd);  // the old name
  if (!HasVideoEncoder()) GTEST_SKIP() << "this build has no video encoder";
  p.values.clear();
  p.Set("encoding", std::string("h264"));
  p.Set("h264/mbps", 3);  // an integer, as a launch file may write it
  p.Set("h264/grey", true);
  p.Set("rate_control", true);
  p.Set("draco/max_reply_kb", 30.0);
  p.Set("draco/cap_min_points", 2);
  o = ReadBridgeOptions(p, "cloudcast-ros-bridge");
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_EQ(o->config.draco().cap_min_points_per_voxel(), 2u);
  EXPECT_EQ(o->uplink, Uplink::kH264);
  EXPECT_EQ(o->h264.mbps, 3.0);
  EXPECT_TRUE(o->h264.grey);
  EXPECT_EQ(o->config.draco().max_cloud_bytes(), 30000u);
  EXPECT_EQ(o->config.delivery(), v1::DELIVERY_LATEST);
  auto so = StreamOptionsFor(*o, CameraModel{});
  ASSERT_TRUE(so.ok()) << so.status();
  EXPECT_NE(so->coder, nullptr);
  EXPECT_TRUE(so->rate_control.has_value());
  EXPECT_TRUE(so->resilient);
}

// rate/*: the rate controller's settings reach the stream, only with rate_control, each named
// when out of range.
TEST(BridgeParams, RateSettingsReachTheStreamsController) {
  MapParams p;
  p.Set("rate_control", true);
  p.Set("rate/target_delay_ms", 15.0);
  p.Set("rate/start_mbps", 2);  // an integer, as a launch file may write it
  p.Set("rate/max_mbps", 12.0);
  auto o = ReadBridgeOptions(p, "cloudcast-ros-bridge");
  ASSERT_TRUE(o.ok()) << o.status();
  auto so = StreamOptionsFor(*o, CameraModel{});
  ASSERT_TRUE(so.ok()) << so.status();
  ASSERT_TRUE(so->rate_control.has_value());
  EXPECT_EQ(so->rate_control->target_delay, std::chrono::milliseconds(15));
  EXPECT_EQ(so->rate_control->start_bps, 2e6);
  EXPECT_EQ(so->rate_control->max_bps, 12e6);
  EXPECT_EQ(so->rate_control->min_bps, client::RateControlOptions{}.min_bps);
  EXPECT_TRUE(so->rate_control->cap_replies);  // the replies follow the downlink by default
  p.Set("rate/reply_cap", false);
  auto off = ReadBridgeOptions(p, "cloudcast-ros-bridge");
  ASSERT_TRUE(off.ok()) << off.status();
  EXPECT_FALSE(StreamOptionsFor(*off, CameraModel{})->rate_control->cap_replies);

  p.values.clear();
  p.Set("rate/reply_cap", false);
  EXPECT_EQ(ErrorOf(p), "~rate/reply_cap needs ~rate_control true");
  p.values.clear();
  p.Set("rate/target_delay_ms", 15.0);
  EXPECT_EQ(ErrorOf(p), "~rate/target_delay_ms needs ~rate_control true");
  p.Set("rate_control", true);
  p.Set("rate/target_delay_ms", 0.0);
  EXPECT_EQ(ErrorOf(p), "~rate/target_delay_ms is 0; must be in [1, 1000] ms");
  p.values.clear();
  p.Set("rate_control", true);
  p.Set("rate/min_mbps", 5.0);
  p.Set("rate/max_mbps", 2.0);
  EXPECT_NE(ErrorOf(p).find("~rate/min_mbps <= ~rate/start_mbps <= ~rate/max_mbps must hold"),
            std::string::npos)
      << ErrorOf(p);
}

// ~encoding jpeg with ROS 1's spelling: the ~jpeg/* settings, each error naming the parameter, and
// the stream's coder (client::AdaptiveJpegCoder, cloudcast-client --encoding jpeg's).
TEST(BridgeParams, JpegSettingsAreNamedAndReachTheStreamsCoder) {
  MapParams p;
  p.Set("jpeg/quality", 80);
  EXPECT_EQ(ErrorOf(p),
            "~jpeg/quality is set but ~encoding is 'raw'; it applies to ~encoding jpeg only");
  if (!HasJpegEncoder()) {
    p.values.clear();
    p.Set("encoding", std::string("jpeg"));
    EXPECT_NE(ErrorOf(p).find("built without the JPEG coder"), std::string::npos);
    GTEST_SKIP() << "this build has no JPEG coder (OpenCV)";
  }
  p.values.clear();
  p.Set("encoding", std::string("jpeg"));
  p.Set("jpeg/min_quality", 20);
  EXPECT_EQ(ErrorOf(p),
            "~jpeg/min_quality needs ~rate_control true (without it every frame goes at "
            "~jpeg/quality)");
  p.values.clear();
  p.Set("encoding", std::string("jpeg"));
  p.Set("jpeg/half_resolution", false);
  EXPECT_EQ(ErrorOf(p), "~jpeg/half_resolution needs ~rate_control true");
  p.Set("rate_control", true);
  p.Set("jpeg/quality", 150);
  EXPECT_EQ(ErrorOf(p), "~jpeg/quality is 150; must be in 1..100");
  p.Set("jpeg/quality", 50);
  p.Set("jpeg/max_quality", 40);
  EXPECT_EQ(ErrorOf(p),
            "~jpeg/min_quality <= ~jpeg/quality <= ~jpeg/max_quality must hold with "
            "~rate_control; they are 10, 50, 40");
  p.values.erase("jpeg/max_quality");
  p.Set("jpeg/fps", 2000.0);
  EXPECT_EQ(ErrorOf(p), "~jpeg/fps is 2000; must be in [1, 1000] frames a second");
  p.Set("jpeg/fps", 15);  // an integer, as a launch file may write it

  auto o = ReadBridgeOptions(p, "cloudcast-ros-bridge");
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_EQ(o->uplink, Uplink::kJpeg);
  EXPECT_EQ(o->jpeg.quality, 50);
  EXPECT_FALSE(o->jpeg.half_resolution);
  EXPECT_EQ(o->jpeg.fps, 15.0);
  EXPECT_EQ(o->config.delivery(), v1::DELIVERY_LATEST);
  auto so = StreamOptionsFor(*o, CameraModel{});
  ASSERT_TRUE(so.ok()) << so.status();
  EXPECT_NE(so->coder, nullptr);
  EXPECT_TRUE(so->rate_control.has_value());

  // Without ~rate_control: fixed quality (~jpeg/quality), the coder without a controller.
  p.values.clear();
  p.Set("encoding", std::string("jpeg"));
  p.Set("jpeg/quality", 75);
  o = ReadBridgeOptions(p, "cloudcast-ros-bridge");
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_EQ(o->jpeg.quality, 75);
  so = StreamOptionsFor(*o, CameraModel{});
  ASSERT_TRUE(so.ok()) << so.status();
  EXPECT_NE(so->coder, nullptr);
  EXPECT_FALSE(so->rate_control.has_value());
}

}  // namespace
}  // namespace cloudcast::ros_bridge
