// The compressed uplink (CompressedDisparity / CompressedColor: a row predictor, then zstd):
//   - the codec and the proto boundary: round trips for every encoding, predictor and odd sizes,
//     padded strides, NaN and infinities bit for bit;
//   - validation: empty, not zstd, truncated, corrupt, trailing bytes, unknown content size,
//     decompression bombs (a few bytes claiming 16k x 16k, a payload larger than its image), wrong
//     sizes, unknown enums, limits; each INVALID_ARGUMENT (RESOURCE_EXHAUSTED for a limit) naming
//     the field, and none growing the decode buffer beyond the image it claims;
//   - a real server on loopback: compressed frames give the same replies (Draco bytes included)
//     as the same frames sent raw, on the New Tsukuba frames (or synthetic ones); a bad payload
//     is answered with its error and the stream goes on; GetInfo lists the compressions.
#include <grpcpp/grpcpp.h>
#include <zstd.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "cloudcast/client/client.h"
#include "cloudcast/core/frame_codec.h"
#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/datasets/tsukuba.h"
#include "cloudcast/proto/convert.h"
#include "cloudcast/server/server.h"
#include "cloudcast/v1/cloudcast.grpc.pb.h"
#include "frame_input.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "support/test_support.h"

namespace cloudcast {
namespace {

using ::testing::HasSubstr;

// ---------------------------------------------------------------------------------------------
// Helpers.

// Packed rows of a view, to compare with what came back.
std::vector<std::uint8_t> Packed(const void* data, std::size_t stride, std::uint32_t width,
                                 std::uint32_t height, std::size_t bpp) {
  std::vector<std::uint8_t> out(std::size_t{width} * height * bpp);
  for (std::uint32_t v = 0; v < height; ++v) {
    std::memcpy(out.data() + v * width * bpp, static_cast<const std::uint8_t*>(data) + v * stride,
                width * bpp);
  }
  return out;
}

template <typename View>
std::vector<std::uint8_t> Packed(const View& v) {
  return Packed(v.data, v.stride_bytes, v.width, v.height, BytesPerPixel(v.encoding));
}

// A zstd frame header by hand (RFC 8878): magic, a descriptor with single-segment and an 8-byte
// content size, then RLE blocks of `blocks` x `block_size` bytes of `value`. A few bytes can
// claim any content size, which is what a bomb does.
std::string HandMadeFrame(std::uint64_t declared, int blocks, std::uint32_t block_size,
                          std::uint8_t value = 0) {
  std::string f = "\x28\xB5\x2F\xFD";
  f.push_back(static_cast<char>(0xE4));  // FCS 8 bytes, single segment, checksum, no dict
  for (int i = 0; i < 8; ++i) f.push_back(static_cast<char>((declared >> (8 * i)) & 0xFF));
  for (int b = 0; b < blocks; ++b) {
    const std::uint32_t last = b == blocks - 1 ? 1 : 0;
    const std::uint32_t header = last | (1u << 1) | (block_size << 3);  // RLE block
    f.push_back(static_cast<char>(header & 0xFF));
    f.push_back(static_cast<char>((header >> 8) & 0xFF));
    f.push_back(static_cast<char>((header >> 16) & 0xFF));
    f.push_back(static_cast<char>(value));
  }
  return f + "\x01\x02\x03\x04";  // a checksum (never reached: the sizes are refused first)
}

v1::CompressedDisparity CompressedU8(std::uint32_t w, std::uint32_t h, std::string payload) {
  v1::CompressedDisparity c;
  c.set_encoding(v1::DISPARITY_U8);
  c.set_width(w);
  c.set_height(h);
  c.set_compression(v1::COMPRESSION_ZSTD);
  c.set_payload(std::move(payload));
  return c;
}

// A real payload: `w` x `h` U8 disparities with some structure.
std::string RealPayload(std::uint32_t w, std::uint32_t h, v1::Compression compression,
                        std::uint8_t seed = 1) {
  std::vector<std::uint8_t> px(std::size_t{w} * h);
  for (std::size_t i = 0; i < px.size(); ++i) px[i] = static_cast<std::uint8_t>(i * seed / 7);
  DisparityView view{px.data(), px.size(), w, h, w, DisparityEncoding::kU8};
  v1::CompressedDisparity c;
  const absl::Status s = convert::ToProto(view, {compression, 1}, "d", &c);
  EXPECT_TRUE(s.ok()) << s;
  return c.payload();
}

absl::Status Decode(const v1::CompressedDisparity& c, PlaneDecompressor* d,
                    const Limits& limits = {}) {
  DisparityView view;
  return convert::DecodeCompressed(c, "frame.disparity.compressed", limits, d, &view);
}

// ---------------------------------------------------------------------------------------------
// Round trips.

struct Size {
  std::uint32_t w, h;
};
const Size kSizes[] = {{1, 1}, {1, 7}, {7, 1}, {3, 5}, {17, 9}, {641, 479}};

TEST(UplinkCodec, EveryDisparityEncodingPredictorAndOddSizeRoundTrips) {
  std::mt19937 rng(7);
  PlaneDecompressor decompressor;
  for (DisparityEncoding e :
       {DisparityEncoding::kU8, DisparityEncoding::kU16, DisparityEncoding::kF32}) {
    for (v1::Compression c : convert::AcceptedCompressions()) {
      for (Size s : kSizes) {
        testing::TestFrame f = testing::RandomFrame(rng, s.w, s.h, e, ColorEncoding::kBGR8, 0,
                                                    e == DisparityEncoding::kU8 ? 255 : 4000);
        if (e == DisparityEncoding::kF32) {  // special values survive bit for bit
          const float special[] = {std::numeric_limits<float>::quiet_NaN(),
                                   std::numeric_limits<float>::infinity(), -0.0f,
                                   -std::numeric_limits<float>::infinity()};
          for (std::uint32_t i = 0; i < 4 && i < s.w; ++i) {
            testing::SetSample<float>(f, i, s.h - 1, special[i]);
          }
        }
        v1::CompressedDisparity msg;
        ASSERT_TRUE(convert::ToProto(f.disparity, {c, 1}, "disparity", &msg).ok());
        EXPECT_EQ(msg.width(), s.w);
        EXPECT_EQ(msg.height(), s.h);
        EXPECT_EQ(msg.encoding(), convert::ToProto(e));
        DisparityView back;
        const absl::Status st = convert::DecodeCompressed(msg, "frame.disparity.compressed",
                                                          Limits{}, &decompressor, &back);
        ASSERT_TRUE(st.ok()) << st << " " << Name(e) << " " << v1::Compression_Name(c) << " " << s.w
                             << "x" << s.h;
        EXPECT_EQ(back.encoding, e);
        EXPECT_EQ(back.width, s.w);
        EXPECT_EQ(back.height, s.h);
        EXPECT_EQ(Packed(back), Packed(f.disparity))
            << Name(e) << " " << v1::Compression_Name(c) << " " << s.w << "x" << s.h;
      }
    }
  }
}

TEST(UplinkCodec, EveryColourEncodingPredictorAndOddSizeRoundTrips) {
  std::mt19937 rng(11);
  PlaneDecompressor decompressor;
  for (ColorEncoding e :
       {ColorEncoding::kBGR8, ColorEncoding::kRGB8, ColorEncoding::kRGBA8, ColorEncoding::kMono8}) {
    for (v1::Compression c : convert::AcceptedCompressions()) {
      for (Size s : kSizes) {
        testing::TestFrame f =
            testing::RandomFrame(rng, s.w, s.h, DisparityEncoding::kU8, e, 0, 255);
        v1::CompressedColor msg;
        for (int level : {-1, 1, 3}) {
          ASSERT_TRUE(convert::ToProto(f.colour, {c, level}, "colour", &msg).ok());
          ColorView back;
          const absl::Status st = convert::DecodeCompressed(msg, "frame.color.compressed", Limits{},
                                                            &decompressor, &back);
          ASSERT_TRUE(st.ok()) << st;
          EXPECT_EQ(back.encoding, e);
          EXPECT_EQ(Packed(back), Packed(f.colour))
              << Name(e) << " " << v1::Compression_Name(c) << " " << s.w << "x" << s.h;
        }
      }
    }
  }
}

TEST(UplinkCodec, PredictorsAreExactInverses) {
  std::mt19937 rng(3);
  for (Predictor p : {Predictor::kNone, Predictor::kUp, Predictor::kLeft}) {
    for (PlaneLayout l :
         {PlaneLayout{13, 7, 1, 1}, PlaneLayout{13, 7, 3, 1}, PlaneLayout{13, 7, 4, 1},
          PlaneLayout{5, 9, 2, 2}, PlaneLayout{5, 9, 4, 4}}) {
      std::vector<std::uint8_t> in(l.bytes()), out(l.bytes());
      for (auto& b : in) b = static_cast<std::uint8_t>(rng());
      ApplyPredictor(p, l, in.data(), l.width * l.bpp, out.data());
      UndoPredictor(p, l, out.data());
      EXPECT_EQ(out, in) << Name(p) << " bpp " << l.bpp;
    }
  }
}

TEST(UplinkCodec, DefaultIsRowDeltasAtLevelOneAndCompressesCameraImages) {
  const convert::Compression z;
  EXPECT_EQ(z.codec, v1::COMPRESSION_ZSTD_DELTA_ROWS);
  EXPECT_EQ(z.level, 1);
  // The synthetic scene's 8-bit frame: smooth surfaces, as a camera's.
  SyntheticOptions o;
  o.disparity_encoding = DisparityEncoding::kU8;
  auto r = SyntheticScene::Default().Render(o);
  ASSERT_TRUE(r.ok());
  DisparityView d{r->disparity.data(),   r->disparity.size(), o.width, o.height, o.width,
                  DisparityEncoding::kU8};
  ColorView c{r->colour.data(), r->colour.size(), o.width,
              o.height,         o.width * 3,      ColorEncoding::kBGR8};
  v1::CompressedDisparity cd;
  v1::CompressedColor cc;
  ASSERT_TRUE(convert::ToProto(d, z, "disparity", &cd).ok());
  ASSERT_TRUE(convert::ToProto(c, z, "colour", &cc).ok());
  EXPECT_LT(cd.payload().size() + cc.payload().size(), (d.size_bytes + c.size_bytes) * 4 / 10);
}

// ---------------------------------------------------------------------------------------------
// Validation: what the server sees from a hostile or broken client.

TEST(UplinkValidation, BombClaimingSixteenKSquaredInAFewBytesIsRefusedBeforeAllocating) {
  PlaneDecompressor d;
  // 16384 x 16384 x 3 bytes claimed by an 18-byte frame, sent for a 640x480 image.
  const std::uint64_t huge = std::uint64_t{16384} * 16384 * 3;
  v1::CompressedColor c;
  c.set_encoding(v1::COLOR_BGR8);
  c.set_width(640);
  c.set_height(480);
  c.set_compression(v1::COMPRESSION_ZSTD_DELTA_ROWS);
  c.set_payload(HandMadeFrame(huge, 1, 1));
  EXPECT_LT(c.payload().size(), 32u);
  ColorView view;
  const absl::Status s =
      convert::DecodeCompressed(c, "frame.color.compressed", Limits{}, &d, &view);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(s.message(),
            "frame.color.compressed.payload decompresses to 805306368 bytes; 640x480 COLOR_BGR8 "
            "needs 921600");
  EXPECT_EQ(d.capacity(), 0u) << "nothing may be allocated for a refused payload";
}

TEST(UplinkValidation, SixteenKSquaredImageInTheMessageIsOverTheLimits) {
  // The same claim in width and height: over max_pixels, refused as every image over the limits
  // is (RESOURCE_EXHAUSTED, ServerLimits), before the payload is looked at.
  PlaneDecompressor d;
  const absl::Status s =
      Decode(CompressedU8(16384, 16384, HandMadeFrame(std::uint64_t{16384} * 16384, 1, 1)), &d);
  EXPECT_EQ(s.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(std::string(s.message()), HasSubstr("frame.disparity.compressed is 16384x16384"));
  EXPECT_EQ(d.capacity(), 0u);
}

TEST(UplinkValidation, PayloadOfAnotherSizeThanItsImageIsRefused) {
  PlaneDecompressor d;
  // Larger: a real 640x481 image sent as 640x480.
  absl::Status s = Decode(CompressedU8(640, 480, RealPayload(640, 481, v1::COMPRESSION_ZSTD)), &d);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(s.message(),
            "frame.disparity.compressed.payload decompresses to 307840 bytes; 640x480 "
            "DISPARITY_U8 needs 307200");
  // Smaller.
  s = Decode(CompressedU8(640, 480, RealPayload(320, 240, v1::COMPRESSION_ZSTD)), &d);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), HasSubstr("decompresses to 76800 bytes"));
  // The right size for another encoding is still the wrong size.
  v1::CompressedDisparity u16 = CompressedU8(640, 480, RealPayload(640, 480, v1::COMPRESSION_ZSTD));
  u16.set_encoding(v1::DISPARITY_U16);
  s = Decode(u16, &d);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), HasSubstr("640x480 DISPARITY_U16 needs 614400"));
  EXPECT_EQ(d.capacity(), 0u);
}

