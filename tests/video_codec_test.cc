// The video codec layer (video/): real libx264 output decoded by libavcodec's own H.264 decoder,
// and every bad input the server must survive, each a per-frame error naming the field after
// which the stream goes on at the next IDR.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <malloc.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/datasets/tsukuba.h"
#include "cloudcast/io/image_io.h"
#include "cloudcast/stereo/evaluation.h"
#include "cloudcast/stereo/grey.h"
#include "cloudcast/stereo/matcher.h"
#include "cloudcast/video/decoder.h"
#include "cloudcast/video/encoder.h"
#include "cloudcast/video/h264_bitstream.h"
#include "cloudcast/video/rvl.h"
#include "support/h264_sps.h"
#include "support/test_support.h"

namespace cloudcast::video {
namespace {

using cloudcast::testing::Sps;
using ::testing::HasSubstr;

// Consecutive frames of the synthetic scene (its camera moves frame to frame), grey or BGR.
std::vector<OwnedColor> Frames(std::uint32_t w, std::uint32_t h, int count, bool grey,
                               int first = 0) {
  const SyntheticScene scene = SyntheticScene::Default();
  std::vector<OwnedColor> out;
  for (int i = 0; i < count; ++i) {
    SyntheticOptions o;
    o.width = w;
    o.height = h;
    o.frame = static_cast<std::uint64_t>(first + i);
    auto f = scene.Render(o);
    EXPECT_TRUE(f.ok()) << f.status();
    OwnedColor c;
    c.pixels = f->colour;
    c.width = w;
    c.height = h;
    c.encoding = ColorEncoding::kBGR8;
    out.push_back(grey ? *stereo::ToGrey(c.view()) : c);
  }
  return out;
}

double Psnr(const ColorView& a, const ColorView& b) {
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  const std::size_t row = a.width * BytesPerPixel(a.encoding);
  double se = 0;
  for (std::uint32_t v = 0; v < a.height; ++v) {
    for (std::size_t i = 0; i < row; ++i) {
      const double d = static_cast<double>(a.row(v)[i]) - static_cast<double>(b.row(v)[i]);
      se += d * d;
    }
  }
  const double mse = se / (double(row) * a.height);
  return mse == 0 ? 99.0 : 10 * std::log10(255.0 * 255.0 / mse);
}

EncoderOptions Options(PictureKind kind, std::uint32_t w, std::uint32_t h) {
  EncoderOptions o;
  o.kind = kind;
  o.width = w;
  o.height = h;
  o.crf = 18;
  o.bitrate_bps = 0;
  return o;
}

std::vector<EncodedPicture> Encode(const EncoderOptions& options,
                                   const std::vector<OwnedColor>& frames,
                                   const std::vector<int>& keyframes = {}) {
  auto enc = Encoder::Make(options);
  EXPECT_TRUE(enc.ok()) << enc.status();
  std::vector<EncodedPicture> out;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    FrameControl control;
    for (int k : keyframes) control.keyframe |= static_cast<std::size_t>(k) == i;
    EncodedPicture p;
    const absl::Status s = (*enc)->Encode(frames[i].view(), control, "frame", &p);
    EXPECT_TRUE(s.ok()) << s;
    out.push_back(std::move(p));
  }
  return out;
}

Decoder::Options DecoderOptions(ColorEncoding output = ColorEncoding::kMono8) {
  Decoder::Options o;
  o.output = output;
  return o;
}

// --- the codec on real frames
// ---------------------------------------------------------------------

TEST(VideoCodec, GreyRoundTripIsOnePictureInOneOut) {
  const auto frames = Frames(320, 240, 8, /*grey=*/true);
  const auto units = Encode(Options(PictureKind::kGrey, 320, 240), frames);
  Decoder decoder(DecoderOptions());
  for (std::size_t i = 0; i < units.size(); ++i) {
    EXPECT_EQ(units[i].index, static_cast<std::int64_t>(i));
    EXPECT_EQ(units[i].keyframe, i == 0) << i;
    ColorView out;
    ASSERT_TRUE(decoder.Decode(units[i].bytes, "au", &out).ok()) << i;
    EXPECT_EQ(out.encoding, ColorEncoding::kMono8);
    EXPECT_GT(Psnr(out, frames[i].view()), 38.0) << i;  // crf 18
  }
  // Luma only: the grey stream's SPS says 4:0:0.
  auto info = InspectAccessUnit(units[0].bytes, "au", Limits{});
  ASSERT_TRUE(info.ok());
  ASSERT_TRUE(info->sps.has_value());
  EXPECT_EQ(info->sps->chroma_format_idc, 0u);
  EXPECT_EQ(info->sps->width, 320u);
  EXPECT_EQ(info->sps->height, 240u);
  EXPECT_TRUE(info->idr);
  // Consecutive frames cost less than the IDR: prediction works.
  EXPECT_LT(units[3].bytes.size(), units[0].bytes.size());
}

TEST(VideoCodec, ColourRoundTripBgr) {
  const auto frames = Frames(320, 240, 5, /*grey=*/false);
  const auto units = Encode(Options(PictureKind::kColour, 320, 240), frames);
  Decoder decoder(DecoderOptions(ColorEncoding::kBGR8));
  for (std::size_t i = 0; i < units.size(); ++i) {
    ColorView out;
    ASSERT_TRUE(decoder.Decode(units[i].bytes, "au", &out).ok()) << i;
    EXPECT_EQ(out.encoding, ColorEncoding::kBGR8);
    EXPECT_GT(Psnr(out, frames[i].view()), 26.0) << i;  // 4:2:0's own ceiling here: 27.9 dB
  }
  auto info = InspectAccessUnit(units[0].bytes, "au", Limits{});
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info->sps->chroma_format_idc, 1u);
}

