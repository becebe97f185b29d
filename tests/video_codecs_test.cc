// The codecs cloudcast-video-bench measures against H.264 (video/codecs.h): each opens at its
// low-latency settings, codes a small moving synthetic sequence picture by picture (nothing held
// back), and decodes it back within a PSNR bound; lossless is bit-exact where the codec has it;
// wrong options are refused naming the field; and the server's decoder (video::Decoder, H.264
// only) refuses the other codecs' bitstreams. A codec whose encoder or decoder this FFmpeg build
// lacks is skipped, saying which.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "cloudcast/video/codecs.h"
#include "cloudcast/video/decoder.h"

namespace cloudcast::video {
namespace {

constexpr std::uint32_t kW = 192, kH = 128;

// Picture `f` of a scene that moves: a smooth gradient, a textured square sliding right,
// noise-free.
std::vector<std::uint8_t> Grey(int f) {
  std::vector<std::uint8_t> p(std::size_t{kW} * kH);
  for (std::uint32_t y = 0; y < kH; ++y) {
    for (std::uint32_t x = 0; x < kW; ++x) {
      int v = static_cast<int>(40 + x / 2 + y / 3);
      const int sx = static_cast<int>(x) - 30 - 3 * f, sy = static_cast<int>(y) - 40;
      if (sx >= 0 && sx < 48 && sy >= 0 && sy < 48) v = ((sx / 6 + sy / 6) % 2) ? 220 : 60;
      p[std::size_t{y} * kW + x] = static_cast<std::uint8_t>(v);
    }
  }
  return p;
}
std::vector<std::uint8_t> Colour(int f) {  // BGR
  const std::vector<std::uint8_t> g = Grey(f);
  std::vector<std::uint8_t> p(g.size() * 3);
  for (std::size_t i = 0; i < g.size(); ++i) {
    p[3 * i] = g[i];
    p[3 * i + 1] = static_cast<std::uint8_t>(255 - g[i]);
    p[3 * i + 2] = static_cast<std::uint8_t>((g[i] / 2 + 64));
  }
  return p;
}
ColorView View(const std::vector<std::uint8_t>& p, ColorEncoding e) {
  ColorView v;
  v.data = p.data();
  v.size_bytes = p.size();
  v.width = kW;
  v.height = kH;
  v.stride_bytes = kW * BytesPerPixel(e);
  v.encoding = e;
  return v;
}
double Psnr(const std::vector<std::uint8_t>& a, const ColorView& b) {
  double se = 0;
  const auto* q = static_cast<const std::uint8_t*>(b.data);
  for (std::size_t i = 0; i < a.size(); ++i) se += (a[i] - q[i]) * double(a[i] - q[i]);
  if (se == 0) return 99;
  return 10 * std::log10(255.0 * 255.0 * a.size() / se);
}

// A middle quality on each codec's own scale.
double MidCrf(const CodecInfo& c) { return c.max_crf > 51 ? 32 : 22; }

EncoderOptions Options(const CodecInfo& c, PictureKind kind) {
  EncoderOptions o;
  o.kind = kind;
  o.width = kW;
  o.height = kH;
  o.preset = c.codec == Codec::kVp9 ? "8" : c.codec == Codec::kAv1 ? "9" : "ultrafast";
  o.crf = MidCrf(c);
  o.bitrate_bps = 0;
  o.keyframe_interval = 4;  // keyframes mid-sequence too
  return o;
}

class CodecsTest : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    info_ = FindCodec(GetParam());
    ASSERT_NE(info_, nullptr) << GetParam();
    if (!Available(info_->codec)) {
      GTEST_SKIP() << "this FFmpeg build has no " << info_->encoder << " encoder or no "
                   << info_->decoder << " decoder: " << info_->label << " not tested";
    }
  }
  const CodecInfo* info_ = nullptr;
};

TEST_P(CodecsTest, GreySequenceRoundTripsPictureByPicture) {
  auto stream =
      CodecStream::Open(info_->codec, Options(*info_, PictureKind::kGrey), ColorEncoding::kMono8);
  ASSERT_TRUE(stream.ok()) << stream.status();
  std::string bytes;
  std::size_t total = 0;
  for (int f = 0; f < 10; ++f) {
    const std::vector<std::uint8_t> img = Grey(f);
    ASSERT_TRUE((*stream)->Encode(View(img, ColorEncoding::kMono8), "left", &bytes).ok()) << f;
    ASSERT_FALSE(bytes.empty()) << f;
    total += bytes.size();
    ColorView out;
    const absl::Status s = (*stream)->Decode(bytes, "left", &out);
    ASSERT_TRUE(s.ok()) << f << ": " << s;
    ASSERT_EQ(out.width, kW);
    ASSERT_EQ(out.encoding, ColorEncoding::kMono8);
    EXPECT_GT(Psnr(img, out), 34.0) << info_->label << " picture " << f;
  }
  EXPECT_LT(total, 10u * kW * kH / 4) << "under a quarter of the raw bytes";
}