TEST(UplinkValidation, HeaderThatUnderstatesItsBlocksNeverWritesPastTheImage) {
  // Declares exactly the image (307200 bytes) but its blocks hold 393216: the decoder is given a
  // buffer of exactly 307200 and refuses the rest.
  PlaneDecompressor d;
  const absl::Status s = Decode(CompressedU8(640, 480, HandMadeFrame(307200, 3, 131072)), &d);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), HasSubstr("frame.disparity.compressed.payload is corrupt"));
  EXPECT_EQ(d.capacity(), 307200u);
}

TEST(UplinkValidation, TruncatedPayloadIsRefusedBeforeAllocating) {
  const std::string whole = RealPayload(640, 480, v1::COMPRESSION_ZSTD_DELTA_ROWS, 3);
  for (std::size_t keep :
       {std::size_t{1}, std::size_t{4}, std::size_t{12}, whole.size() / 2, whole.size() - 1}) {
    PlaneDecompressor d;
    const absl::Status s = Decode(CompressedU8(640, 480, whole.substr(0, keep)), &d);
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << keep;
    EXPECT_THAT(std::string(s.message()), HasSubstr("frame.disparity.compressed.payload"));
    EXPECT_EQ(d.capacity(), 0u) << keep;
  }
}

TEST(UplinkValidation, EmptyForeignTrailingAndSizelessPayloadsAreRefused) {
  PlaneDecompressor d;
  absl::Status s = Decode(CompressedU8(4, 4, ""), &d);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(s.message(), "frame.disparity.compressed.payload is empty");

  s = Decode(CompressedU8(4, 4, std::string("\x89PNG\r\n\x1a\n....", 12)), &d);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()),
              HasSubstr("frame.disparity.compressed.payload is not a zstd frame"));

  s = Decode(CompressedU8(640, 480, RealPayload(640, 480, v1::COMPRESSION_ZSTD) + "x"), &d);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), HasSubstr("it must be one frame alone"));

  // Two frames back to back (each the right size) are not one image.
  const std::string one = RealPayload(640, 480, v1::COMPRESSION_ZSTD);
  s = Decode(CompressedU8(640, 480, one + one), &d);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);

  // A frame of the right size without the content checksum the protocol requires.
  {
    std::vector<std::uint8_t> px(640 * 480, 9);
    std::string plain(ZSTD_compressBound(px.size()), '\0');
    plain.resize(ZSTD_compress(plain.data(), plain.size(), px.data(), px.size(), 1));
    s = Decode(CompressedU8(640, 480, plain), &d);
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(std::string(s.message()), HasSubstr("without a content checksum"));
  }

  // A streaming zstd frame that does not declare its size.
  std::vector<std::uint8_t> px(64, 5);
  std::string sizeless(ZSTD_compressBound(px.size()) + 64, '\0');
  ZSTD_CCtx* cctx = ZSTD_createCCtx();
  ZSTD_CCtx_setParameter(cctx, ZSTD_c_contentSizeFlag, 0);
  ZSTD_outBuffer out{sizeless.data(), sizeless.size(), 0};
  ZSTD_inBuffer in{px.data(), px.size(), 0};
  ASSERT_EQ(ZSTD_compressStream2(cctx, &out, &in, ZSTD_e_end), 0u);
  ZSTD_freeCCtx(cctx);
  sizeless.resize(out.pos);
  s = Decode(CompressedU8(8, 8, sizeless), &d);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), HasSubstr("does not declare its content size"));
  EXPECT_EQ(d.capacity(), 0u);
}