// 4:2:0 alone caps the synthetic scene's colour near 28 dB (its textures change colour pixel to
// pixel); 4:4:4 keeps it.
TEST(VideoCodec, Colour444KeepsColourDetail) {
  const auto frames = Frames(320, 240, 3, /*grey=*/false);
  const auto units = Encode(Options(PictureKind::kColour444, 320, 240), frames);
  Decoder decoder(DecoderOptions(ColorEncoding::kBGR8));
  for (std::size_t i = 0; i < units.size(); ++i) {
    ColorView out;
    ASSERT_TRUE(decoder.Decode(units[i].bytes, "au", &out).ok()) << i;
    EXPECT_GT(Psnr(out, frames[i].view()), 33.0) << i;  // 4:2:0 at the same CRF: 27.6 dB
  }
  EXPECT_EQ(InspectAccessUnit(units[0].bytes, "au", Limits{})->sps->chroma_format_idc, 3u);
}

// Pictures through the server's decoder (BGR out): their mean PSNR against `frames` and mean bytes.
struct ColourFigures {
  double psnr = 0, bytes = 0;
};
ColourFigures DecodeAndMeasure(const std::vector<EncodedPicture>& units,
                               const std::vector<OwnedColor>& frames) {
  Decoder decoder(DecoderOptions(ColorEncoding::kBGR8));
  ColourFigures f;
  for (std::size_t i = 0; i < units.size(); ++i) {
    ColorView out;
    const absl::Status s = decoder.Decode(units[i].bytes, "au", &out);
    EXPECT_TRUE(s.ok()) << i << ": " << s;
    if (!s.ok()) return {};
    f.psnr += Psnr(out, frames[i].view());
    f.bytes += static_cast<double>(units[i].bytes.size());
  }
  f.psnr /= static_cast<double>(units.size());
  f.bytes /= static_cast<double>(units.size());
  return f;
}

// Whether an access unit's picture parameter set codes with CABAC (entropy_coding_mode_flag): the
// first bit after pic_parameter_set_id and seq_parameter_set_id, both 0 (one bit each) in x264's.
bool CodedWithCabac(const EncodedPicture& unit) {
  auto info = InspectAccessUnit(unit.bytes, "au", Limits{});
  if (!info.ok()) {
    ADD_FAILURE() << info.status();
    return true;
  }
  for (const NalUnit& nal : info->nals) {
    if (nal.type != kNalPps) continue;
    const auto first = static_cast<std::uint8_t>(nal.bytes.at(1));
    EXPECT_EQ(first & 0xC0, 0xC0) << "pps_id and sps_id are not both 0";
    return (first & 0x20) != 0;
  }
  ADD_FAILURE() << "no PPS in the access unit";
  return true;
}

// 3 Mbit/s at 30 frames a second.
constexpr double kColourBarBytesPerFrame = 3e6 / 8 / 30;

// docs/video.md's colour settings (table 8e) code with CAVLC, no deblocking, x264's PSNR tuning
// (no psy, no adaptive quantization) and no weighted prediction (its analysis saved): the server
// decodes them in two thirds of the time of table 8c's CABAC settings (synthetic 0.69, New Tsukuba
// 0.66 within rounds; 0.65 and 0.67 of the instructions) and they encode in 0.78 and 0.67 of it
// (0.71 and 0.64). Through the server's decoder each keeps issue 27's colour bar: <= 3 Mbit/s at 30
// fps (12,500 bytes a frame) at a mean PSNR >= 38 dB. x264 on one thread is deterministic, so these
// are the benchmark's rows, not samples.
//
// The synthetic scene (a rendered camera: colour changes pixel to pixel, so 4:4:4), 30
// consecutive 640x480 frames: veryfast crf 25, every partition, diamond motion search, one
// sub-pixel refinement and three references (the benchmark: 2.79 Mbit/s, 39.37 dB). At the
// default tuning and the same CRF the stream is smaller but under the bar: what the PSNR tuning
// buys.
TEST(VideoCodec, FastDecodeColourSettingKeepsTheColourBar) {
  const auto frames = Frames(640, 480, 30, /*grey=*/false);
  EncoderOptions o = Options(PictureKind::kColour444, 640, 480);
  o.crf = 25;
  o.x264_params =
      "cabac=0:no-deblock=1:no-psy=1:aq-mode=0:weightp=0:partitions=all:subme=1:me=dia:ref=3";
  const std::vector<EncodedPicture> units = Encode(o, frames);
  ASSERT_FALSE(units.empty());
  EXPECT_FALSE(CodedWithCabac(units.front()));
  const ColourFigures tuned = DecodeAndMeasure(units, frames);
  EXPECT_GE(tuned.psnr, 38.0);
  EXPECT_LE(tuned.bytes, kColourBarBytesPerFrame);
  o.x264_params.clear();
  const ColourFigures plain = DecodeAndMeasure(Encode(o, frames), frames);
  EXPECT_LT(plain.psnr, 38.0);
  std::printf("fast-decode colour setting: %.0f bytes a frame, %.2f dB (default tuning %.2f dB)\n",
              tuned.bytes, tuned.psnr, plain.psnr);
}

