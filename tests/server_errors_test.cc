// Bad input, end to end: every malformed frame and config gets its own error reply (the code,
// and a message naming the field and the limit) while the stream and every other stream go on;
// the Process RPC's errors as statuses; the image header sniffing the limits are checked with.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include "frame_input.h"
#include "support/server_support.h"

namespace cloudcast::server {
namespace {

// ---------------------------------------------------------------------------------------------
// Bad input.

struct BadFrameCase {
  std::string name;
  std::function<void(v1::Frame*)> spoil;
  grpc::StatusCode code;
  std::vector<std::string> message_has;
};

std::string PngWithSize(std::uint32_t w, std::uint32_t h) {
  std::string png = Frames().front().disparity_png;
  for (int i = 0; i < 4; ++i) {
    png[16 + i] = static_cast<char>(w >> (24 - 8 * i));
    png[20 + i] = static_cast<char>(h >> (24 - 8 * i));
  }
  return png;
}

// A little-endian TIFF whose first directory claims w x h (and holds nothing else).
std::string TiffHeader(std::uint32_t w, std::uint32_t h) {
  std::string t = {'I', 'I', 42, 0, 8, 0, 0, 0, 2, 0};
  auto entry = [&](std::uint16_t tag, std::uint32_t value) {
    const std::uint8_t e[12] = {std::uint8_t(tag),
                                std::uint8_t(tag >> 8),
                                4,
                                0,
                                1,
                                0,
                                0,
                                0,
                                std::uint8_t(value),
                                std::uint8_t(value >> 8),
                                std::uint8_t(value >> 16),
                                std::uint8_t(value >> 24)};
    t.append(reinterpret_cast<const char*>(e), 12);
  };
  entry(256, w);
  entry(257, h);
  t.append(4, '\0');
  return t;
}

std::string JpegWithSize(std::uint16_t w, std::uint16_t h) {
  std::string jpeg = Frames().front().colour_jpeg;
  // Walk the marker segments to the start of frame (baseline or progressive) and patch its size.
  auto byte = [&](std::size_t i) { return static_cast<unsigned char>(jpeg[i]); };
  for (std::size_t i = 2; i + 9 < jpeg.size();) {
    const unsigned char marker = byte(i + 1);
    if (marker == 0xC0 || marker == 0xC1 || marker == 0xC2) {
      jpeg[i + 5] = static_cast<char>(h >> 8);
      jpeg[i + 6] = static_cast<char>(h & 0xFF);
      jpeg[i + 7] = static_cast<char>(w >> 8);
      jpeg[i + 8] = static_cast<char>(w & 0xFF);
      return jpeg;
    }
    i += 2 + ((std::size_t{byte(i + 2)} << 8) | byte(i + 3));
  }
  ADD_FAILURE() << "no start-of-frame marker in the JPEG";
  return jpeg;
}

std::vector<BadFrameCase> BadFrameCases() {
  const auto kInvalid = grpc::StatusCode::INVALID_ARGUMENT;
  const auto kExhausted = grpc::StatusCode::RESOURCE_EXHAUSTED;
  const SourceFrame& f = Frames().front();
  return {
      {"missing disparity",
       [](v1::Frame* fr) { fr->clear_disparity(); },
       kInvalid,
       {"frame.disparity is missing"}},
      {"missing colour",
       [](v1::Frame* fr) { fr->clear_color(); },
       kInvalid,
       {"frame.color is missing"}},
      {"unspecified disparity encoding",
       [](v1::Frame* fr) {
         fr->mutable_disparity()->mutable_raw()->set_encoding(v1::DISPARITY_ENCODING_UNSPECIFIED);
       },
       kInvalid,
       {"frame.disparity.raw.encoding", "DISPARITY_ENCODING_UNSPECIFIED"}},
      {"unknown colour encoding",
       [](v1::Frame* fr) {
         fr->mutable_color()->mutable_raw()->set_encoding(static_cast<v1::ColorEncoding>(42));
       },
       kInvalid,
       {"frame.color.raw.encoding is 42"}},
      {"zero width",
       [](v1::Frame* fr) { fr->mutable_disparity()->mutable_raw()->set_width(0); },
       kInvalid,
       {"frame.disparity.raw.width is 0"}},
      {"zero height",
       [](v1::Frame* fr) { fr->mutable_color()->mutable_raw()->set_height(0); },
       kInvalid,
       {"frame.color.raw.height is 0"}},
      {"disparity row_stride too small",
       [](v1::Frame* fr) { fr->mutable_disparity()->mutable_raw()->set_row_stride(100); },
       kInvalid,
       {"frame.disparity.raw.row_stride is 100, less than width x 1 = 640"}},
      {"colour row_stride too small",
       [](v1::Frame* fr) { fr->mutable_color()->mutable_raw()->set_row_stride(1000); },
       kInvalid,
       {"frame.color.raw.row_stride is 1000, less than width x 3 = 1920"}},
      {"disparity pixels too short",
       [](v1::Frame* fr) {
         fr->mutable_disparity()->mutable_raw()->mutable_pixels()->resize(1000);
       },
       kInvalid,
       {"frame.disparity.raw.pixels holds 1000 bytes", "needs 307200"}},
      {"colour pixels too short for its stride",
       [](v1::Frame* fr) { fr->mutable_color()->mutable_raw()->set_row_stride(1921); },
       kInvalid,
       {"frame.color.raw.pixels holds 921600 bytes", "row_stride 1921"}},
      {"u16 pixels too short",
       [](v1::Frame* fr) {
         fr->mutable_disparity()->mutable_raw()->set_encoding(v1::DISPARITY_U16);
       },
       kInvalid,
       {"frame.disparity.raw.pixels holds 307200 bytes", "DISPARITY_U16"}},
      {"sizes differ",
       [](v1::Frame* fr) {
         v1::RawColor* c = fr->mutable_color()->mutable_raw();
         c->set_width(320);
         c->set_height(240);
       },
       kInvalid,
       {"frame.color is 320x240 but frame.disparity is 640x480"}},
      {"unknown image format",
       [](v1::Frame* fr) { fr->mutable_disparity()->set_encoded("this is not a PNG"); },
       kInvalid,
       {"frame.disparity.encoded is not a PNG, JPEG, TIFF, PNM or PFM image"}},
      {"undecodable PNG body",
       [&f](v1::Frame* fr) {
         std::string png = f.disparity_png;
         std::fill(png.begin() + 40, png.end(), 'x');
         fr->mutable_disparity()->set_encoded(png);
       },
       kInvalid,
       {"frame.disparity.encoded: cannot be decoded"}},
      {"truncated colour PNG",
       [&f](v1::Frame* fr) { fr->mutable_color()->set_encoded(f.colour_png.substr(0, 200)); },
       kInvalid,
       {"frame.color.encoded"}},
      {"empty encoded disparity",
       [](v1::Frame* fr) { fr->mutable_disparity()->set_encoded(""); },
       kInvalid,
       {"frame.disparity.encoded is empty"}},
      {"multi-channel disparity file",
       [&f](v1::Frame* fr) {
         fr->mutable_disparity()->set_encoded(
             Encode(".png", f.colour.width, f.colour.height, CV_8UC3, f.colour.pixels.data()));
       },
       kInvalid,
       {"frame.disparity.encoded", "3 channels", "one"}},
      {"side over the limit",
       [](v1::Frame* fr) {
         fr->mutable_disparity()->mutable_raw()->set_width(20000);
         fr->mutable_disparity()->mutable_raw()->set_height(1);
       },
       kExhausted,
       {"frame.disparity.raw is 20000x1", "the limit is 16384 pixels per side"}},
      {"pixels over the limit",
       [](v1::Frame* fr) {
         fr->mutable_color()->mutable_raw()->set_width(5000);
         fr->mutable_color()->mutable_raw()->set_height(5000);
       },
       kExhausted,
       {"frame.color.raw is 5000x5000 = 25000000 pixels", "the limit is 16777216"}},
      {"PNG header over the limit",
       [](v1::Frame* fr) { fr->mutable_disparity()->set_encoded(PngWithSize(16000, 16000)); },
       kExhausted,
       {"frame.disparity.encoded (PNG) is 16000x16000", "16777216"}},
      {"TIFF header over the limit",
       [](v1::Frame* fr) { fr->mutable_disparity()->set_encoded(TiffHeader(30000, 30000)); },
       kExhausted,
       {"frame.disparity.encoded (TIFF) is 30000x30000", "16384 pixels per side"}},
      {"PNM header over the limit",
       [](v1::Frame* fr) { fr->mutable_color()->set_encoded("P6\n# a comment\n5000 4000\n255\n"); },
       kExhausted,
       {"frame.color.encoded (PNM) is 5000x4000 = 20000000 pixels"}},
      {"JPEG header over the limit",
       [](v1::Frame* fr) { fr->mutable_color()->set_encoded(JpegWithSize(30000, 2)); },
       kExhausted,
       {"frame.color.encoded (JPEG) is 30000x2", "16384 pixels per side"}},
  };
}

struct BadConfigCase {
  std::string name;
  std::function<void(v1::StreamConfig*)> spoil;
  std::vector<std::string> message_has;
};

std::vector<BadConfigCase> BadConfigCases() {
  return {
      {"fx zero",
       [](v1::StreamConfig* c) { c->mutable_camera()->set_fx(0); },
       {"config.camera.fx must be finite and in (0, 1e9], got 0"}},
      {"fx NaN",
       [](v1::StreamConfig* c) { c->mutable_camera()->set_fx(std::nan("")); },
       {"config.camera.fx", "nan"}},
      {"baseline negative",
       [](v1::StreamConfig* c) { c->mutable_camera()->set_baseline(-1); },
       {"config.camera.baseline"}},
      {"disparity_scale zero",
       [](v1::StreamConfig* c) { c->mutable_camera()->set_disparity_scale(0); },
       {"config.camera.disparity_scale must not be 0"}},
      {"too many invalid disparities",
       [](v1::StreamConfig* c) {
         for (int i = 0; i < 17; ++i)
           c->mutable_camera()->mutable_invalid_disparities()->add_values(i);
       },
       {"config.camera.invalid_disparities.values holds 17 values; the limit is 16"}},
      {"leaf zero",
       [](v1::StreamConfig* c) { c->mutable_voxel_grid()->set_leaf(0); },
       {"config.voxel_grid.leaf must be finite and > 0", "got 0"}},
      {"leaf negative",
       [](v1::StreamConfig* c) { c->mutable_voxel_grid()->set_leaf_y(-0.5f); },
       {"config.voxel_grid.leaf_y", "got -0.5"}},
      {"min above max",
       [](v1::StreamConfig* c) {
         c->mutable_passthrough()->set_min(20);
         c->mutable_passthrough()->clear_max();
       },
       {"config.passthrough.min (20) must not exceed config.passthrough.max (12, the server "
        "default)"}},
      {"min NaN",
       [](v1::StreamConfig* c) { c->mutable_passthrough()->set_min(std::nanf("")); },
       {"config.passthrough.min must be finite"}},
      {"unknown axis",
       [](v1::StreamConfig* c) { c->mutable_passthrough()->set_axis(static_cast<v1::Axis>(9)); },
       {"config.passthrough.axis is 9"}},
      {"draco bits out of range",
       [](v1::StreamConfig* c) { c->mutable_draco()->set_position_bits(31); },
       {"config.draco.position_bits is 31; it must be in [1, 30]"}},
      {"draco colour bits zero",
       [](v1::StreamConfig* c) { c->mutable_draco()->set_color_bits(0); },
       {"config.draco.color_bits is 0; it must be in [1, 8]"}},
      {"draco speed out of range",
       [](v1::StreamConfig* c) { c->mutable_draco()->set_encode_speed(11); },
       {"config.draco.encode_speed is 11; it must be in [0, 10]"}},
      {"draco negative error",
       [](v1::StreamConfig* c) { c->mutable_draco()->set_max_position_error(-1); },
       {"config.draco.max_position_error must be finite and >= 0"}},
      {"unknown delivery",
       [](v1::StreamConfig* c) { c->set_delivery(static_cast<v1::DeliveryMode>(7)); },
       {"config.delivery is 7"}},
  };
}

// The field path each case's FieldViolation names (FrameError.bad_request): written out here,
// not derived from the message, so that a change of either shows.
const std::map<std::string, std::string>& ExpectedFields() {
  static const std::map<std::string, std::string> fields = {
      {"missing disparity", "frame.disparity"},
      {"missing colour", "frame.color"},
      {"unspecified disparity encoding", "frame.disparity.raw.encoding"},
      {"unknown colour encoding", "frame.color.raw.encoding"},
      {"zero width", "frame.disparity.raw.width"},
      {"zero height", "frame.color.raw.height"},
      {"disparity row_stride too small", "frame.disparity.raw.row_stride"},
      {"colour row_stride too small", "frame.color.raw.row_stride"},
      {"disparity pixels too short", "frame.disparity.raw.pixels"},
      {"colour pixels too short for its stride", "frame.color.raw.pixels"},
      {"u16 pixels too short", "frame.disparity.raw.pixels"},
      {"sizes differ", "frame.color"},
      {"unknown image format", "frame.disparity.encoded"},
      {"undecodable PNG body", "frame.disparity.encoded"},
      {"truncated colour PNG", "frame.color.encoded"},
      {"empty encoded disparity", "frame.disparity.encoded"},
      {"multi-channel disparity file", "frame.disparity.encoded"},
      {"side over the limit", "frame.disparity.raw"},
      {"pixels over the limit", "frame.color.raw"},
      {"PNG header over the limit", "frame.disparity.encoded"},
      {"TIFF header over the limit", "frame.disparity.encoded"},
      {"PNM header over the limit", "frame.color.encoded"},
      {"JPEG header over the limit", "frame.color.encoded"},
      {"fx zero", "config.camera.fx"},
      {"fx NaN", "config.camera.fx"},
      {"baseline negative", "config.camera.baseline"},
      {"disparity_scale zero", "config.camera.disparity_scale"},
      {"too many invalid disparities", "config.camera.invalid_disparities.values"},
      {"leaf zero", "config.voxel_grid.leaf"},
      {"leaf negative", "config.voxel_grid.leaf_y"},
      {"min above max", "config.passthrough.min"},
      {"min NaN", "config.passthrough.min"},
      {"unknown axis", "config.passthrough.axis"},
      {"draco bits out of range", "config.draco.position_bits"},
      {"draco colour bits zero", "config.draco.color_bits"},
      {"draco speed out of range", "config.draco.encode_speed"},
      {"draco negative error", "config.draco.max_position_error"},
      {"unknown delivery", "config.delivery"},
      {"neither", "kind"},
  };
  return fields;
}

::testing::AssertionResult IsError(const v1::StreamReply& reply, grpc::StatusCode code,
                                   std::uint64_t sequence, const std::vector<std::string>& has,
                                   const std::string& field) {
  if (!reply.has_error()) return ::testing::AssertionFailure() << "not an error reply";
  const v1::FrameError& e = reply.error();
  if (e.bad_request().field_violations_size() != 1) {
    return ::testing::AssertionFailure() << "no field violation: " << e.message();
  }
  const v1::FieldViolation& v = e.bad_request().field_violations(0);
  const std::string reason =
      code == grpc::StatusCode::RESOURCE_EXHAUSTED ? "OVER_LIMIT" : "INVALID";
  if (v.field() != field || v.reason() != reason || v.description() != e.message()) {
    return ::testing::AssertionFailure()
           << "field violation " << v.field() << " (" << v.reason() << "), want " << field << " ("
           << reason << "): " << e.message();
  }
  if (e.code() != static_cast<int>(code)) {
    return ::testing::AssertionFailure()
           << "code " << e.code() << ", want " << code << ": " << e.message();
  }
  if (e.sequence() != sequence) {
    return ::testing::AssertionFailure() << "sequence " << e.sequence() << ", want " << sequence;
  }
  for (const std::string& s : has) {
    if (e.message().find(s) == std::string::npos) {
      return ::testing::AssertionFailure()
             << "message \"" << e.message() << "\" lacks \"" << s << "\"";
    }
  }
  return ::testing::AssertionSuccess() << e.message();
}

TEST_F(ServerTest, BadFramesAndConfigsGetNamedErrorsAndEveryStreamGoesOn) {
  const std::vector<BadFrameCase> frame_cases = BadFrameCases();
  const std::vector<BadConfigCase> config_cases = BadConfigCases();
  const Params before{0.1f, true, 3.0f, 12.0f};  // the config in force throughout
  const SourceFrame& f = Frames().front();

  // A second stream streams good frames meanwhile; it must not notice anything.
  std::atomic<bool> stop{false};
  StreamResult bystander;
  std::thread other([&] {
    auto stub = testing::NewStub(shared_server());
    grpc::ClientContext ctx;
    SetDeadline(&ctx);
    auto stream = stub->Stream(&ctx);
    stream->Write(ConfigRequest(ConfigFor(Params{}, v1::DELIVERY_ALL)));
    v1::StreamReply reply;
    for (std::uint64_t i = 0; !stop.load(); ++i) {
      if (!stream->Write(FrameRequest(MakeFrame(Frames()[i % Frames().size()], i)))) break;
      if (!stream->Read(&reply)) break;
      bystander.replies.push_back(reply);
    }
    stream->WritesDone();
    while (stream->Read(&reply)) bystander.replies.push_back(reply);
    bystander.status = stream->Finish();
  });

  std::vector<v1::StreamRequest> requests = {ConfigRequest(ConfigFor(before, v1::DELIVERY_ALL))};
  std::uint64_t sequence = 1;
  for (const BadFrameCase& c : frame_cases) {
    v1::Frame bad = MakeFrame(f, sequence++);
    c.spoil(&bad);
    requests.push_back(FrameRequest(bad));
    requests.push_back(FrameRequest(MakeFrame(f, sequence++)));
  }
  for (const BadConfigCase& c : config_cases) {
    v1::StreamConfig bad = ConfigFor(before, v1::DELIVERY_ALL);
    c.spoil(&bad);
    requests.push_back(ConfigRequest(bad));
    requests.push_back(FrameRequest(MakeFrame(f, sequence++)));
  }
  requests.push_back(v1::StreamRequest());  // neither config nor frame
  requests.push_back(FrameRequest(MakeFrame(f, sequence++)));
  const StreamResult result = RunStream(*stub_, requests);
  stop.store(true);
  other.join();

  ASSERT_TRUE(result.status.ok()) << result.status.error_message();
  ASSERT_EQ(result.replies.size(), 2 * (frame_cases.size() + config_cases.size() + 1));
  const PointCloud expected = Reference(f, before);
  std::size_t r = 0;
  std::uint64_t s = 1;
  for (const BadFrameCase& c : frame_cases) {
    SCOPED_TRACE(c.name);
    EXPECT_TRUE(
        IsError(result.replies[r++], c.code, s++, c.message_has, ExpectedFields().at(c.name)));
    ASSERT_TRUE(result.replies[r].has_cloud()) << result.replies[r].error().message();
    EXPECT_EQ(result.replies[r].cloud().sequence(), s++);
    EXPECT_TRUE(CloudMatches(expected, result.replies[r++].cloud()));
  }
  for (const BadConfigCase& c : config_cases) {
    SCOPED_TRACE(c.name);
    EXPECT_TRUE(IsError(result.replies[r++], grpc::StatusCode::INVALID_ARGUMENT, 0, c.message_has,
                        ExpectedFields().at(c.name)));
    // The previous config (leaf 0.1) is still in force.
    ASSERT_TRUE(result.replies[r].has_cloud()) << result.replies[r].error().message();
    EXPECT_EQ(result.replies[r].cloud().sequence(), s++);
    EXPECT_TRUE(CloudMatches(expected, result.replies[r++].cloud()));
  }
  EXPECT_TRUE(
      IsError(result.replies[r++], grpc::StatusCode::INVALID_ARGUMENT, 0, {"neither"}, "kind"));
  EXPECT_TRUE(result.replies[r++].has_cloud());

  ASSERT_TRUE(bystander.status.ok()) << bystander.status.error_message();
  ASSERT_FALSE(bystander.replies.empty());
  for (std::size_t i = 0; i < bystander.replies.size(); ++i) {
    ASSERT_TRUE(bystander.replies[i].has_cloud());
    EXPECT_EQ(bystander.replies[i].cloud().sequence(), i);
  }
}

TEST_F(ServerTest, ProcessRpcReturnsFrameErrorsAsStatus) {
  const SourceFrame& f = Frames().front();
  auto process = [&](const v1::ProcessRequest& request) {
    v1::CloudReply reply;
    grpc::ClientContext ctx;
    SetDeadline(&ctx);
    return stub_->Process(&ctx, request, &reply);
  };
  v1::ProcessRequest request;
  *request.mutable_frame() = MakeFrame(f, 1);
  request.mutable_frame()->mutable_disparity()->mutable_raw()->set_row_stride(100);
  // Every refusal carries its field and rule in the status details (google.rpc.BadRequest).
  auto violation = [](const grpc::Status& st) {
    v1::BadRequest bad;
    EXPECT_TRUE(convert::ParseStatusDetails(st.error_details(), &bad)) << st.error_message();
    return bad.field_violations_size() == 1 ? bad.field_violations(0) : v1::FieldViolation();
  };
  grpc::Status status = process(request);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("frame.disparity.raw.row_stride is 100"), std::string::npos)
      << status.error_message();
  EXPECT_EQ(violation(status).field(), "frame.disparity.raw.row_stride");
  EXPECT_EQ(violation(status).reason(), "INVALID");