TEST(UplinkValidation, CorruptPayloadsNeverCrashNorGrowPastTheirImage) {
  const std::string whole = RealPayload(200, 100, v1::COMPRESSION_ZSTD_DELTA_ROWS, 5);
  std::mt19937 rng(42);
  int refused = 0;
  for (int i = 0; i < 300; ++i) {
    std::string bad = whole;
    const int flips = 1 + static_cast<int>(rng() % 8);
    for (int k = 0; k < flips; ++k) bad[rng() % bad.size()] ^= static_cast<char>(1 + rng() % 255);
    PlaneDecompressor d;
    const absl::Status s = Decode(CompressedU8(200, 100, bad), &d);
    // Even a flip inside the literals, which decodes to other pixels, fails the checksum.
    if (!s.ok()) {
      ++refused;
      EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
      EXPECT_THAT(std::string(s.message()), HasSubstr("frame.disparity.compressed.payload"));
    }
    EXPECT_LE(d.capacity(), 200u * 100u);
  }
  EXPECT_EQ(refused, 300);
}

TEST(UplinkValidation, UnknownEnumsAndZeroSizesNameTheirField) {
  PlaneDecompressor d;
  v1::CompressedDisparity c = CompressedU8(4, 4, RealPayload(4, 4, v1::COMPRESSION_ZSTD));
  c.set_compression(v1::COMPRESSION_UNSPECIFIED);
  absl::Status s = Decode(c, &d);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()),
              HasSubstr("frame.disparity.compressed.compression is COMPRESSION_UNSPECIFIED"));
  c.set_compression(static_cast<v1::Compression>(77));
  s = Decode(c, &d);
  EXPECT_THAT(std::string(s.message()), HasSubstr("frame.disparity.compressed.compression is 77"));

  c = CompressedU8(4, 4, RealPayload(4, 4, v1::COMPRESSION_ZSTD));
  c.set_encoding(v1::DISPARITY_ENCODING_UNSPECIFIED);
  s = Decode(c, &d);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), HasSubstr("frame.disparity.compressed.encoding"));

  c = CompressedU8(0, 4, RealPayload(4, 4, v1::COMPRESSION_ZSTD));
  s = Decode(c, &d);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), HasSubstr("frame.disparity.compressed.width is 0"));

  Limits small;
  small.max_side = 100;
  s = Decode(CompressedU8(101, 4, RealPayload(101, 4, v1::COMPRESSION_ZSTD)), &d, small);
  EXPECT_EQ(s.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_EQ(d.capacity(), 0u);

  // The client side refuses an unknown compression too, naming its own field.
  std::vector<std::uint8_t> px(16, 1);
  DisparityView view{px.data(), px.size(), 4, 4, 4, DisparityEncoding::kU8};
  v1::CompressedDisparity out;
  s = convert::ToProto(view, {v1::COMPRESSION_UNSPECIFIED, 1}, "disparity", &out);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), HasSubstr("disparity.compression"));
}

