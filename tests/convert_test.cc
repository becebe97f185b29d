// The proto boundary (proto/convert): mappings both ways, resolution of a StreamConfig against
// defaults, frames to and from core views, and the errors it words.
#include "cloudcast/proto/convert.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace cloudcast::convert {
namespace {

using ::testing::HasSubstr;

TEST(ConvertTest, EnumsMapBothWays) {
  for (Axis a : {Axis::kX, Axis::kY, Axis::kZ}) {
    Axis back = Axis::kZ;
    ASSERT_TRUE(FromProto(ToProto(a), "axis", &back).ok());
    EXPECT_EQ(back, a);
  }
  for (DisparityEncoding e :
       {DisparityEncoding::kU8, DisparityEncoding::kU16, DisparityEncoding::kF32}) {
    DisparityEncoding back{};
    ASSERT_TRUE(FromProto(ToProto(e), "e", &back).ok());
    EXPECT_EQ(back, e);
  }
  for (ColorEncoding e : {ColorEncoding::kBGR8, ColorEncoding::kRGB8, ColorEncoding::kRGBA8,
                          ColorEncoding::kMono8}) {
    ColorEncoding back{};
    ASSERT_TRUE(FromProto(ToProto(e), "e", &back).ok());
    EXPECT_EQ(back, e);
  }
  for (Delivery d : {Delivery::kLatest, Delivery::kAll}) {
    Delivery back = d == Delivery::kAll ? Delivery::kLatest : Delivery::kAll;
    ASSERT_TRUE(FromProto(ToProto(d), "d", &back).ok());
    EXPECT_EQ(back, d);
    ASSERT_TRUE(ParseDelivery(Name(d), &back));
    EXPECT_EQ(back, d);
  }
  // UNSPECIFIED keeps the caller's default where the proto says so...
  Axis axis = Axis::kY;
  ASSERT_TRUE(FromProto(v1::AXIS_UNSPECIFIED, "axis", &axis).ok());
  EXPECT_EQ(axis, Axis::kY);
  // ...and is an error for image encodings, named with the field.
  DisparityEncoding e{};
  EXPECT_THAT(std::string(FromProto(v1::DISPARITY_ENCODING_UNSPECIFIED, "f.encoding", &e).message()),
              HasSubstr("f.encoding is DISPARITY_ENCODING_UNSPECIFIED"));
  EXPECT_THAT(std::string(FromProto(static_cast<v1::Axis>(9), "c.axis", &axis).message()),
              HasSubstr("c.axis is 9, not one of AXIS_X, AXIS_Y, AXIS_Z"));
}

TEST(ConvertTest, StreamConfigResolvesFieldByFieldAgainstTheDefaults) {
  StreamSettings defaults;
  defaults.frame.pipeline.voxel.SetLeaf(0.05f);
  v1::StreamConfig config;
  config.mutable_camera()->set_fx(700);
  auto s = Resolve(config, defaults);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->frame.pipeline.camera.fx, 700);
  EXPECT_EQ(s->frame.pipeline.camera.fy, 700);  // follows fx
  EXPECT_FALSE(s->frame.cx.has_value());
  EXPECT_EQ(s->frame.PipelineFor(641, 481).camera.cx, 320);  // integer division, as PCL
  EXPECT_EQ(s->frame.PipelineFor(641, 481).camera.cy, 240);
  EXPECT_FLOAT_EQ(s->frame.pipeline.voxel.leaf_x, 0.05f);
  EXPECT_FLOAT_EQ(s->frame.Draco().max_position_error, 0.05f / 4);
  EXPECT_EQ(s->delivery, Delivery::kLatest);