// New Tsukuba's ten frames (a camera's: its colour is smoother than its luma, so 4:2:0, which our
// conversion keeps at 44.5 to 48 dB there and back), 200 apart and so coded almost all intra:
// veryfast crf 24, 8x8 and 4x4 intra blocks, no sub-pixel refinement (the benchmark: 2.92 Mbit/s,
// 38.12 dB). Table 8c's 4:4:4 CABAC setting is held beside it, for its bar too.
TEST(VideoCodec, IntraColourSettingKeepsTheColourBarOnNewTsukuba) {
  CLOUDCAST_REQUIRE_TSUKUBA();
  auto loaded = tsukuba::LoadAll(::cloudcast::testing::TsukubaDir());
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  std::vector<OwnedColor> frames;
  for (const tsukuba::Frame& f : *loaded) frames.push_back(f.colour);
  ASSERT_FALSE(frames.empty());
  EncoderOptions o = Options(PictureKind::kColour, frames[0].width, frames[0].height);
  o.crf = 24;
  o.x264_params = "cabac=0:no-deblock=1:no-psy=1:aq-mode=0:weightp=0:partitions=i8x8,i4x4:subme=0";
  const std::vector<EncodedPicture> units = Encode(o, frames);
  ASSERT_FALSE(units.empty());
  EXPECT_FALSE(CodedWithCabac(units.front()));
  const ColourFigures f = DecodeAndMeasure(units, frames);
  EncoderOptions before = Options(PictureKind::kColour444, frames[0].width, frames[0].height);
  before.crf = 24;
  before.x264_params = "no-deblock=1:no-psy=1:aq-mode=0:partitions=i8x8:subme=0";
  const ColourFigures cabac = DecodeAndMeasure(Encode(before, frames), frames);
  std::printf(
      "intra colour setting on New Tsukuba: %.0f bytes a frame, %.2f dB (4:4:4 CABAC: %.0f bytes, "
      "%.2f dB)\n",
      f.bytes, f.psnr, cabac.bytes, cabac.psnr);
  EXPECT_GE(f.psnr, 38.0);
  EXPECT_LE(f.bytes, kColourBarBytesPerFrame);
  EXPECT_GE(cabac.psnr, 38.0);
  EXPECT_LE(cabac.bytes, kColourBarBytesPerFrame);
}

// Stereo pairs (grey) with the left view's truth (kU8 rows, px, 0 = unknown).
struct StereoPairs {
  std::vector<OwnedColor> left, right;
  std::vector<OwnedDisparity> truth;
};

// Our matcher's bad-2.0 (docs/stereo.md's defaults, against truth + `truth_offset` px) on the
// decoded pairs, minus on the originals: issue 27's measure of what a coding costs stereo.
double Bad2Change(const StereoPairs& original, const StereoPairs& decoded, int truth_offset) {
  auto matcher = stereo::MakeMatcher(StereoParams{});
  EXPECT_TRUE(matcher.ok()) << matcher.status();
  stereo::DisparityScore before, after;
  const auto score = [&](const OwnedColor& l, const OwnedColor& r, const OwnedDisparity& truth,
                         stereo::DisparityScore* into) {
    stereo::DisparityMap16 map;
    const absl::Status s = (*matcher)->Compute(l.view(), r.view(), &map);
    EXPECT_TRUE(s.ok()) << s;
    EXPECT_TRUE(into->Add(map, truth.view()).ok());
  };
  for (std::size_t i = 0; i < original.left.size(); ++i) {
    score(original.left[i], original.right[i], original.truth[i], &before);
    score(decoded.left[i], decoded.right[i], original.truth[i], &after);
  }
  std::printf(
      "bad-2.0 (truth + %d px): %.2f %% decoded, %.2f %% original; matched %.1f %% and "
      "%.1f %% of the known pixels\n",
      truth_offset, after.Bad(2, truth_offset), before.Bad(2, truth_offset), 100 * after.Density(),
      100 * before.Density());
  return after.Bad(2, truth_offset) - before.Bad(2, truth_offset);
}

// A decoded picture, kept (the decoder's view is overwritten by its next picture).
OwnedColor Decoded(Decoder& decoder, const EncodedPicture& unit) {
  ColorView v;
  const absl::Status s = decoder.Decode(unit.bytes, "au", &v);
  EXPECT_TRUE(s.ok()) << s;
  const auto* p = static_cast<const std::uint8_t*>(v.data);
  return OwnedColor{std::vector<std::uint8_t>(p, p + v.size_bytes), v.width, v.height, v.encoding};
}

// 8 Mbit/s at 30 pairs a second.
constexpr double kStereoBarBytesPerPair = 8e6 / 8 / 30;