TEST(UplinkValidation, DecodeBufferIsReusedOnceWarm) {
  PlaneDecompressor d;
  const v1::CompressedDisparity c =
      CompressedU8(640, 480, RealPayload(640, 480, v1::COMPRESSION_ZSTD_DELTA_ROWS));
  ASSERT_TRUE(Decode(c, &d).ok());
  const std::size_t warm = d.capacity();
  EXPECT_EQ(warm, 640u * 480u);
  DisparityView first, second;
  ASSERT_TRUE(convert::DecodeCompressed(c, "f", Limits{}, &d, &first).ok());
  ASSERT_TRUE(convert::DecodeCompressed(c, "f", Limits{}, &d, &second).ok());
  EXPECT_EQ(first.data, second.data);
  EXPECT_EQ(d.capacity(), warm);
}

TEST(UplinkValidation, ServerFrameInputDecodesAndNamesTheField) {
  // The server's frame input (what a worker runs): compressed and raw images mix freely.
  std::mt19937 rng(5);
  testing::TestFrame f =
      testing::RandomFrame(rng, 31, 17, DisparityEncoding::kU16, ColorEncoding::kRGB8, 0, 900);
  v1::Frame frame;
  ASSERT_TRUE(convert::ToProto(f.disparity, {}, "disparity",
                               frame.mutable_disparity()->mutable_compressed())
                  .ok());
  ASSERT_TRUE(convert::ToProto(f.colour, "colour", frame.mutable_color()->mutable_raw()).ok());
  server::DecodeScratch scratch;
  server::FrameImages images;
  ASSERT_TRUE(server::PrepareFrameImages(frame, Limits{}, &scratch, &images).ok());
  EXPECT_TRUE(images.decoded);
  EXPECT_EQ(Packed(images.disparity), Packed(f.disparity));
  EXPECT_EQ(Packed(images.colour), Packed(f.colour));

  frame.mutable_color()->mutable_compressed()->set_payload("garbage");
  frame.mutable_color()->mutable_compressed()->set_width(31);
  frame.mutable_color()->mutable_compressed()->set_height(17);
  frame.mutable_color()->mutable_compressed()->set_encoding(v1::COLOR_RGB8);
  frame.mutable_color()->mutable_compressed()->set_compression(v1::COMPRESSION_ZSTD);
  const absl::Status s = server::PrepareFrameImages(frame, Limits{}, &scratch, &images);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()),
              HasSubstr("frame.color.compressed.payload is not a zstd frame"));
}