TEST_P(CodecsTest, ColourSequenceRoundTrips) {
  for (PictureKind kind : {PictureKind::kColour, PictureKind::kColour444}) {
    if (kind == PictureKind::kColour444 && !info_->colour444) continue;
    auto stream = CodecStream::Open(info_->codec, Options(*info_, kind), ColorEncoding::kBGR8);
    ASSERT_TRUE(stream.ok()) << stream.status();
    std::string bytes;
    for (int f = 0; f < 6; ++f) {
      const std::vector<std::uint8_t> img = Colour(f);
      ASSERT_TRUE((*stream)->Encode(View(img, ColorEncoding::kBGR8), "colour", &bytes).ok());
      ColorView out;
      ASSERT_TRUE((*stream)->Decode(bytes, "colour", &out).ok()) << f;
      ASSERT_EQ(out.encoding, ColorEncoding::kBGR8);
      // 4:2:0 loses chroma detail at the square's saturated edges before any coding (25 dB).
      EXPECT_GT(Psnr(img, out), kind == PictureKind::kColour ? 22.0 : 32.0)
          << info_->label << " " << Name(kind) << " picture " << f;
    }
  }
}

TEST_P(CodecsTest, LosslessIsBitExactWhereOffered) {
  EncoderOptions o = Options(*info_, PictureKind::kGrey);
  o.crf = 0;
  o.qp = 0;
  auto stream = CodecStream::Open(info_->codec, o, ColorEncoding::kMono8);
  if (!info_->lossless) {
    ASSERT_FALSE(stream.ok());
    EXPECT_NE(std::string(stream.status().message()).find("options.qp"), std::string::npos)
        << stream.status();
    return;
  }
  ASSERT_TRUE(stream.ok()) << stream.status();
  std::string bytes;
  for (int f = 0; f < 4; ++f) {
    const std::vector<std::uint8_t> img = Grey(f);
    ASSERT_TRUE((*stream)->Encode(View(img, ColorEncoding::kMono8), "left", &bytes).ok());
    ColorView out;
    ASSERT_TRUE((*stream)->Decode(bytes, "left", &out).ok());
    EXPECT_EQ(Psnr(img, out), 99) << info_->label << " picture " << f;
  }
}

TEST_P(CodecsTest, BitrateModeKeepsNearItsBudget) {
  EncoderOptions o = Options(*info_, PictureKind::kGrey);
  o.crf = 0;
  o.bitrate_bps = 600'000;  // 2,500 bytes a picture at 30 fps
  auto stream = CodecStream::Open(info_->codec, o, ColorEncoding::kMono8);
  ASSERT_TRUE(stream.ok()) << stream.status();
  std::string bytes;
  std::size_t after_first = 0;
  for (int f = 0; f < 12; ++f) {
    const std::vector<std::uint8_t> img = Grey(f);
    ASSERT_TRUE((*stream)->Encode(View(img, ColorEncoding::kMono8), "left", &bytes).ok());
    if (f > 0 && f % 4 != 0) after_first += bytes.size();  // the predicted pictures
    ColorView out;
    ASSERT_TRUE((*stream)->Decode(bytes, "left", &out).ok());
  }
  EXPECT_LT(after_first / 8.0, 3 * 2500.0) << info_->label;
}

TEST_P(CodecsTest, RefusesWrongOptionsNamingTheField) {
  EncoderOptions o = Options(*info_, PictureKind::kGrey);
  o.preset = "nonsense";
  auto s = CodecStream::Open(info_->codec, o, ColorEncoding::kMono8);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(std::string(s.status().message()).find("preset"), std::string::npos) << s.status();
  o = Options(*info_, PictureKind::kGrey);
  o.crf = info_->max_crf + 1;
  s = CodecStream::Open(info_->codec, o, ColorEncoding::kMono8);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(std::string(s.status().message()).find("options.crf"), std::string::npos) << s.status();
  o = Options(*info_, PictureKind::kGrey);
  o.width = 191;
  s = CodecStream::Open(info_->codec, o, ColorEncoding::kMono8);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(std::string(s.status().message()).find("options.width"), std::string::npos)
      << s.status();
}

// The server decodes H.264 alone: another codec's first picture is refused, never decoded.
TEST_P(CodecsTest, TheServersDecoderRefusesOtherCodecs) {
  if (info_->codec == Codec::kH264) GTEST_SKIP() << "H.264 is the contract's codec";
  auto stream =
      CodecStream::Open(info_->codec, Options(*info_, PictureKind::kGrey), ColorEncoding::kMono8);
  ASSERT_TRUE(stream.ok()) << stream.status();
  std::string bytes;
  const std::vector<std::uint8_t> img = Grey(0);
  ASSERT_TRUE((*stream)->Encode(View(img, ColorEncoding::kMono8), "left", &bytes).ok());
  Decoder server(Decoder::Options{});
  ColorView out;
  const absl::Status s = server.Decode(bytes, "frame.video.left.access_unit", &out);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << info_->label << ": " << s;
  EXPECT_FALSE(server.opened()) << "libavcodec's H.264 decoder never saw the bytes";
}

INSTANTIATE_TEST_SUITE_P(Codecs, CodecsTest, ::testing::Values("h264", "hevc", "vp9", "av1"),
                         [](const auto& info) { return info.param; });

TEST(CodecsTable, KeysAreDistinctAndH264First) {
  ASSERT_FALSE(Codecs().empty());
  EXPECT_EQ(Codecs().front().codec, Codec::kH264);
  for (const CodecInfo& c : Codecs()) {
    EXPECT_EQ(FindCodec(c.key), &c);
    EXPECT_EQ(&Info(c.codec), &c);
  }
  EXPECT_EQ(FindCodec("mpeg2"), nullptr);
}

}  // namespace
}  // namespace cloudcast::video