// docs/video.md's stereo settings (table 8d) code with CAVLC, which is what makes them decode in
// half the time of the CABAC streams they replace (1.07 and 1.20 ms an image against 2.21 in the
// same rounds: CABAC's arithmetic decoding is half of an H.264 decode at these rates). Through
// the server's decoder they keep issue 27's stereo bar: <= 8 Mbit/s at 30 pairs a second with our
// matcher's bad-2.0 within +1.0 point of the same matcher on the original pairs, against each data
// set's own truth. x264 on one thread is deterministic, so these are the benchmark's rows.
//
// The synthetic scene (a rendered camera, 30 consecutive 640x480 pairs, exact truth): two grey
// streams, superfast crf 4.5, every partition, eight references, no 8x8 transform, no deblocking
// (a no-op at such quantisers: the same pictures, less work at both ends); the benchmark:
// 7.59 Mbit/s, +0.77 points.
TEST(VideoCodec, CavlcStereoSettingKeepsTheStereoBarOnTheSyntheticScene) {
  const SyntheticScene scene = SyntheticScene::Default();
  StereoPairs pairs;
  for (int i = 0; i < 30; ++i) {
    SyntheticOptions o;
    o.frame = static_cast<std::uint64_t>(i);
    auto left = scene.Render(o);
    o.eye_x = kSyntheticStereoBaseline;
    auto right = scene.Render(o);
    ASSERT_TRUE(left.ok() && right.ok());
    auto truth = SyntheticStereoTruth(*left);
    ASSERT_TRUE(truth.ok()) << truth.status();
    pairs.truth.push_back({*std::move(truth), left->width, left->height, DisparityEncoding::kU8});
    pairs.left.push_back(*stereo::ToGrey(left->colour_view()));
    pairs.right.push_back(*stereo::ToGrey(right->colour_view()));
  }
  EncoderOptions o = Options(PictureKind::kGrey, 640, 480);
  o.preset = "superfast";
  o.crf = 4.5;
  o.x264_params = "cabac=0:no-deblock=1:8x8dct=0:partitions=all:ref=8";
  const std::vector<EncodedPicture> left_units = Encode(o, pairs.left);
  const std::vector<EncodedPicture> right_units = Encode(o, pairs.right);
  EXPECT_FALSE(CodedWithCabac(left_units[0]));
  EXPECT_FALSE(CodedWithCabac(right_units[0]));
  Decoder left_decoder(DecoderOptions()), right_decoder(DecoderOptions());
  StereoPairs decoded;
  double bytes = 0;
  for (std::size_t i = 0; i < pairs.left.size(); ++i) {
    decoded.left.push_back(Decoded(left_decoder, left_units[i]));
    decoded.right.push_back(Decoded(right_decoder, right_units[i]));
    bytes += static_cast<double>(left_units[i].bytes.size() + right_units[i].bytes.size());
  }
  bytes /= static_cast<double>(pairs.left.size());
  const double change = Bad2Change(pairs, decoded, 0);
  std::printf(
      "CAVLC stereo setting, synthetic scene: %.0f bytes a pair (%.2f Mbit/s), %+.2f "
      "points\n",
      bytes, bytes * 8 * 30 / 1e6, change);
  EXPECT_LE(bytes, kStereoBarBytesPerPair);
  EXPECT_LE(change, 1.0);
}

// New Tsukuba (10 pairs 200 apart, truth + 1 px: the data set's truth reads 1 px low): one stream,
// the right view after its left (two references, 60 pictures a second), superfast crf 2 capped by
// 9 Mbit/s (a one-frame VBV: the average stays under 8), no deblocking, no 8x8 transform (the
// benchmark: 7.60 Mbit/s, +0.06 points).
TEST(VideoCodec, CavlcStereoSettingKeepsTheStereoBarOnNewTsukuba) {
  CLOUDCAST_REQUIRE_TSUKUBA();
  auto loaded = tsukuba::LoadAllStereo(::cloudcast::testing::TsukubaDir());
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  StereoPairs pairs;
  std::vector<OwnedColor> interleaved;
  for (const StereoFrame& f : *loaded) {
    pairs.left.push_back(*stereo::ToGrey(f.left.view()));
    pairs.right.push_back(*stereo::ToGrey(f.right.view()));
    pairs.truth.push_back(f.truth);
    interleaved.push_back(pairs.left.back());
    interleaved.push_back(pairs.right.back());
  }
  ASSERT_FALSE(pairs.left.empty());
  EncoderOptions o = Options(PictureKind::kGrey, pairs.left[0].width, pairs.left[0].height);
  o.preset = "superfast";
  o.crf = 2;
  o.fps = 60;
  o.keyframe_interval = 120;
  o.refs = 2;
  o.bitrate_bps = 9'000'000;
  o.x264_params = "cabac=0:no-deblock=1:8x8dct=0";
  const std::vector<EncodedPicture> units = Encode(o, interleaved);
  EXPECT_FALSE(CodedWithCabac(units[0]));
  Decoder decoder(DecoderOptions());
  StereoPairs decoded;
  double bytes = 0;
  for (std::size_t i = 0; i < units.size(); i += 2) {
    decoded.left.push_back(Decoded(decoder, units[i]));
    decoded.right.push_back(Decoded(decoder, units[i + 1]));
    bytes += static_cast<double>(units[i].bytes.size() + units[i + 1].bytes.size());
  }
  bytes /= static_cast<double>(pairs.left.size());
  const double change = Bad2Change(pairs, decoded, 1);
  std::printf("CAVLC stereo setting, New Tsukuba: %.0f bytes a pair (%.2f Mbit/s), %+.2f points\n",
              bytes, bytes * 8 * 30 / 1e6, change);
  EXPECT_LE(bytes, kStereoBarBytesPerPair);
  EXPECT_LE(change, 1.0);
}