// ---------------------------------------------------------------------------------------------
// A real server on loopback.

class UplinkServerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    server::ServerOptions options;
    EXPECT_TRUE(ApplyPreset("new_tsukuba", &options.defaults.frame).ok());  // camera-less frames
    options.listen = "127.0.0.1:0";
    options.metrics_listen = "";
    options.threads = 2;
    auto s = server::Server::Start(options);
    ASSERT_TRUE(s.ok()) << s.status();
    server_ = s->release();
    auto c = client::Client::Connect("127.0.0.1:" + std::to_string(server_->port()));
    ASSERT_TRUE(c.ok()) << c.status();
    client_ = c->release();
  }
  static void TearDownTestSuite() {
    delete client_;
    client_ = nullptr;
    if (server_ != nullptr) server_->Shutdown();
    delete server_;
    server_ = nullptr;
  }

  struct Frame {
    OwnedDisparity disparity;
    OwnedColor colour;
  };
  // The New Tsukuba frames when present, else synthetic frames of the same size and kind.
  static std::vector<Frame> Frames() {
    std::vector<Frame> frames;
    if (auto all = tsukuba::LoadAll(tsukuba::DefaultDir()); all.ok()) {
      for (auto& t : *all) frames.push_back({std::move(t.disparity), std::move(t.colour)});
      return frames;
    }
    for (std::uint64_t i = 0; i < 4; ++i) {
      SyntheticOptions o;
      o.frame = i * 40;
      o.disparity_encoding = DisparityEncoding::kU8;
      auto r = SyntheticScene::Default().Render(o);
      frames.push_back(
          {OwnedDisparity{std::move(r->disparity), o.width, o.height, DisparityEncoding::kU8},
           OwnedColor{std::move(r->colour), o.width, o.height, ColorEncoding::kBGR8}});
    }
    return frames;
  }

  static server::Server* server_;
  static client::Client* client_;
};
server::Server* UplinkServerTest::server_ = nullptr;
client::Client* UplinkServerTest::client_ = nullptr;

