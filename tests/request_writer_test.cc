// The client's RequestWriter (each raw pixel copied once, into a slice of its own): its bytes
// parse, with protobuf's own parser, to the very message FillImages + FillMeta build, for every
// kind of input; and the server's RequestReader finds the pixels in place in them.
#include <gtest/gtest.h>

#include <random>
#include <string>
#include <vector>

#include "cloudcast/proto/convert.h"
#include "frame_builder.h"  // client/src
#include "google/protobuf/util/message_differencer.h"
#include "request_reader.h"  // server/src
#include "support/test_support.h"

namespace cloudcast {
namespace {

using client::internal::RequestWriter;
using google::protobuf::util::MessageDifferencer;

std::string Flat(const grpc::ByteBuffer& bytes) {
  std::vector<grpc::Slice> slices;
  EXPECT_TRUE(bytes.Dump(&slices).ok());
  std::string out;
  for (const grpc::Slice& s : slices)
    out.append(reinterpret_cast<const char*>(s.begin()), s.size());
  return out;
}

// What protobuf's own serializer would send for the same inputs.
v1::StreamRequest Reference(const client::FrameInput& input, const client::FrameMeta& meta,
                            std::uint64_t sequence) {
  v1::StreamRequest r;
  EXPECT_TRUE(client::internal::FillImages(input, r.mutable_frame()).ok());
  client::internal::FillMeta(meta, sequence, r.mutable_frame());
  return r;
}

struct Inputs {
  std::string name;
  client::FrameInput input;
};

// A depth image of 41 x 29 16-bit or float samples.
struct Depth {
  std::vector<std::uint8_t> bytes;
  DepthView view;
  Depth(DepthEncoding e, std::mt19937& rng) : bytes(41 * 29 * BytesPerPixel(e)) {
    for (auto& b : bytes) b = static_cast<std::uint8_t>(rng());
    view = DepthView{bytes.data(), bytes.size(), 41, 29, 41 * BytesPerPixel(e), e};
  }
};

TEST(RequestWriterTest, BytesParseToTheMessageProtobufWouldSend) {
  std::mt19937 rng(3);
  // Padded strides: rows are packed on the way.
  testing::TestFrame f =
      testing::RandomFrame(rng, 41, 29, DisparityEncoding::kU16, ColorEncoding::kBGR8, 0, 900);
  testing::TestFrame g =
      testing::RandomFrame(rng, 41, 29, DisparityEncoding::kU8, ColorEncoding::kRGBA8, 0, 200);
  const std::string png = "\x89PNG not really";
  std::vector<std::uint8_t> bgra(41 * 29 * 4, 7);
  const client::BgraView bgra_view{bgra.data(), bgra.size(), 41, 29, 41 * 4};
  v1::CompressedColor precompressed;
  ASSERT_TRUE(convert::ToProto(f.colour, convert::Compression{}, "c", &precompressed).ok());
  Depth mm(DepthEncoding::kU16, rng), metres(DepthEncoding::kF32, rng);
  v1::CompressedDepth precompressed_depth;
  ASSERT_TRUE(
      convert::ToProto(metres.view, convert::Compression{}, "d", &precompressed_depth).ok());
  using client::DepthFrame;
  using client::DisparityFrame;
  using client::StereoFrame;
  // Kinds alternate, so that the writer must clear what the last kind set.
  const std::vector<Inputs> cases = {
      {"raw + raw", DisparityFrame{f.disparity, f.colour}},
      {"raw u8 + raw rgba", DisparityFrame{g.disparity, g.colour}},
      {"depth raw + raw", DepthFrame{mm.view, f.colour}},
      {"raw + compressed", DisparityFrame{f.disparity, client::CompressedColorView{f.colour, {}}}},
      {"stereo raw + raw", StereoFrame{f.colour, g.colour}},
      {"encoded + raw", DisparityFrame{client::EncodedImage{png}, f.colour}},
      {"depth compressed + bgra", DepthFrame{client::Compressed(metres.view), bgra_view}},
      {"raw + bgra", DisparityFrame{f.disparity, bgra_view}},
      {"stereo compressed + encoded",
       StereoFrame{client::CompressedColorView{f.colour, {}}, client::EncodedImage{png}}},
      {"compressed + precompressed",
       DisparityFrame{client::CompressedDisparityView{f.disparity, {}},
                      client::PrecompressedColor{&precompressed}}},
      {"depth precompressed + raw",
       DepthFrame{client::PrecompressedDepth{&precompressed_depth}, g.colour}},
      {"stereo bgra + raw", StereoFrame{bgra_view, f.colour}},
      {"raw + raw again", DisparityFrame{g.disparity, g.colour}},
  };
  RequestWriter writer;  // one writer for all: nothing of one frame may leak into the next
  std::uint64_t sequence = 10;
  for (const Inputs& in : cases) {
    SCOPED_TRACE(in.name);
    client::FrameMeta meta;
    meta.frame_id = "f" + std::to_string(sequence);
    meta.capture_time_unix_ns = 1'700'000'000'000'000'000 + static_cast<std::int64_t>(sequence);
    grpc::ByteBuffer bytes;
    ASSERT_TRUE(writer.Write(in.input, meta, sequence, &bytes).ok());
    v1::StreamRequest parsed;
    ASSERT_TRUE(parsed.ParseFromString(Flat(bytes)));
    const v1::StreamRequest expected = Reference(in.input, meta, sequence);
    EXPECT_TRUE(MessageDifferencer::Equals(parsed, expected))
        << parsed.ShortDebugString().substr(0, 400);
    EXPECT_EQ(writer.image_bytes(), client::internal::ImageBytes(expected.frame()));

    // The server reads the same bytes with the raw pixels left in place.
    server::RequestReader reader;
    v1::StreamRequest read;
    ASSERT_TRUE(reader.Parse(&bytes, &read));
    EXPECT_TRUE(reader.walked());
    EXPECT_EQ(reader.pixels().disparity.size, expected.frame().disparity().raw().pixels().size());
    EXPECT_EQ(reader.pixels().colour.size, expected.frame().color().raw().pixels().size());
    EXPECT_EQ(reader.pixels().depth.size, expected.frame().depth().raw().pixels().size());
    EXPECT_EQ(reader.pixels().right.size, expected.frame().right().raw().pixels().size());
    reader.PutPixelsBack(read.mutable_frame());
    EXPECT_TRUE(MessageDifferencer::Equals(read, expected));
    ++sequence;
  }
}

TEST(RequestWriterTest, ABadViewIsRefusedAsFillImagesRefusesIt) {
  RequestWriter writer;
  grpc::ByteBuffer bytes;
  DisparityView d{nullptr, 0, 4, 4, 4, DisparityEncoding::kU8};
  std::vector<std::uint8_t> c(48);
  ColorView colour{c.data(), c.size(), 4, 4, 12, ColorEncoding::kBGR8};
  const client::DisparityFrame frame{d, colour};
  const absl::Status s = writer.Write(frame, {}, 0, &bytes);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("disparity"), std::string::npos) << s;
  EXPECT_EQ(s, client::internal::FillImages(frame, v1::StreamRequest().mutable_frame()));
  // The right image of a stereo pair is named as such.
  const absl::Status right = writer.Write(
      client::StereoFrame{colour, ColorView{nullptr, 0, 4, 4, 12, ColorEncoding::kBGR8}}, {}, 0,
      &bytes);
  EXPECT_NE(right.message().find("right"), std::string::npos) << right;
}

}  // namespace
}  // namespace cloudcast