TEST(VideoCodec, QpZeroIsLossless) {
  const auto frames = Frames(160, 120, 3, /*grey=*/true);
  EncoderOptions o = Options(PictureKind::kGrey, 160, 120);
  o.qp = 0;
  const auto units = Encode(o, frames);
  Decoder decoder(DecoderOptions());
  for (std::size_t i = 0; i < units.size(); ++i) {
    ColorView out;
    ASSERT_TRUE(decoder.Decode(units[i].bytes, "au", &out).ok());
    EXPECT_EQ(Psnr(out, frames[i].view()), 99.0) << "picture " << i << " differs";
  }
}

TEST(VideoCodec, IdrOnRequestStartsALateDecoder) {
  const auto frames = Frames(160, 120, 8, /*grey=*/true);
  const auto units = Encode(Options(PictureKind::kGrey, 160, 120), frames, {5});
  EXPECT_TRUE(units[5].keyframe);
  EXPECT_FALSE(units[4].keyframe);
  auto info = InspectAccessUnit(units[5].bytes, "au", Limits{});
  ASSERT_TRUE(info.ok());
  EXPECT_TRUE(info->sps.has_value()) << "an IDR repeats the headers for late joiners";
  Decoder late(DecoderOptions());
  ColorView out;
  for (int i = 5; i < 8; ++i) ASSERT_TRUE(late.Decode(units[i].bytes, "au", &out).ok()) << i;
}

TEST(VideoCodec, PeriodicIdrAndIntraRefresh) {
  const auto frames = Frames(160, 120, 9, /*grey=*/true);
  EncoderOptions o = Options(PictureKind::kGrey, 160, 120);
  o.keyframe_interval = 4;
  auto units = Encode(o, frames);
  for (std::size_t i = 0; i < units.size(); ++i) EXPECT_EQ(units[i].keyframe, i % 4 == 0) << i;
  // Intra refresh: one IDR, then no picture much larger than the rest; an IDR still on request.
  o.keyframe_interval = 0;
  o.intra_refresh = true;
  units = Encode(o, frames, {6});
  Decoder decoder(DecoderOptions());
  for (std::size_t i = 0; i < units.size(); ++i) {
    EXPECT_EQ(units[i].keyframe, i == 0 || i == 6) << i;
    ColorView out;
    ASSERT_TRUE(decoder.Decode(units[i].bytes, "au", &out).ok()) << i;
  }
}

TEST(VideoCodec, BitrateChangesPerFrame) {
  const auto frames = Frames(320, 240, 30, /*grey=*/false);
  EncoderOptions o = Options(PictureKind::kColour, 320, 240);
  o.crf = 0;
  o.bitrate_bps = 4'000'000;
  auto enc = Encoder::Make(o);
  ASSERT_TRUE(enc.ok()) << enc.status();
  std::vector<std::size_t> sizes;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    FrameControl c;
    if (i == 15) c.bitrate_bps = 300'000;  // the link dropped
    EncodedPicture p;
    ASSERT_TRUE((*enc)->Encode(frames[i].view(), c, "frame", &p).ok());
    sizes.push_back(p.bytes.size());
  }
  std::size_t before = 0, after = 0;
  for (int i = 8; i < 15; ++i) before += sizes[i];
  for (int i = 22; i < 29; ++i) after += sizes[i];
  EXPECT_LT(after * 3, before) << "7 frames at 4 Mbit/s: " << before << " B, at 0.3: " << after;
  // One frame of VBV at 0.3 Mbit/s and 30 fps is 1,250 bytes: no frame far above it.
  for (int i = 22; i < 29; ++i) EXPECT_LT(sizes[i], 2 * 1250u) << i;
}

TEST(VideoCodec, EncoderOptionErrorsNameTheField) {
  EncoderOptions o = Options(PictureKind::kGrey, 161, 120);
  EXPECT_THAT(std::string(Encoder::Make(o).status().message()), HasSubstr("options.width"));
  o.width = 160;
  o.crf = 0;
  o.bitrate_bps = 0;
  EXPECT_THAT(std::string(Encoder::Make(o).status().message()), HasSubstr("options.bitrate_bps"));
  o.crf = 60;
  EXPECT_THAT(std::string(Encoder::Make(o).status().message()), HasSubstr("options.crf"));
  o.crf = 18;
  o.preset = "warp-speed";
  EXPECT_THAT(std::string(Encoder::Make(o).status().message()), HasSubstr("warp-speed"));
  o.preset = "veryfast";
  o.x264_params = "no-such-option=1";
  EXPECT_THAT(std::string(Encoder::Make(o).status().message()), HasSubstr("no-such-option"));
  o.x264_params = "aq-strength=1.5";
  auto enc = Encoder::Make(o);
  ASSERT_TRUE(enc.ok()) << enc.status();
  const auto colour = Frames(160, 120, 1, /*grey=*/false);
  EncodedPicture p;
  const absl::Status s = (*enc)->Encode(colour[0].view(), {}, "frame.left", &p);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), HasSubstr("frame.left.encoding"));
  const auto small = Frames(80, 60, 1, /*grey=*/true);
  EXPECT_THAT(std::string((*enc)->Encode(small[0].view(), {}, "frame.left", &p).message()),
              HasSubstr("80x60 but the stream is 160x120"));
}