// The reply's deterministic part: the cloud and what the server counted.
void ExpectSameCloud(const v1::CloudReply& raw, const v1::CloudReply& compressed) {
  EXPECT_EQ(raw.point_count(), compressed.point_count());
  EXPECT_EQ(raw.counts().SerializeAsString(), compressed.counts().SerializeAsString());
  EXPECT_EQ(raw.position_bits(), compressed.position_bits());
  EXPECT_TRUE(raw.draco() == compressed.draco()) << "Draco bytes differ";
}

TEST_F(UplinkServerTest, CompressedFramesGiveTheRawFramesCloudsExactly) {
  const std::vector<Frame> frames = Frames();
  const client::StreamConfig config = client::MakeStreamConfig(PipelineOptions{});
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const Frame& f = frames[i];
    auto raw = client_->Process(f.disparity.view(), f.colour.view(), config);
    ASSERT_TRUE(raw.ok()) << raw.status();
    for (v1::Compression c : convert::AcceptedCompressions()) {
      auto z = client_->Process(client::Compressed(f.disparity.view(), {c, 1}),
                                client::Compressed(f.colour.view(), {c, 1}), config);
      ASSERT_TRUE(z.ok()) << z.status();
      ExpectSameCloud(raw->reply, z->reply);
      EXPECT_GT(z->reply.times().decode_us(), 0u);
    }
    // Mixed: one image compressed, the other raw.
    auto mixed = client_->Process(f.disparity.view(), client::Compressed(f.colour.view()), config);
    ASSERT_TRUE(mixed.ok()) << mixed.status();
    ExpectSameCloud(raw->reply, mixed->reply);
  }
}

