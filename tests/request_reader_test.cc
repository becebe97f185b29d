// RequestReader: requests parsed from gRPC's slices with the raw pixels left in them. Every case
// is checked against protobuf's own parse of the same bytes (with the pixels put back), and the
// images a worker views through the row tables against the contiguous ones, down to the cloud.
#include "request_reader.h"

#include <gtest/gtest.h>

#include <cstring>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "cloudcast/core/pipeline.h"
#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/proto/convert.h"
#include "frame_input.h"
#include "google/protobuf/util/message_differencer.h"
#include "support/test_support.h"

namespace cloudcast {
namespace {

using google::protobuf::util::MessageDifferencer;
using server::RequestReader;

// `bytes` as gRPC hands them over: slices of the given sizes in turn (the last one repeats).
grpc::ByteBuffer InSlices(const std::string& bytes, const std::vector<std::size_t>& sizes) {
  std::vector<grpc::Slice> slices;
  std::size_t at = 0;
  for (std::size_t i = 0; at < bytes.size(); ++i) {
    const std::size_t n = std::min(sizes[std::min(i, sizes.size() - 1)], bytes.size() - at);
    slices.emplace_back(bytes.data() + at, n);
    at += n;
  }
  return grpc::ByteBuffer(slices.data(), slices.size());
}

// The wire format by hand, for messages protobuf's own writer would not make (repeated and
// reordered fields, oneof switches, unknown fields, groups).
std::string Varint(std::uint64_t v) {
  std::string out;
  while (v >= 0x80) {
    out.push_back(static_cast<char>((v & 0x7f) | 0x80));
    v >>= 7;
  }
  out.push_back(static_cast<char>(v));
  return out;
}
std::string Len(int field, const std::string& content) {
  return Varint((static_cast<std::uint64_t>(field) << 3) | 2) + Varint(content.size()) + content;
}
std::string VarintField(int field, std::uint64_t v) {
  return Varint(static_cast<std::uint64_t>(field) << 3) + Varint(v);
}
std::string Group(int field, const std::string& content) {
  return Varint((static_cast<std::uint64_t>(field) << 3) | 3) + content +
         Varint((static_cast<std::uint64_t>(field) << 3) | 4);
}
// StreamRequest.frame > Frame.disparity / Frame.colour > raw: field numbers from the proto.
std::string InFrame(const std::string& frame_fields) {
  return Len(v1::StreamRequest::kFrameFieldNumber, frame_fields);
}
std::string Disparity(const std::string& image_fields) {
  return Len(v1::Frame::kDisparityFieldNumber, image_fields);
}
std::string Colour(const std::string& image_fields) {
  return Len(v1::Frame::kColorFieldNumber, image_fields);
}
std::string Raw(const std::string& raw_fields) {
  return Len(v1::DisparityImage::kRawFieldNumber, raw_fields);
}
std::string Pixels(const std::string& bytes) {
  return Len(v1::RawDisparity::kPixelsFieldNumber, bytes);
}

// Parses `bytes` in slices both ways and expects the same outcome and message.
template <typename Request>
void ExpectParsesLikeProtobuf(const std::string& bytes, const std::vector<std::size_t>& sizes,
                              RequestReader* reader, Request* parsed, bool* walked = nullptr) {
  Request expected;
  const bool expected_ok = expected.ParseFromString(bytes);
  grpc::ByteBuffer buffer = InSlices(bytes, sizes);
  const bool ok = reader->Parse(&buffer, parsed);
  buffer.Clear();  // the reader keeps what it needs
  ASSERT_EQ(ok, expected_ok);
  if (walked != nullptr) *walked = reader->walked();
  if (!ok) return;
  Request rebuilt = *parsed;
  if (rebuilt.has_frame()) reader->PutPixelsBack(rebuilt.mutable_frame());
  EXPECT_TRUE(MessageDifferencer::Equals(rebuilt, expected))
      << rebuilt.ShortDebugString() << "\nvs protobuf's\n"
      << expected.ShortDebugString();
}

std::string Bytes(std::size_t n, std::uint8_t seed) {
  std::string s(n, '\0');
  for (std::size_t i = 0; i < n; ++i) s[i] = static_cast<char>(seed + i * 7);
  return s;
}

TEST(RequestReaderTest, RawPixelsStayInTheSlicesAndTheRestParsesAsProtobufParsesIt) {
  std::mt19937 rng(1);
  testing::TestFrame f =
      testing::RandomFrame(rng, 37, 23, DisparityEncoding::kU16, ColorEncoding::kRGB8, 0, 900);
  v1::StreamRequest request;
  v1::Frame* frame = request.mutable_frame();
  frame->set_sequence(7);
  frame->set_frame_id("left-0007");
  frame->set_capture_time_unix_ns(123456789);
  ASSERT_TRUE(convert::ToProto(f.disparity, "d", frame->mutable_disparity()->mutable_raw()).ok());
  ASSERT_TRUE(convert::ToProto(f.colour, "c", frame->mutable_color()->mutable_raw()).ok());
  const std::string bytes = request.SerializeAsString();
  for (const std::vector<std::size_t>& sizes :
       std::vector<std::vector<std::size_t>>{{bytes.size()}, {1}, {5, 3, 64}, {100}, {16384}}) {
    RequestReader reader;
    v1::StreamRequest parsed;
    bool walked = false;
    ExpectParsesLikeProtobuf(bytes, sizes, &reader, &parsed, &walked);
    EXPECT_TRUE(walked);
    // The pixels were not copied into the message.
    EXPECT_TRUE(parsed.frame().disparity().raw().pixels().empty());
    EXPECT_TRUE(parsed.frame().color().raw().pixels().empty());
    EXPECT_EQ(reader.pixels().disparity.size, frame->disparity().raw().pixels().size());
    EXPECT_EQ(reader.pixels().colour.size, frame->color().raw().pixels().size());
    EXPECT_EQ(parsed.frame().disparity().raw().width(), 37u);
    EXPECT_EQ(parsed.frame().frame_id(), "left-0007");
  }
}

TEST(RequestReaderTest, ARawImageHoldingOnlyPixelsIsStillSet) {
  // No other field of raw is on the wire: protobuf still sets the oneof to raw.
  const std::string bytes = InFrame(Disparity(Raw(Pixels(Bytes(50, 1)))));
  RequestReader reader;
  v1::StreamRequest parsed;
  ExpectParsesLikeProtobuf(bytes, {7}, &reader, &parsed);
  EXPECT_TRUE(parsed.frame().disparity().has_raw());
  EXPECT_EQ(reader.pixels().disparity.size, 50u);
}

TEST(RequestReaderTest, RepeatedFieldsMergeAndTheLastPixelsWin) {
  const std::string bytes = InFrame(Disparity(Raw(VarintField(2, 10) + Pixels(Bytes(30, 1))))) +
                            InFrame(VarintField(v1::Frame::kSequenceFieldNumber, 9) +
                                    Disparity(Raw(Pixels(Bytes(20, 2)) + VarintField(3, 2)))) +
                            InFrame(Colour(Raw(Pixels(Bytes(60, 3)))));
  RequestReader reader;
  v1::StreamRequest parsed;
  ExpectParsesLikeProtobuf(bytes, {3, 11}, &reader, &parsed);
  EXPECT_EQ(parsed.frame().disparity().raw().width(), 10u);
  EXPECT_EQ(parsed.frame().disparity().raw().height(), 2u);
  EXPECT_EQ(reader.pixels().disparity.size, 20u);
  EXPECT_EQ(reader.pixels().colour.size, 60u);
}

TEST(RequestReaderTest, AnotherOneofMemberClearsThePixelsItReplaces) {
  RequestReader reader;
  v1::StreamRequest parsed;
  // raw, then encoded: the image is encoded; raw's pixels are gone.
  ExpectParsesLikeProtobuf(
      InFrame(Disparity(Raw(Pixels(Bytes(40, 1))))) +
          InFrame(Disparity(Len(v1::DisparityImage::kEncodedFieldNumber, "x"))),
      {5}, &reader, &parsed);
  EXPECT_TRUE(parsed.frame().disparity().has_encoded());
  EXPECT_EQ(reader.pixels().disparity.size, 0u);
  // raw with pixels, compressed, raw again without: raw holds no pixels.
  ExpectParsesLikeProtobuf(
      InFrame(Disparity(Raw(Pixels(Bytes(40, 1))) +
                        Len(v1::DisparityImage::kCompressedFieldNumber, VarintField(2, 4)) +
                        Raw(VarintField(2, 3)))),
      {9}, &reader, &parsed);
  EXPECT_TRUE(parsed.frame().disparity().has_raw());
  EXPECT_EQ(reader.pixels().disparity.size, 0u);
  // A frame, then a config: the request is a config (StreamRequest's oneof).
  ExpectParsesLikeProtobuf(
      InFrame(Colour(Raw(Pixels(Bytes(40, 1))))) + Len(v1::StreamRequest::kConfigFieldNumber, ""),
      {4}, &reader, &parsed);
  EXPECT_TRUE(parsed.has_config());
  EXPECT_EQ(reader.pixels().colour.size, 0u);
  // A oneof member's number with another wire type is an unknown field to protobuf, which
  // clears nothing (found by fuzz-stream-request).
  ExpectParsesLikeProtobuf(InFrame(Colour(Raw(Pixels(Bytes(40, 1))))) +
                               VarintField(v1::StreamRequest::kConfigFieldNumber, 8) +
                               InFrame(Colour(VarintField(v1::ColorImage::kEncodedFieldNumber, 1))),
                           {4}, &reader, &parsed);
  EXPECT_TRUE(parsed.has_frame());
  EXPECT_EQ(reader.pixels().colour.size, 40u);
  // Every member of an image's oneof replaces raw, those added since the walk was written too:
  // colour's video picture (contract revision 3; CI's fuzz-stream-request found the walk keeping
  // the pixels it replaced).
  ExpectParsesLikeProtobuf(InFrame(Colour(Raw(Pixels(Bytes(40, 1))))) +
                               InFrame(Colour(Len(v1::ColorImage::kVideoFieldNumber, ""))),
                           {6}, &reader, &parsed);
  EXPECT_TRUE(parsed.frame().color().has_video());
  EXPECT_EQ(reader.pixels().colour.size, 0u);
  // The same number in a disparity image is no oneof member there but an unknown field.
  ExpectParsesLikeProtobuf(InFrame(Disparity(Raw(Pixels(Bytes(40, 1))))) +
                               InFrame(Disparity(Len(v1::ColorImage::kVideoFieldNumber, ""))),
                           {6}, &reader, &parsed);
  EXPECT_TRUE(parsed.frame().disparity().has_raw());
  EXPECT_EQ(reader.pixels().disparity.size, 40u);
  // ProcessRequest's config is no oneof member: the frame's pixels stay.
  v1::ProcessRequest process;
  ExpectParsesLikeProtobuf(
      InFrame(Colour(Raw(Pixels(Bytes(40, 1))))) + Len(v1::ProcessRequest::kConfigFieldNumber, ""),
      {4}, &reader, &process);
  EXPECT_TRUE(process.has_config());
  EXPECT_EQ(reader.pixels().colour.size, 40u);
}

TEST(RequestReaderTest, UnknownFieldsAreKeptAtEveryLevel) {
  const std::string bytes =
      VarintField(90, 1) +
      InFrame(VarintField(91, 2) +
              Disparity(Len(92, "abc") +
                        Raw(VarintField(93, 3) + Pixels(Bytes(30, 4)) + Len(94, Bytes(5, 5))))) +
      Len(95, "tail");
  RequestReader reader;
  v1::StreamRequest parsed;
  bool walked = false;
  ExpectParsesLikeProtobuf(bytes, {2, 5}, &reader, &parsed, &walked);
  EXPECT_TRUE(walked);
  EXPECT_EQ(reader.pixels().disparity.size, 30u);
}

TEST(RequestReaderTest, WhatTheWalkDoesNotTakeProtobufParsesWhole) {
  RequestReader reader;
  v1::StreamRequest parsed;
  bool walked = true;
  // A group on the path: protobuf's parse (which keeps it as an unknown field).
  ExpectParsesLikeProtobuf(InFrame(Group(50, VarintField(1, 1)) + Disparity(Raw(Pixels("ab")))),
                           {3}, &reader, &parsed, &walked);
  EXPECT_FALSE(walked);
  EXPECT_EQ(parsed.frame().disparity().raw().pixels(), "ab");
  // pixels with another wire type: an unknown field to protobuf.
  ExpectParsesLikeProtobuf(InFrame(Disparity(Raw(VarintField(5, 3)))), {3}, &reader, &parsed,
                           &walked);
  EXPECT_FALSE(walked);
  // Truncated inside the pixels, a length past the end, a bad wire type: refused, as protobuf
  // refuses them.
  const std::string whole = InFrame(Disparity(Raw(Pixels(Bytes(40, 1)))));
  ExpectParsesLikeProtobuf(whole.substr(0, whole.size() - 3), {6}, &reader, &parsed);
  ExpectParsesLikeProtobuf(InFrame("") + Varint((2 << 3) | 2) + Varint(1000) + "x", {2}, &reader,
                           &parsed);
  ExpectParsesLikeProtobuf(InFrame(Varint((7 << 3) | 7)), {2}, &reader, &parsed);
  ExpectParsesLikeProtobuf(std::string(), {1}, &reader, &parsed);
}

TEST(RequestReaderTest, RandomFragmentsInRandomSlicesParseAsProtobufParsesThem) {
  std::mt19937 rng(11);
  auto pick = [&](int n) { return static_cast<int>(rng() % n); };
  // Random sequences of path and non-path fields at every level, some of them repeated.
  std::function<std::string(int)> fields = [&](int level) {
    std::string out;
    const int count = pick(4);
    for (int i = 0; i < count; ++i) {
      switch (level * 10 + pick(4)) {
        case 0:
          out += Len(v1::StreamRequest::kConfigFieldNumber, "");
          break;
        case 1:
        case 2:
          out += InFrame(fields(1));
          break;
        case 3:
          out += VarintField(60 + pick(3), rng() % 1000);
          break;
        case 10:
          out += VarintField(v1::Frame::kSequenceFieldNumber, rng() % 100);
          break;
        case 11:
          out += Disparity(fields(2));
          break;
        case 12:
          out += Colour(fields(2));
          break;
        case 13:
          out += Len(v1::Frame::kFrameIdFieldNumber, "id" + std::to_string(pick(9)));
          break;
        case 20:
          // encoded, or (a oneof member of colour's image only) an empty video picture
          out += pick(2) ? Len(v1::DisparityImage::kEncodedFieldNumber, Bytes(pick(20), 1))
                         : Len(v1::ColorImage::kVideoFieldNumber, "");
          break;
        case 21:
        case 22:
          out += Raw(fields(3));
          break;
        case 23:
          out += Len(v1::DisparityImage::kCompressedFieldNumber, VarintField(2, pick(9)));
          break;
        case 30:
        case 31:
          out += Pixels(Bytes(pick(300), static_cast<std::uint8_t>(pick(250))));
          break;
        case 32:
          out += VarintField(2, pick(50));
          break;
        default:
          out += VarintField(3, pick(50));
          break;
      }
    }
    return out;
  };
  RequestReader reader;
  for (int i = 0; i < 400; ++i) {
    const std::string bytes = fields(0);
    const std::vector<std::size_t> sizes = {static_cast<std::size_t>(1 + pick(40)),
                                            static_cast<std::size_t>(1 + pick(200))};
    v1::StreamRequest stream;
    ExpectParsesLikeProtobuf(bytes, sizes, &reader, &stream);
    v1::ProcessRequest process;
    ExpectParsesLikeProtobuf(bytes, sizes, &reader, &process);
    if (HasFailure()) {
      ADD_FAILURE() << "case " << i;
      return;
    }
  }
}

// The worker's view of a frame left in slices: the same rows as the message's own, and the
// same cloud from the pipeline.
TEST(RequestReaderTest, RowTablesGiveTheWorkerTheSameImagesAndTheSameCloud) {
  for (DisparityEncoding de : {DisparityEncoding::kU8, DisparityEncoding::kU16}) {
    SyntheticOptions o;
    o.width = 320;
    o.height = 240;
    o.disparity_encoding = de;
    const SyntheticFrame scene = *SyntheticScene::Default().Render(o);
    v1::StreamRequest request;
    v1::Frame* frame = request.mutable_frame();
    ASSERT_TRUE(
        convert::ToProto(scene.disparity_view(), "d", frame->mutable_disparity()->mutable_raw())
            .ok());
    ASSERT_TRUE(
        convert::ToProto(scene.colour_view(), "c", frame->mutable_color()->mutable_raw()).ok());
    const std::string bytes = request.SerializeAsString();
    PipelineOptions options;
    options.camera = scene.camera;
    options.voxel.SetLeaf(0.05f);
    Pipeline pipeline;
    PointCloud expected;
    ASSERT_TRUE(pipeline.Run(options, scene.disparity_view(), scene.colour_view(), &expected).ok());
    ASSERT_GT(expected.size(), 100u);
    // gRPC's 16 KB slices, odd sizes that put most rows across two, and one slice (no table).
    for (const std::vector<std::size_t>& sizes :
         std::vector<std::vector<std::size_t>>{{16384}, {999, 1001, 4097}, {bytes.size()}}) {
      RequestReader reader;
      grpc::ByteBuffer buffer = InSlices(bytes, sizes);
      v1::StreamRequest parsed;
      ASSERT_TRUE(reader.Parse(&buffer, &parsed));
      buffer.Clear();
      server::DecodeScratch scratch;
      server::FrameImages images;
      ASSERT_TRUE(
          server::PrepareFrameImages(parsed.frame(), Limits{}, &scratch, &images, &reader.pixels())
              .ok());
      EXPECT_EQ(images.disparity.rows != nullptr, sizes.size() > 1 || sizes[0] < bytes.size());
      for (std::uint32_t v = 0; v < scene.height; ++v) {
        ASSERT_EQ(std::memcmp(images.disparity.row(v), scene.disparity_view().row(v),
                              scene.width * BytesPerPixel(de)),
                  0)
            << "disparity row " << v;
        ASSERT_EQ(std::memcmp(images.colour.row(v), scene.colour_view().row(v), scene.width * 3), 0)
            << "colour row " << v;
      }
      PointCloud cloud;
      ASSERT_TRUE(pipeline.Run(options, images.disparity, images.colour, &cloud).ok());
      ASSERT_EQ(cloud.size(), expected.size());
      EXPECT_EQ(std::memcmp(cloud.points.data(), expected.points.data(),
                            cloud.size() * sizeof(cloud.points[0])),
                0);
    }
  }
}

TEST(RequestReaderTest, ImagesInSlicesAreCheckedAsImagesInTheMessage) {
  // The sizes come from the message, the byte count from the slices: a short buffer is named.
  v1::StreamRequest request;
  v1::RawDisparity* raw = request.mutable_frame()->mutable_disparity()->mutable_raw();
  raw->set_encoding(v1::DISPARITY_U8);
  raw->set_width(100);
  raw->set_height(100);
  raw->set_pixels(Bytes(9000, 1));
  v1::RawColor* colour = request.mutable_frame()->mutable_color()->mutable_raw();
  colour->set_encoding(v1::COLOR_BGR8);
  colour->set_width(100);
  colour->set_height(100);
  colour->set_pixels(Bytes(30000, 2));
  const std::string bytes = request.SerializeAsString();
  RequestReader reader;
  grpc::ByteBuffer buffer = InSlices(bytes, {1000});
  v1::StreamRequest parsed;
  ASSERT_TRUE(reader.Parse(&buffer, &parsed));
  server::DecodeScratch scratch;
  server::FrameImages images;
  const absl::Status s =
      server::PrepareFrameImages(parsed.frame(), Limits{}, &scratch, &images, &reader.pixels());
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("frame.disparity.raw.pixels holds 9000 bytes"), std::string::npos)
      << s;
}

}  // namespace
}  // namespace cloudcast
