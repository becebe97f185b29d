// image_io on its own: disparity and colour files of every depth and format, written here by hand
// (support/image_files.h) so that every byte the decoder sees is known, New Tsukuba's RGBA colour,
// and the errors of files that cannot be read.
#include "cloudcast/io/image_io.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "cloudcast/core/image.h"
#include "cloudcast/core/limits.h"
#include "support/image_files.h"
#include "support/program_support.h"
#include "support/test_support.h"

namespace cloudcast {
namespace {

using testing::Be16;
using testing::Bytes;
using testing::FloatTiff;
using testing::Pfm;
using testing::Png;
using testing::PnmHeader;
using testing::ReadText;
using testing::Samples;
using testing::Tiff;
using testing::TiffEntry;
using testing::WriteFile;

using ImageIoTest = testing::ScratchDirTest;

// A TIFF's size must be the one libtiff reads, and nothing in its directory may make OpenCV
// allocate more than that size allows. Both files below passed the check as 1x1 images, then made
// OpenCV allocate 900 MB and 1 GB (found by fuzz-frame-images; seeds tiff_repeated_size_tags and
// tiff_tile_bomb in fuzz/corpus/frame_images).
TEST(CheckEncodedImageTest, TiffDirectoriesMustAgreeWithTheSizeTheyGive) {
  const std::string pixel(1, '\x10');
  const std::vector<TiffEntry> rest = {{258, 3, 8}, {259, 3, 1}, {262, 3, 1},
                                       {273, 4, 8}, {277, 3, 1}, {279, 4, 1}};
  auto with = [&](std::vector<TiffEntry> size_tags) {
    std::vector<TiffEntry> all = std::move(size_tags);
    all.insert(all.end(), rest.begin(), rest.end());
    std::sort(all.begin(), all.end());  // ascending tags, as the spec wants
    return Tiff(pixel, all);
  };
  Limits limits;
  const char* format = nullptr;
  EXPECT_TRUE(CheckEncodedImage(with({{256, 4, 1}, {257, 4, 1}}), "f", limits, &format).ok());
  // ImageWidth and ImageLength twice: libtiff keeps the first (30000), a reader of the last sees 1.
  const absl::Status repeated = CheckEncodedImage(
      with({{256, 4, 30000}, {256, 4, 1}, {257, 4, 30000}, {257, 4, 1}}), "f", limits);
  EXPECT_EQ(repeated.code(), absl::StatusCode::kInvalidArgument) << repeated;
  EXPECT_NE(repeated.message().find("f"), std::string::npos);
  EXPECT_NE(repeated.message().find("ascending"), std::string::npos) << repeated;
  // Out of order (the spec wants ascending tags; libtiff sorts them and warns): refused alike.
  std::vector<TiffEntry> unsorted = {{257, 4, 1}, {256, 4, 1}};
  unsorted.insert(unsorted.end(), rest.begin(), rest.end());
  EXPECT_EQ(CheckEncodedImage(Tiff(pixel, unsorted), "f", limits).code(),
            absl::StatusCode::kInvalidArgument);
  // Tiles larger than the image: OpenCV allocates a whole tile (up to 1 GB) for a 1x1 image.
  const absl::Status tiles = CheckEncodedImage(
      with({{256, 4, 1}, {257, 4, 1}, {322, 4, 16000}, {323, 4, 16000}}), "f", limits);
  EXPECT_EQ(tiles.code(), absl::StatusCode::kInvalidArgument) << tiles;
  EXPECT_NE(tiles.message().find("tile"), std::string::npos) << tiles;
  // Tiles of the spec's 16-pixel grid over a small image are fine.
  EXPECT_TRUE(
      CheckEncodedImage(with({{256, 4, 20}, {257, 4, 5}, {322, 4, 32}, {323, 4, 16}}), "f", limits)
          .ok());
}

TEST_F(ImageIoTest, DisparityKeepsDepthAndValues) {
  WriteFile(Path("d8.png"), Png(3, 2, 8, 0, Bytes({0, 1, 2, 100, 254, 255})));
  WriteFile(Path("d16.png"), Png(3, 2, 16, 0, Be16({0, 1, 256, 2047, 40000, 65535})));
  WriteFile(Path("d32.tif"), FloatTiff(3, 2, {0.0f, 0.5f, 1.25f, 100.0f, -3.0f, 1e6f}));
  WriteFile(Path("d32.pfm"), Pfm(3, 2, {0.0f, 0.5f, 1.25f, 100.0f, -3.0f, 1e6f}));
  WriteFile(Path("d16.pgm"), PnmHeader("P5", 3, 2, 65535) + Be16({0, 1, 256, 2047, 40000, 65535}));

  auto d8 = LoadDisparity(Path("d8.png"));
  ASSERT_TRUE(d8.ok()) << d8.status();
  EXPECT_EQ(d8->encoding, DisparityEncoding::kU8);
  EXPECT_EQ(d8->width, 3u);
  EXPECT_EQ(d8->height, 2u);
  EXPECT_EQ(d8->pixels, (std::vector<std::uint8_t>{0, 1, 2, 100, 254, 255}));

  for (const char* name : {"d16.png", "d16.pgm"}) {
    SCOPED_TRACE(name);
    auto d16 = LoadDisparity(Path(name));
    ASSERT_TRUE(d16.ok()) << d16.status();
    EXPECT_EQ(d16->encoding, DisparityEncoding::kU16);
    EXPECT_EQ(Samples<std::uint16_t>(d16->pixels),
              (std::vector<std::uint16_t>{0, 1, 256, 2047, 40000, 65535}));
  }
  for (const char* name : {"d32.tif", "d32.pfm"}) {
    SCOPED_TRACE(name);
    auto d32 = LoadDisparity(Path(name));
    ASSERT_TRUE(d32.ok()) << d32.status();
    EXPECT_EQ(d32->encoding, DisparityEncoding::kF32);
    EXPECT_EQ(Samples<float>(d32->pixels),
              (std::vector<float>{0.0f, 0.5f, 1.25f, 100.0f, -3.0f, 1e6f}));
    EXPECT_TRUE(ValidateView(d32->view(), Limits{}).ok());
  }

  // From bytes, as the server receives them.
  auto d16 = LoadDisparity(Path("d16.png"));
  ASSERT_TRUE(d16.ok()) << d16.status();
  auto decoded = DecodeDisparity(ReadText(Path("d16.png")));
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  EXPECT_EQ(decoded->pixels, d16->pixels);
}

// A PFM in a frame's bytes decodes in memory, as OpenCV reads the same file. OpenCV 4.6 cannot
// read PFM from memory: imdecode wrote every PFM frame to /tmp first, and left the file there
// whenever the header read differently from our size check ("# comment" lines, a height of 0 to
// OpenCV): a CI run of the fuzzers and tests left about 1,000, and any client could fill the
// server's disk with them, or fail every PFM frame where /tmp is read-only.
TEST_F(ImageIoTest, PfmBytesDecodeInMemoryAsOpenCvReadsTheFile) {
  const std::string temp = Path("opencv_temp");
  std::filesystem::create_directories(temp);
  ASSERT_EQ(::setenv("OPENCV_TEMP_PATH", temp.c_str(), 1), 0);

  auto floats = [](std::initializer_list<float> v, bool big_endian) {
    std::string s;
    for (float f : v) {
      std::uint32_t u;
      std::memcpy(&u, &f, 4);
      if (big_endian) u = __builtin_bswap32(u);
      s.append(reinterpret_cast<const char*>(&u), 4);
    }
    return s;
  };
  // Bottom row first, as PFM stores them.
  const std::vector<std::pair<std::string, std::string>> valid = {
      {"grey.pfm", "Pf\n3 2\n-1.0\n" + floats({100.0f, -3.0f, 1e6f, 0.0f, 0.5f, 1.25f}, false)},
      {"big_endian.pfm", "Pf\n2 1\n1\n" + floats({7.5f, -0.25f}, true)},
      {"scaled.pfm", "Pf\n2 1\n-3\n" + floats({1.0f, 0.7f}, false)},
      {"fractional_scale.pfm", "Pf\n1 1\n-0.7\n" + floats({1.0f}, false)},
      {"rgb.pfm", "PF\n2 1\n-1\n" + floats({1, 2, 3, 4, 5, 6}, false)},
      {"trailing_bytes.pfm", "Pf\n1 1\n-1\n" + floats({2.0f}, false) + "\n"},
  };
  for (const auto& [name, bytes] : valid) {
    SCOPED_TRACE(name);
    WriteFile(Path(name), bytes);
    const cv::Mat file = cv::imread(Path(name), cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(file.empty());
    const char* format = nullptr;
    ASSERT_TRUE(CheckEncodedImage(bytes, "frame.disparity.encoded", Limits{}, &format).ok());
    EXPECT_STREQ(format, "PFM");
    if (file.channels() == 1) {
      auto from_bytes = DecodeDisparity(bytes, "frame.disparity.encoded");
      ASSERT_TRUE(from_bytes.ok()) << from_bytes.status();
      auto from_file = LoadDisparity(Path(name));
      ASSERT_TRUE(from_file.ok()) << from_file.status();
      EXPECT_EQ(from_bytes->width, static_cast<std::uint32_t>(file.cols));
      EXPECT_EQ(from_bytes->pixels, from_file->pixels);  // bit for bit
    } else {
      // Colour from float samples is refused by name alike, from the file or from bytes.
      auto from_bytes = DecodeColor(bytes, "frame.color.encoded");
      EXPECT_NE(from_bytes.status().message().find("32-bit float"), std::string::npos)
          << from_bytes.status();
    }
  }
  EXPECT_EQ(Samples<float>(DecodeDisparity(valid[0].second)->pixels),
            (std::vector<float>{0.0f, 0.5f, 1.25f, 100.0f, -3.0f, 1e6f}));
  EXPECT_EQ(Samples<float>(DecodeDisparity(valid[1].second)->pixels),
            (std::vector<float>{7.5f, -0.25f}));

  // Headers OpenCV reads otherwise than a careful reader, or pixels cut short: refused by
  // CheckEncodedImage (the server's check before decoding) and by the decoder, naming the field.
  struct Invalid {
    std::string bytes;
    bool header_is_fine;  // CheckEncodedImage reads headers only, so it passes these
  };
  const std::vector<Invalid> invalid = {
      {"Pf\n1 #)\n 2\n1" + std::string("\0\0\xff>eXIf#)\n", 12), false},  // found by fuzzing
      {"Pf\n# a comment\n1 1\n-1\n" + floats({1.0f}, false), false},
      {"Pf 1 1\n-1\n" + floats({1.0f}, false), false},  // OpenCV wants a line break after Pf
      {"Pf\n1  1\n-1\n" + floats({1.0f}, false), false},  // two spaces: OpenCV reads height 0
      {"Pf\n1 1\n0\n" + floats({1.0f}, false), false},    // scale 0
      {"Pf\n1 1\nnan\n" + floats({1.0f}, false), false},
      {"Pf\n1 1\n-1x\n" + floats({1.0f}, false), false},
      {"Pf\n1 1\n-1", false},
      {"Pf\n2 2\n-1\n" + floats({1.0f, 2.0f, 3.0f}, false), true},  // a pixel short
  };
  for (const auto& [bytes, header_is_fine] : invalid) {
    SCOPED_TRACE(::testing::PrintToString(bytes.substr(0, 16)));
    const auto decoded = DecodeDisparity(bytes, "frame.disparity.encoded");
    EXPECT_EQ(decoded.status().code(), absl::StatusCode::kInvalidArgument) << decoded.status();
    EXPECT_NE(decoded.status().message().find("frame.disparity.encoded"), std::string::npos)
        << decoded.status();
    const absl::Status checked = CheckEncodedImage(bytes, "frame.disparity.encoded", Limits{});
    EXPECT_EQ(checked.ok(), header_is_fine) << checked;
    if (!header_is_fine) {
      EXPECT_NE(checked.message().find("frame.disparity.encoded is a PFM image that"),
                std::string::npos)
          << checked;
    }
  }
  std::vector<std::string> left;
  for (const auto& entry : std::filesystem::directory_iterator(temp)) {
    left.push_back(entry.path().filename());
  }
  EXPECT_TRUE(left.empty()) << left.size() << " temporary files left, the first "
                            << (left.empty() ? "" : left.front());
  ::unsetenv("OPENCV_TEMP_PATH");
}

TEST_F(ImageIoTest, ColourDropsAlphaAndNarrows16Bit) {
  // RGBA with alpha 0, 136 and 255: the colour stays, alpha goes (New Tsukuba's PNGs are RGBA).
  WriteFile(Path("rgba.png"),
            Png(3, 1, 8, 6, Bytes({10, 20, 30, 0, 40, 50, 60, 136, 70, 80, 90, 255})));
  auto rgba = LoadColor(Path("rgba.png"));
  ASSERT_TRUE(rgba.ok()) << rgba.status();
  EXPECT_EQ(rgba->encoding, ColorEncoding::kBGR8);
  EXPECT_EQ(rgba->pixels, (std::vector<std::uint8_t>{30, 20, 10, 60, 50, 40, 90, 80, 70}));

  WriteFile(Path("c16.png"), Png(2, 1, 16, 2, Be16({0, 257, 65535, 128, 32896, 1000})));
  auto c16 = LoadColor(Path("c16.png"));
  ASSERT_TRUE(c16.ok()) << c16.status();
  EXPECT_EQ(c16->encoding, ColorEncoding::kBGR8);
  // v / 257 rounded, in BGR order.
  EXPECT_EQ(c16->pixels, (std::vector<std::uint8_t>{255, 1, 0, 4, 128, 0}));

  WriteFile(Path("grey.png"), Png(2, 1, 8, 0, Bytes({7, 200})));
  WriteFile(Path("grey.pgm"), PnmHeader("P5", 2, 1, 255) + Bytes({7, 200}));
  for (const char* name : {"grey.png", "grey.pgm"}) {
    SCOPED_TRACE(name);
    auto grey = LoadColor(Path(name));
    ASSERT_TRUE(grey.ok()) << grey.status();
    EXPECT_EQ(grey->encoding, ColorEncoding::kMono8);
    EXPECT_EQ(grey->pixels, (std::vector<std::uint8_t>{7, 200}));
  }
  // OpenCV expands grey + alpha PNGs to BGRA; the grey survives as equal channels.
  WriteFile(Path("grey_alpha.png"), Png(2, 1, 8, 4, Bytes({7, 0, 200, 255})));
  auto grey_alpha = LoadColor(Path("grey_alpha.png"));
  ASSERT_TRUE(grey_alpha.ok()) << grey_alpha.status();
  EXPECT_EQ(grey_alpha->pixels, (std::vector<std::uint8_t>{7, 7, 7, 200, 200, 200}));

  auto decoded = DecodeColor(ReadText(Path("rgba.png")));
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  EXPECT_EQ(decoded->pixels, rgba->pixels);
}

TEST_F(ImageIoTest, TsukubaColourIsRgbaAndLoadsAsBgr) {
  CLOUDCAST_REQUIRE_TSUKUBA();
  // Frame 00600 has alpha down to 0; its colour must survive.
  auto c = LoadColor(testing::TsukubaColourPath("00600"));
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->encoding, ColorEncoding::kBGR8);
  EXPECT_EQ(c->width, 640u);
  EXPECT_EQ(c->height, 480u);
  auto d = LoadDisparity(testing::TsukubaDisparityPath("00600"));
  ASSERT_TRUE(d.ok()) << d.status();
  EXPECT_EQ(d->encoding, DisparityEncoding::kU8);
  EXPECT_EQ(std::count(d->pixels.begin(), d->pixels.end(), 0), 447);  // README: 447 zeros
}

TEST_F(ImageIoTest, ErrorsNameTheFileAndTheReason) {
  WriteFile(Path("c.png"), Png(2, 2, 8, 2, std::string(12, '\x09')));
  WriteFile(Path("bad.png"), Png(2, 2, 8, 2, std::string(12, '\x09')).substr(0, 40));
  WriteFile(Path("float.tif"), FloatTiff(1, 1, {1.0f}));

  auto missing = LoadDisparity(Path("missing.png"));
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(missing.status().message().find(Path("missing.png")), std::string::npos);

  auto colour_as_disparity = LoadDisparity(Path("c.png"));
  EXPECT_EQ(colour_as_disparity.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(colour_as_disparity.status().message().find("3 channels"), std::string::npos)
      << colour_as_disparity.status();

  auto float_colour = LoadColor(Path("float.tif"));
  EXPECT_EQ(float_colour.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(float_colour.status().message().find("32-bit float"), std::string::npos)
      << float_colour.status();

  auto bad = LoadColor(Path("bad.png"));
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(bad.status().message().find(Path("bad.png")), std::string::npos) << bad.status();

  EXPECT_FALSE(DecodeColor("").ok());
  EXPECT_FALSE(DecodeDisparity("not an image").ok());
  EXPECT_NE(DecodeDisparity("not an image").status().message().find("disparity bytes"),
            std::string::npos);
}

}  // namespace
}  // namespace cloudcast