TEST_F(UplinkServerTest, StreamedCompressedSequenceMatchesRawAndSendsUnderFortyPercent) {
  const std::vector<Frame> frames = Frames();
  client::StreamConfig config = client::MakeStreamConfig(PipelineOptions{});
  config.set_delivery(v1::DELIVERY_ALL);
  auto run = [&](bool compress) {
    std::vector<client::Result> results;
    client::StreamOptions options;  // every reply delivered before Finish returns
    options.on_result = [&](client::Result&& r) { results.push_back(std::move(r)); };
    auto stream = client_->OpenStream(config, options);
    EXPECT_TRUE(stream.ok()) << stream.status();
    if (!stream.ok()) return results;
    for (std::size_t i = 0; i < frames.size(); ++i) {
      const Frame& f = frames[i];
      const absl::Status s = compress ? (*stream)->Send(client::Compressed(f.disparity.view()),
                                                        client::Compressed(f.colour.view()))
                                      : (*stream)->Send(f.disparity.view(), f.colour.view());
      EXPECT_TRUE(s.ok()) << s;
    }
    const absl::Status done = (*stream)->Finish();
    EXPECT_TRUE(done.ok()) << done;
    if (compress) {
      EXPECT_LT((*stream)->image_bytes_sent(), frames.size() * 1228800 * 4 / 10);
    }
    return results;
  };
  const std::vector<client::Result> raw = run(false);
  const std::vector<client::Result> compressed = run(true);
  ASSERT_EQ(raw.size(), frames.size());
  ASSERT_EQ(compressed.size(), frames.size());
  for (std::size_t i = 0; i < frames.size(); ++i) {
    ASSERT_TRUE(raw[i].ok() && compressed[i].ok()) << raw[i].status << compressed[i].status;
    ExpectSameCloud(raw[i].reply, compressed[i].reply);
  }
}