// --- bad input
// --------------------------------------------------------------------------------------

class VideoBadInput : public ::testing::Test {
 protected:
  void SetUp() override {
    frames_ = Frames(160, 120, 10, /*grey=*/true);
    units_ = Encode(Options(PictureKind::kGrey, 160, 120), frames_, {6});
  }
  // The stream goes on: the next IDR decodes, and the pictures after it.
  void ExpectRecoversAtIdr(Decoder& d) {
    ColorView out;
    EXPECT_TRUE(d.needs_keyframe());
    const absl::Status refused = d.Decode(units_[4].bytes, "au", &out);
    EXPECT_EQ(refused.code(), absl::StatusCode::kFailedPrecondition) << refused;
    for (int i = 6; i < 10; ++i) {
      const absl::Status s = d.Decode(units_[i].bytes, "au", &out);
      ASSERT_TRUE(s.ok()) << i << ": " << s;
      EXPECT_GT(Psnr(out, frames_[i].view()), 35.0);
    }
    EXPECT_FALSE(d.needs_keyframe());
  }
  std::vector<OwnedColor> frames_;
  std::vector<EncodedPicture> units_;
};

TEST_F(VideoBadInput, StreamStartingWithoutKeyframeIsRefusedUndecoded) {
  int charges = 0;
  Decoder::Options o = DecoderOptions();
  o.charge = [&](std::uint64_t) {
    ++charges;
    return absl::OkStatus();
  };
  Decoder d(o);
  ColorView out;
  const absl::Status s = d.Decode(units_[2].bytes, "frame.video.left.access_unit", &out);
  EXPECT_EQ(s.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(std::string(s.message()),
              HasSubstr("frame.video.left.access_unit is not a keyframe"));
  EXPECT_TRUE(d.needs_keyframe());
  EXPECT_FALSE(d.opened()) << "nothing is decoded before the stream's IDR";
  EXPECT_EQ(charges, 0);
  ExpectRecoversAtIdr(d);
  EXPECT_EQ(charges, 1);
}

TEST_F(VideoBadInput, CorruptSliceIsAnErrorThenTheStreamGoesOn) {
  Decoder d(DecoderOptions());
  ColorView out;
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(d.Decode(units_[i].bytes, "au", &out).ok());
  // Damage the slice data of picture 3 (its header bytes kept, so the NAL units still parse).
  std::string bad = units_[3].bytes;
  for (std::size_t k = 8; k < bad.size(); k += 3) bad[k] = static_cast<char>(bad[k] ^ 0x5A);
  for (std::size_t k = 3; k + 2 < bad.size(); ++k) {  // no start code may appear by chance
    if (bad[k] == 0 && bad[k + 1] == 0) bad[k + 1] = 1;
  }
  const absl::Status s = d.Decode(bad, "frame.video.left.access_unit", &out);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
  EXPECT_THAT(std::string(s.message()), HasSubstr("frame.video.left.access_unit"));
  EXPECT_THAT(std::string(s.message()), HasSubstr("needs an IDR"));
  ExpectRecoversAtIdr(d);
}

TEST_F(VideoBadInput, TruncatedAccessUnitIsAnError) {
  Decoder d(DecoderOptions());
  ColorView out;
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(d.Decode(units_[i].bytes, "au", &out).ok());
  const std::string cut = units_[3].bytes.substr(0, units_[3].bytes.size() / 2);
  const absl::Status s = d.Decode(cut, "frame.video.left.access_unit", &out);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
  EXPECT_THAT(std::string(s.message()), HasSubstr("frame.video.left.access_unit"));
  ExpectRecoversAtIdr(d);
}

TEST_F(VideoBadInput, TruncatedIdrIsAnError) {
  Decoder d(DecoderOptions());
  ColorView out;
  const std::string cut = units_[0].bytes.substr(0, units_[0].bytes.size() * 2 / 3);
  const absl::Status s = d.Decode(cut, "au", &out);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
  ExpectRecoversAtIdr(d);
}

TEST_F(VideoBadInput, ResolutionChangeMidStreamIsRefused) {
  Decoder d(DecoderOptions());
  ColorView out;
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(d.Decode(units_[i].bytes, "au", &out).ok());
  const auto bigger = Encode(Options(PictureKind::kGrey, 320, 240), Frames(320, 240, 1, true));
  const absl::Status s = d.Decode(bigger[0].bytes, "frame.video.left.access_unit", &out);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()),
              HasSubstr("frame.video.left.access_unit.sps: the picture size changes mid-stream, "
                        "from 160x120 to 320x240"));
  EXPECT_EQ(d.width(), 160u);
  ExpectRecoversAtIdr(d);
}

TEST_F(VideoBadInput, SizeOtherThanTheFramesIsRefused) {
  Decoder::Options o = DecoderOptions();
  o.width = 640;
  o.height = 480;
  Decoder d(o);
  ColorView out;
  const absl::Status s = d.Decode(units_[0].bytes, "au", &out);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), HasSubstr("au.sps: the sequence header says 160x120"));
  EXPECT_FALSE(d.opened());
}