  config.mutable_voxel_grid()->set_leaf(0.2f);
  config.mutable_voxel_grid()->set_leaf_z(0.08f);
  config.mutable_camera()->mutable_invalid_disparities();  // set, empty: no invalid values
  s = Resolve(config, defaults);
  ASSERT_TRUE(s.ok());
  EXPECT_FLOAT_EQ(s->frame.pipeline.voxel.leaf_y, 0.2f);
  EXPECT_FLOAT_EQ(s->frame.pipeline.voxel.leaf_z, 0.08f);
  EXPECT_FLOAT_EQ(s->frame.Draco().max_position_error, 0.02f);  // a quarter of the smallest leaf
  EXPECT_TRUE(s->frame.pipeline.camera.invalid_disparities.empty());

  config.mutable_voxel_grid()->set_enabled(false);
  s = Resolve(config, defaults);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->frame.Draco().max_position_error, 0.0f);

  config.mutable_draco()->set_max_position_error(0.5f);
  config.mutable_camera()->set_cx(10);
  s = Resolve(config, defaults);
  ASSERT_TRUE(s.ok());
  EXPECT_FLOAT_EQ(s->frame.Draco().max_position_error, 0.5f);
  EXPECT_EQ(s->frame.PipelineFor(641, 481).camera.cx, 10);

  // A server with the grid off by default: a client that names a leaf turns it on.
  defaults.frame.pipeline.voxel.enabled = false;
  v1::StreamConfig with_leaf;
  with_leaf.mutable_voxel_grid()->set_leaf(0.1f);
  EXPECT_TRUE(Resolve(with_leaf, defaults)->frame.pipeline.voxel.enabled);
  EXPECT_FALSE(Resolve(v1::StreamConfig(), defaults)->frame.pipeline.voxel.enabled);
}