TEST_F(UplinkServerTest, BadPayloadsAreAnsweredNamingTheFieldAndTheStreamGoesOn) {
  const std::vector<Frame> frames = Frames();
  const Frame& f = frames[0];
  client::StreamConfig config = client::MakeStreamConfig(PipelineOptions{});
  config.set_delivery(v1::DELIVERY_ALL);
  std::vector<client::Result> results;
  client::StreamOptions options;
  options.on_result = [&](client::Result&& r) { results.push_back(std::move(r)); };
  auto stream = client_->OpenStream(config, options);
  ASSERT_TRUE(stream.ok()) << stream.status();
  // The bad frames are built by hand: the client library only ever sends good payloads.
  v1::CompressedDisparity good;
  ASSERT_TRUE(convert::ToProto(f.disparity.view(), {}, "d", &good).ok());
  struct Bad {
    std::string payload;
    std::string expect;
  };
  const std::vector<Bad> bad = {
      {HandMadeFrame(std::uint64_t{16384} * 16384, 1, 1),
       "frame.disparity.compressed.payload decompresses to 268435456 bytes"},
      {good.payload().substr(0, good.payload().size() / 2),
       "frame.disparity.compressed.payload is truncated or corrupt"},
      {"not zstd at all", "frame.disparity.compressed.payload is not a zstd frame"},
  };
  // Sent through Process: each is one call with the status naming the field.
  for (const Bad& b : bad) {
    v1::ProcessRequest request;
    v1::CompressedDisparity* c = request.mutable_frame()->mutable_disparity()->mutable_compressed();
    *c = good;
    c->set_payload(b.payload);
    ASSERT_TRUE(convert::ToProto(f.colour.view(), "colour",
                                 request.mutable_frame()->mutable_color()->mutable_raw())
                    .ok());
    grpc::ClientContext context;
    v1::CloudReply reply;
    auto channel = grpc::CreateChannel("127.0.0.1:" + std::to_string(server_->port()),
                                       grpc::InsecureChannelCredentials());
    auto stub = v1::CloudCast::NewStub(channel);
    const grpc::Status s = stub->Process(&context, request, &reply);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
    EXPECT_THAT(s.error_message(), HasSubstr(b.expect));
  }
  // And on a stream: the good frame after a bad one is answered.
  ASSERT_TRUE((*stream)
                  ->Send(client::Compressed(f.disparity.view()),
                         client::EncodedImage{"definitely not an image"})
                  .ok());
  ASSERT_TRUE(
      (*stream)
          ->Send(client::Compressed(f.disparity.view()), client::Compressed(f.colour.view()))
          .ok());
  EXPECT_TRUE((*stream)->Finish().ok());
  ASSERT_EQ(results.size(), 2u);
  EXPECT_EQ(results[0].status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(results[1].ok()) << results[1].status;
}

TEST_F(UplinkServerTest, GetInfoListsTheCompressions) {
  auto info = client_->GetInfo();
  ASSERT_TRUE(info.ok()) << info.status();
  ASSERT_EQ(info->compressions_size(), 3);
  EXPECT_EQ(info->compressions(0), v1::COMPRESSION_ZSTD);
  EXPECT_EQ(info->compressions(1), v1::COMPRESSION_ZSTD_DELTA_ROWS);
  EXPECT_EQ(info->compressions(2), v1::COMPRESSION_ZSTD_DELTA_LEFT);
}

}  // namespace
}  // namespace cloudcast