  *request.mutable_frame() = MakeFrame(f, 1);
  request.mutable_config()->mutable_camera()->set_fx(0);
  status = process(request);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("config.camera.fx"), std::string::npos)
      << status.error_message();
  EXPECT_EQ(violation(status).field(), "config.camera.fx");

  request.clear_config();
  request.mutable_frame()->mutable_color()->mutable_raw()->set_width(100000);
  status = process(request);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(status.error_message().find("frame.color.raw is 100000x480"), std::string::npos)
      << status.error_message();
  EXPECT_EQ(violation(status).field(), "frame.color.raw");
  EXPECT_EQ(violation(status).reason(), "OVER_LIMIT");

  *request.mutable_frame() = MakeFrame(f, 1);
  EXPECT_TRUE(process(request).ok());
}

TEST(FrameInputTest, SniffsImageSizesFromHeaders) {
  const SourceFrame& f = Frames().front();
  std::uint32_t w = 0, h = 0;
  const char* format = nullptr;
  ASSERT_TRUE(SniffImageSize(f.disparity_png, &w, &h, &format));
  EXPECT_EQ(std::string(format), "PNG");
  EXPECT_EQ(w, 640u);
  EXPECT_EQ(h, 480u);
  ASSERT_TRUE(SniffImageSize(f.colour_jpeg, &w, &h, &format));
  EXPECT_EQ(std::string(format), "JPEG");
  EXPECT_EQ(w, 640u);
  EXPECT_EQ(h, 480u);
  EXPECT_FALSE(SniffImageSize("not an image", &w, &h, &format));
  EXPECT_FALSE(SniffImageSize(f.colour_jpeg.substr(0, 20), &w, &h, &format));
  ASSERT_TRUE(SniffImageSize(TiffHeader(7, 9), &w, &h, &format));
  EXPECT_EQ(std::string(format), "TIFF");
  EXPECT_EQ(w, 7u);
  EXPECT_EQ(h, 9u);
  EXPECT_FALSE(SniffImageSize(TiffHeader(7, 9).substr(0, 20), &w, &h, &format));
  const std::string pgm =
      Encode(".pgm", f.disparity.width, f.disparity.height, CV_8UC1, f.disparity.pixels.data());
  ASSERT_TRUE(SniffImageSize(pgm, &w, &h, &format));
  EXPECT_EQ(std::string(format), "PNM");
  EXPECT_EQ(w, 640u);
  EXPECT_EQ(h, 480u);
  ASSERT_TRUE(SniffImageSize("P5 #c\n 12\n#d\n34 255\n", &w, &h, &format));
  EXPECT_EQ(w, 12u);
  EXPECT_EQ(h, 34u);
  EXPECT_FALSE(SniffImageSize("P5\n12", &w, &h, &format));
  EXPECT_FALSE(SniffImageSize("P9\n12 13\n", &w, &h, &format));
}

}  // namespace
}  // namespace cloudcast::server