TEST(ConvertTest, ResolveNamesTheFieldTheClientSet) {
  const StreamSettings defaults;
  struct Case {
    std::function<void(v1::StreamConfig*)> spoil;
    std::string message;
  };
  const std::vector<Case> cases = {
      {[](v1::StreamConfig* c) { c->mutable_camera()->set_fy(-1); },
       "config.camera.fy must be finite and in (0, 1e9], got -1"},
      {[](v1::StreamConfig* c) { c->mutable_camera()->set_cx(INFINITY); }, "config.camera.cx"},
      {[](v1::StreamConfig* c) { c->mutable_camera()->set_disparity_scale(0); },
       "config.camera.disparity_scale must not be 0"},
      {[](v1::StreamConfig* c) {
         c->mutable_camera()->mutable_invalid_disparities()->add_values(NAN);
       },
       "config.camera.invalid_disparities.values[0] must be finite"},
      {[](v1::StreamConfig* c) { c->mutable_voxel_grid()->set_leaf(1e-40f); },
       "config.voxel_grid.leaf must be finite and > 0 (with 1/leaf a finite float)"},
      {[](v1::StreamConfig* c) { c->mutable_voxel_grid()->set_leaf_z(0); },
       "config.voxel_grid.leaf_z"},
      {[](v1::StreamConfig* c) { c->mutable_passthrough()->set_max(1); },
       "config.passthrough.min (3, the server default) must not exceed config.passthrough.max "
       "(1)"},
      {[](v1::StreamConfig* c) { c->mutable_draco()->set_decode_speed(-1); },
       "config.draco.decode_speed is -1; it must be in [0, 10]"},
      {[](v1::StreamConfig* c) { c->set_delivery(static_cast<v1::DeliveryMode>(5)); },
       "config.delivery is 5, not one of DELIVERY_LATEST, DELIVERY_ALL"},
  };
  for (const Case& c : cases) {
    v1::StreamConfig config;
    c.spoil(&config);
    auto s = Resolve(config, defaults);
    ASSERT_FALSE(s.ok()) << c.message;
    EXPECT_EQ(s.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(std::string(s.status().message()), HasSubstr(c.message));
  }
}

TEST(ConvertTest, SettingsRoundTripThroughTheProto) {
  StreamSettings s;
  s.frame.pipeline.camera.fx = 500;
  s.frame.pipeline.camera.fy = 510;
  s.frame.pipeline.camera.invalid_disparities = {0, 255};
  s.frame.pipeline.passthrough = {true, Axis::kY, -1.0f, 2.5f, true};
  s.frame.pipeline.voxel.leaf_x = 0.1f;
  s.frame.pipeline.voxel.min_points_per_voxel = 2;
  s.frame.draco.position_bits = 12;
  s.frame.cy = 100;
  s.delivery = Delivery::kAll;
  const v1::StreamConfig proto = ToProto(s);
  EXPECT_FALSE(proto.camera().has_cx());  // follows each frame
  EXPECT_EQ(proto.camera().cy(), 100);
  EXPECT_FALSE(proto.voxel_grid().has_leaf());  // the leaves differ
  EXPECT_FLOAT_EQ(proto.draco().max_position_error(), 0.03f / 4);  // from the smallest leaf
  auto back = Resolve(proto, StreamSettings{});
  ASSERT_TRUE(back.ok()) << back.status();
  const FrameSettings& f = back->frame;
  EXPECT_EQ(f.pipeline.camera.fx, 500);
  EXPECT_EQ(f.pipeline.camera.fy, 510);
  EXPECT_EQ(f.pipeline.camera.invalid_disparities, (std::vector<double>{0, 255}));
  EXPECT_EQ(f.pipeline.passthrough.axis, Axis::kY);
  EXPECT_TRUE(f.pipeline.passthrough.negative);
  EXPECT_FLOAT_EQ(f.pipeline.passthrough.min, -1.0f);
  EXPECT_FLOAT_EQ(f.pipeline.voxel.leaf_x, 0.1f);
  EXPECT_FLOAT_EQ(f.pipeline.voxel.leaf_y, 0.03f);
  EXPECT_EQ(f.pipeline.voxel.min_points_per_voxel, 2u);
  EXPECT_EQ(f.draco.position_bits, 12);
  EXPECT_FALSE(f.cx.has_value());
  EXPECT_EQ(*f.cy, 100);
  EXPECT_EQ(back->delivery, Delivery::kAll);
}

TEST(ConvertTest, FramesGoToTheProtoPackedAndComeBackAsViews) {
  // 3x2 u16 disparity with 2 bytes of padding per row.
  const std::uint32_t w = 3, h = 2;
  const std::size_t stride = w * 2 + 2;
  std::vector<std::uint8_t> bytes(stride * h, 0xEE);
  for (std::uint32_t v = 0; v < h; ++v) {
    for (std::uint32_t u = 0; u < w; ++u) {
      const std::uint16_t d = static_cast<std::uint16_t>(100 * v + u);
      std::memcpy(&bytes[v * stride + u * 2], &d, 2);
    }
  }
  DisparityView view{bytes.data(), bytes.size(), w, h, stride, DisparityEncoding::kU16};
  v1::RawDisparity raw;
  ASSERT_TRUE(ToProto(view, "disparity", &raw).ok());
  EXPECT_EQ(raw.encoding(), v1::DISPARITY_U16);
  EXPECT_EQ(raw.row_stride(), 0u);
  EXPECT_EQ(raw.pixels().size(), w * h * 2);  // padding is never sent

  DisparityView back;
  ASSERT_TRUE(ViewRaw(raw, "frame.disparity.raw", Limits{}, &back).ok());
  EXPECT_EQ(back.data, raw.pixels().data());  // in place, no copy
  EXPECT_EQ(back.stride_bytes, w * 2);
  for (std::uint32_t v = 0; v < h; ++v) {
    for (std::uint32_t u = 0; u < w; ++u) {
      std::uint16_t d;
      std::memcpy(&d, back.row(v) + u * 2, 2);
      EXPECT_EQ(d, 100 * v + u);
    }
  }

  // Over a limit: RESOURCE_EXHAUSTED naming the field; malformed: INVALID_ARGUMENT.
  const absl::Status over = ViewRaw(raw, "frame.disparity.raw", Limits{2, 100}, &back);
  EXPECT_EQ(over.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(std::string(over.message()), HasSubstr("frame.disparity.raw is 3x2"));
  raw.set_row_stride(5);
  const absl::Status short_stride = ViewRaw(raw, "frame.disparity.raw", Limits{}, &back);
  EXPECT_EQ(short_stride.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(short_stride.message()),
              HasSubstr("frame.disparity.raw.row_stride is 5, less than width x 2 = 6"));

  // BGRA rows lose their alpha on the way.
  const std::uint8_t bgra[] = {1, 2, 3, 255, 4, 5, 6, 255};
  v1::RawColor colour;
  ASSERT_TRUE(BgraToProto(bgra, sizeof bgra, 2, 1, 8, "colour", &colour).ok());
  EXPECT_EQ(colour.encoding(), v1::COLOR_BGR8);
  EXPECT_EQ(colour.pixels(), std::string("\x01\x02\x03\x04\x05\x06", 6));
  EXPECT_FALSE(BgraToProto(bgra, sizeof bgra, 2, 1, 4, "colour", &colour).ok());
}

TEST(ConvertTest, ErrorsCarryTheirKind) {
  v1::FrameError error;
  FillError(absl::InvalidArgumentError("config.camera.fx must be ..."), v1::ERROR_KIND_CONFIG, 0,
            "", &error);
  EXPECT_EQ(error.code(), 3);
  EXPECT_EQ(error.kind(), v1::ERROR_KIND_CONFIG);
  EXPECT_TRUE(AnswersNoFrame(error));
  EXPECT_EQ(ToStatus(error).code(), absl::StatusCode::kInvalidArgument);

  FillError(absl::ResourceExhaustedError("frame.color.raw is 5000x5000"), v1::ERROR_KIND_FRAME,
            7, "cam", &error);
  EXPECT_FALSE(AnswersNoFrame(error));
  EXPECT_EQ(error.sequence(), 7u);
  EXPECT_EQ(error.frame_id(), "cam");
  // A message that merely looks like a config error is still a frame's (nothing parses text).
  error.set_message("config.x");
  error.set_kind(v1::ERROR_KIND_UNSPECIFIED);
  EXPECT_FALSE(AnswersNoFrame(error));
  error.set_code(99);
  EXPECT_EQ(ToStatus(error).code(), absl::StatusCode::kUnknown);
}

TEST(ConvertTest, ErrorsCarryTheirFieldAndRule) {
  v1::FrameError error;
  FillError(absl::ResourceExhaustedError("frame.color.raw is 5000x5000"), v1::ERROR_KIND_FRAME, 7,
            "cam", &error);
  ASSERT_EQ(error.bad_request().field_violations_size(), 1);
  EXPECT_EQ(error.bad_request().field_violations(0).field(), "frame.color.raw");
  EXPECT_EQ(error.bad_request().field_violations(0).reason(), "OVER_LIMIT");
  EXPECT_EQ(error.bad_request().field_violations(0).description(), error.message());
  // The field and rule survive the client's status, for FieldViolationOf.
  const v1::FieldViolation back = FieldViolationOf(ToStatus(error), "");
  EXPECT_EQ(back.field(), "frame.color.raw");
  EXPECT_EQ(back.reason(), "OVER_LIMIT");

  // A message that does not start with a field names the fallback; a required field its own.
  FillError(absl::InvalidArgumentError("the request held neither"), v1::ERROR_KIND_REQUEST, 0, "",
            &error);
  EXPECT_EQ(error.bad_request().field_violations(0).field(), "kind");
  EXPECT_EQ(error.bad_request().field_violations(0).reason(), "INVALID");
  FillError(RequiredError("config.camera.fx", "a depth frame needs the focal length"),
            v1::ERROR_KIND_FRAME, 1, "", &error);
  EXPECT_EQ(error.bad_request().field_violations(0).field(), "config.camera.fx");
  EXPECT_EQ(error.bad_request().field_violations(0).reason(), "REQUIRED");

  // The call status details: a google.rpc.Status holding a google.rpc.BadRequest.
  const std::string details =
      StatusDetails(absl::InvalidArgumentError("frame.depth.raw.row_stride is 3"), "frame");
  v1::BadRequest bad;
  ASSERT_TRUE(ParseStatusDetails(details, &bad));
  ASSERT_EQ(bad.field_violations_size(), 1);
  EXPECT_EQ(bad.field_violations(0).field(), "frame.depth.raw.row_stride");
  EXPECT_NE(details.find("type.googleapis.com/google.rpc.BadRequest"), std::string::npos);
  EXPECT_FALSE(ParseStatusDetails("", &bad));
}

TEST(ConvertTest, TheContractAssumesNoCameraAndNoPassthrough) {
  const StreamSettings defaults = ContractDefaults();
  EXPECT_FALSE(defaults.frame.focal_given);
  EXPECT_FALSE(defaults.frame.pipeline.passthrough.enabled);
  // No camera: fx required for every frame, a baseline for disparities only.
  absl::Status s = RequireCamera(defaults.frame, v1::Frame::kDepth);
  EXPECT_EQ(FieldViolationOf(s, "").field(), "config.camera.fx");
  EXPECT_EQ(FieldViolationOf(s, "").reason(), "REQUIRED");
  v1::StreamConfig config;
  config.mutable_camera()->set_fx(600);
  auto resolved = Resolve(config, defaults);
  ASSERT_TRUE(resolved.ok()) << resolved.status();
  EXPECT_TRUE(RequireCamera(resolved->frame, v1::Frame::kDepth).ok());
  s = RequireCamera(resolved->frame, v1::Frame::kDisparity);
  EXPECT_EQ(FieldViolationOf(s, "").field(), "config.camera.baseline");
  config.mutable_camera()->set_baseline(0.1);
  resolved = Resolve(config, defaults);
  ASSERT_TRUE(resolved.ok());
  EXPECT_TRUE(RequireCamera(resolved->frame, v1::Frame::kDisparity).ok());
  // GetInfo's defaults show no camera.
  const v1::StreamConfig shown = ToProto(defaults);
  EXPECT_FALSE(shown.camera().has_fx());
  EXPECT_FALSE(shown.camera().has_baseline());
  // A limit switches the passthrough on; enabled false keeps it off.
  config.mutable_passthrough()->set_max(4);
  resolved = Resolve(config, defaults);
  ASSERT_TRUE(resolved.ok());
  EXPECT_TRUE(resolved->frame.pipeline.passthrough.enabled);
  EXPECT_EQ(resolved->frame.pipeline.passthrough.max, 4.0f);
  config.mutable_passthrough()->set_enabled(false);
  resolved = Resolve(config, defaults);
  ASSERT_TRUE(resolved.ok());
  EXPECT_FALSE(resolved->frame.pipeline.passthrough.enabled);
  // A frame's camera, field by field over the stream's.
  FrameSettings frame = resolved->frame;
  v1::CameraModel zoom;
  zoom.set_fx(1200);
  ASSERT_TRUE(ApplyCamera(zoom, "frame.camera", &frame).ok());
  EXPECT_EQ(frame.pipeline.camera.fx, 1200);
  EXPECT_EQ(frame.pipeline.camera.baseline, 0.1);
  zoom.set_fx(-1);
  EXPECT_EQ(FieldViolationOf(ApplyCamera(zoom, "frame.camera", &frame), "").field(),
            "frame.camera.fx");
  // The paper's setting, by name.
  auto paper = PresetConfig("new_tsukuba");
  ASSERT_TRUE(paper.ok());
  EXPECT_EQ(paper->camera().fx(), 615);
  EXPECT_EQ(paper->camera().baseline(), 1);
  EXPECT_FALSE(paper->camera().has_cx());
  EXPECT_EQ(paper->passthrough().min(), 3);
  EXPECT_EQ(paper->passthrough().max(), 12);
  EXPECT_THAT(std::string(PresetConfig("kitti").status().message()),
              HasSubstr("preset is \"kitti\"; it must be one of new_tsukuba"));
}

}  // namespace
}  // namespace cloudcast::convert