TEST_F(VideoBadInput, SequenceHeaderClaiming16kIsRefusedBeforeAllocation) {
  // A real IDR whose SPS is replaced by one claiming 16384 x 16384.
  auto info = InspectAccessUnit(units_[0].bytes, "au", Limits{});
  ASSERT_TRUE(info.ok());
  std::string forged = Sps(1024, 1024);
  for (const NalUnit& n : info->nals) {
    if (n.type != kNalSps) forged += std::string("\x00\x00\x00\x01", 4) + std::string(n.bytes);
  }
  std::uint64_t charged = 0;
  Decoder::Options o = DecoderOptions();
  o.charge = [&](std::uint64_t bytes) {
    charged += bytes;
    return absl::OkStatus();
  };
  Decoder d(o);
  ColorView out;
  const absl::Status s = d.Decode(forged, "frame.video.left.access_unit", &out);
  EXPECT_EQ(s.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(std::string(s.message()),
              HasSubstr("frame.video.left.access_unit.sps.pic_width_in_mbs_minus1: the sequence "
                        "header claims 16384x16384"));
  EXPECT_THAT(std::string(s.message()), HasSubstr("max_pixels"));
  EXPECT_EQ(charged, 0u);
  EXPECT_FALSE(d.opened()) << "no decoder exists for a refused header";
  // Over the side limit too: 32768 wide.
  Limits limits;
  EXPECT_THAT(
      std::string(ParseSequenceHeader(Sps(2048, 8).substr(4), "f", limits).status().message()),
      HasSubstr("f.sps.pic_width_in_mbs_minus1: the sequence header claims 32768x128"));
  ExpectRecoversAtIdr(d);
}

TEST_F(VideoBadInput, ChargeComesFromTheHeaderAndARefusalLeavesNoDecoder) {
  Decoder::Options o = DecoderOptions();
  o.charge = [](std::uint64_t bytes) {
    return absl::ResourceExhaustedError("over --max-memory-mb (test)");
  };
  Decoder refused(o);
  ColorView out;
  const absl::Status s = refused.Decode(units_[0].bytes, "au", &out);
  EXPECT_EQ(s.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(std::string(s.message()), HasSubstr("--max-memory-mb"));
  EXPECT_FALSE(refused.opened());
  EXPECT_EQ(refused.charged_bytes(), 0u);

  std::vector<std::uint64_t> charges;
  std::uint64_t released = 0;
  o.charge = [&](std::uint64_t bytes) {
    charges.push_back(bytes);
    return absl::OkStatus();
  };
  o.release = [&](std::uint64_t bytes) { released += bytes; };
  {
    Decoder d(o);
    for (int i = 0; i < 10; ++i) ASSERT_TRUE(d.Decode(units_[i].bytes, "au", &out).ok());
    EXPECT_EQ(released, 0u);
  }
  ASSERT_EQ(charges.size(), 1u) << "the same header again is not charged again";
  EXPECT_EQ(released, charges[0]) << "the stream's memory goes back when its decoder goes";
  auto info = InspectAccessUnit(units_[0].bytes, "au", Limits{});
  EXPECT_EQ(charges[0], DecoderMemoryBytes(*info->sps, ColorEncoding::kMono8));
  EXPECT_GE(charges[0], 160u * 120 * 3 / 2 * (info->sps->max_num_ref_frames + 1));
}

// glibc's accounting sees the allocations only without a sanitizer's allocator (gcc defines
// __SANITIZE_*__, clang answers __has_feature).
#if defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || \
    __has_feature(memory_sanitizer)
#define CLOUDCAST_SANITIZED_ALLOCATOR 1
#endif
#endif
#if !defined(__SANITIZE_ADDRESS__) && !defined(__SANITIZE_THREAD__) && \
    !defined(CLOUDCAST_SANITIZED_ALLOCATOR)
// What is charged covers what the decoder allocates, at 640x480 (glibc's own accounting).
TEST(VideoCodec, ChargeCoversWhatTheDecoderAllocates) {
  const auto frames = Frames(640, 480, 6, /*grey=*/false);
  const auto units = Encode(Options(PictureKind::kColour, 640, 480), frames);
  Decoder::Options o = DecoderOptions(ColorEncoding::kBGR8);
  Decoder d(o);
  const struct mallinfo2 before = mallinfo2();
  std::size_t peak = 0;
  for (const EncodedPicture& u : units) {
    ColorView out;
    ASSERT_TRUE(d.Decode(u.bytes, "au", &out).ok());
    const struct mallinfo2 now = mallinfo2();
    peak = std::max(peak, (now.uordblks + now.hblkhd) - (before.uordblks + before.hblkhd));
  }
  EXPECT_GT(peak, 0u);
  EXPECT_LE(peak, d.charged_bytes()) << "charged " << d.charged_bytes() << ", allocated " << peak;
}
#endif

TEST(H264Bitstream, MalformedAccessUnitsNameTheField) {
  const Limits limits;
  auto err = [&](std::string bytes) {
    return std::string(InspectAccessUnit(bytes, "au", limits).status().message());
  };
  EXPECT_THAT(err(""), HasSubstr("au is empty"));
  EXPECT_THAT(err("\x89PNG\r\n"), HasSubstr("start code"));
  EXPECT_THAT(err(std::string("\x00\x00\x01\xE5\x10", 5)),
              HasSubstr("au.nal[0].forbidden_zero_bit"));
  EXPECT_THAT(err(std::string("\x00\x00\x01\x74\x10", 5)),
              HasSubstr("au.nal[0].nal_unit_type is 20"));
  EXPECT_THAT(err(std::string("\x00\x00\x01\x65\x10\x00\x00\x01", 8)),
              HasSubstr("au.nal[1] is empty"));
  // An SPS cut short names the field it stopped at.
  const std::string sps = Sps(10, 8);
  const std::string cut = err(sps.substr(0, 9));
  EXPECT_THAT(cut, HasSubstr("au.sps."));
  EXPECT_THAT(cut, HasSubstr("ends"));
  auto ok = InspectAccessUnit(sps, "au", limits);
  ASSERT_TRUE(ok.ok()) << ok.status();
  EXPECT_EQ(ok->sps->width, 160u);
  EXPECT_EQ(ok->sps->height, 128u);
  EXPECT_FALSE(ok->has_slices);
}

TEST_F(VideoBadInput, GapRequiresAKeyframe) {
  Decoder d(DecoderOptions());
  ColorView out;
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(d.Decode(units_[i].bytes, "au", &out).ok());
  d.RequireKeyframe();  // frame 3 was lost
  ExpectRecoversAtIdr(d);
}

// --- RVL
// ------------------------------------------------------------------------------------------

TEST(Rvl, RoundTripsDepthAndDisparity) {
  // 16-bit: synthetic disparity in 1/16 px (zeros where nothing is seen), and extremes.
  SyntheticOptions o;
  o.width = 160;
  o.height = 120;
  o.disparity_encoding = DisparityEncoding::kU16;
  auto f = SyntheticScene::Default().Render(o);
  ASSERT_TRUE(f.ok());
  std::vector<std::uint16_t> u16(160 * 120);
  std::memcpy(u16.data(), f->disparity.data(), u16.size() * 2);
  for (int i = 0; i < 40; ++i) u16[i * 7] = 0;  // holes
  u16[1] = 65535;
  u16[2] = 1;
  std::string bytes;
  EncodeRvl(u16.data(), 160, 120, &bytes);
  std::vector<std::uint16_t> back;
  ASSERT_TRUE(DecodeRvl(bytes, 160, 120, 65535, Limits{}, "d", &back).ok());
  EXPECT_EQ(back, u16);
  // 8-bit, all zeros, all one value.
  std::vector<std::uint8_t> u8(64 * 8, 0);
  EncodeRvl(u8.data(), 64, 8, &bytes);
  ASSERT_TRUE(DecodeRvl(bytes, 64, 8, 255, Limits{}, "d", &back).ok());
  EXPECT_EQ(back, std::vector<std::uint16_t>(64 * 8, 0));
  u8.assign(64 * 8, 200);
  EncodeRvl(u8.data(), 64, 8, &bytes);
  ASSERT_TRUE(DecodeRvl(bytes, 64, 8, 255, Limits{}, "d", &back).ok());
  EXPECT_EQ(back, std::vector<std::uint16_t>(64 * 8, 200));
  // A zero delta is one 4-bit group: half a byte a pixel, plus the header and the two runs.
  EXPECT_LE(bytes.size(), 12u + 64 * 8 / 2 + 8);
}

TEST(Rvl, MalformedBytesNameTheField) {
  std::vector<std::uint16_t> img(32 * 4);
  for (std::size_t i = 0; i < img.size(); ++i)
    img[i] = static_cast<std::uint16_t>(i % 5 ? 300 + i : 0);
  std::string bytes;
  EncodeRvl(img.data(), 32, 4, &bytes);
  std::vector<std::uint16_t> back;
  auto err = [&](std::string_view b, std::uint32_t w, std::uint32_t h, std::uint32_t max) {
    return std::string(DecodeRvl(b, w, h, max, Limits{}, "frame.depth.rvl", &back).message());
  };
  EXPECT_THAT(err("PNG....", 32, 4, 65535), HasSubstr("frame.depth.rvl is not RVL"));
  EXPECT_THAT(err(bytes, 16, 8, 65535), HasSubstr("holds a 32x4 image; the frame is 16x8"));
  EXPECT_THAT(err(bytes.substr(0, bytes.size() - 4), 32, 4, 65535), HasSubstr("ends at pixel"));
  EXPECT_THAT(err(bytes.substr(0, bytes.size() - 1), 32, 4, 65535),
              HasSubstr("whole 32-bit words"));
  EXPECT_THAT(err(bytes, 32, 4, 255), HasSubstr("over the image's sample range"));
  // A first run of zeros longer than the image.
  std::vector<std::uint16_t> zeros(32 * 8, 0);
  EncodeRvl(zeros.data(), 32, 8, &bytes);
  bytes.replace(4, 8, std::string("\x20\0\0\0\x04\0\0\0", 8));  // the header now says 32x4
  EXPECT_THAT(err(bytes, 32, 4, 65535), HasSubstr("a run of zeros past the image's end"));
  // Over the limits before anything grows.
  Limits small;
  small.max_side = 16;
  EXPECT_EQ(DecodeRvl(bytes, 32, 4, 65535, small, "d", &back).code(),
            absl::StatusCode::kResourceExhausted);
}

}  // namespace
}  // namespace cloudcast::video
