// cloudcast-video-bench's own behaviour (never its times): two synthetic pairs through every
// layout at one setting, its JSON and charts, its errors.
#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <vector>

#include "support/program_support.h"

namespace cloudcast {
namespace {

using testing::BinDir;
using testing::ReadText;
using testing::RunProgram;

class VideoBenchTest : public testing::ScratchDirTest {
 protected:
  std::string Bench() const { return BinDir() + "/cloudcast-video-bench"; }
};

TEST_F(VideoBenchTest, CodesPairsInEveryLayoutAndWritesItsTablesAndCharts) {
  const testing::RunResult r = RunProgram(Bench(),
                                          {"--datasets",
                                           "synthetic",
                                           "--synthetic-frames",
                                           "2",
                                           "--presets",
                                           "ultrafast",
                                           "--crfs",
                                           "20",
                                           "--bitrates",
                                           "",
                                           "--no-sgbm",
                                           "--colour-presets",
                                           "ultrafast",
                                           "--colour-crfs",
                                           "24",
                                           "--colour-bitrates",
                                           "",
                                           "--jpeg-qualities",
                                           "80",
                                           "--json",
                                           Path("video.json"),
                                           "--plots",
                                           Path("plots")},
                                          dir_.string());
  ASSERT_EQ(r.code, 0) << r;
  EXPECT_NE(r.out.find("L,R interleaved"), std::string::npos) << r;
  const auto j = nlohmann::json::parse(ReadText(Path("video.json")));
  // Per layout: the lossless row (qp 0, checked bit-exact) and crf 20.
  ASSERT_EQ(j["stereo"].size(), 6u) << j.dump(1);
  std::set<std::string> layouts;
  for (const auto& row : j["stereo"]) {
    layouts.insert(row["layout"].get<std::string>());
    EXPECT_GT(row["bytes_per_pair"].get<double>(), 0) << row.dump();
    if (row["lossless"].get<bool>()) {
      EXPECT_EQ(row["ours_delta_gt"].get<double>(), 0.0) << row.dump();
    } else {
      EXPECT_EQ(row["crf"].get<double>(), 20.0);
      EXPECT_GE(row["ours_bad2_gt"].get<double>(), 0.0);
      EXPECT_LE(row["ours_bad2_gt"].get<double>(), 100.0);
    }
  }
  EXPECT_EQ(layouts, (std::set<std::string>{"independent", "interleaved", "side-by-side"}));
  // Colour: H.264 4:2:0 and 4:4:4 at crf 24, JPEG q 80.
  ASSERT_EQ(j["colour"].size(), 3u) << j.dump(1);
  for (const auto& row : j["colour"]) {
    EXPECT_GT(row["psnr_db"].get<double>(), 20.0) << row.dump();
    EXPECT_GT(row["ssim"].get<double>(), 0.5) << row.dump();
    EXPECT_LE(row["ssim"].get<double>(), 1.0) << row.dump();
  }
  // The colour conversion table: swscale and ours, 4:2:0 and 4:4:4, each timed and round-tripped.
  ASSERT_EQ(j["conversion"].size(), 4u) << j.dump(1);
  for (const auto& row : j["conversion"]) {
    EXPECT_GT(row["to_yuv_ms"].get<double>(), 0.0) << row.dump();
    EXPECT_GT(row["to_bgr_ms"].get<double>(), 0.0) << row.dump();
    EXPECT_GT(row["psnr_db"].get<double>(), 25.0) << row.dump();
  }
  for (const char* png : {"video_stereo_synthetic.png", "video_colour_synthetic.png"}) {
    EXPECT_GT(std::filesystem::file_size(Path("plots") + "/" + png), 1000u) << png;
  }
}

TEST_F(VideoBenchTest, RefusesWhatItCannotRun) {
  testing::RunResult r = RunProgram(Bench(), {"--layouts", "diagonal"}, dir_.string());
  EXPECT_EQ(r.code, 2) << r;
  EXPECT_NE(r.err.find("unknown layout 'diagonal'"), std::string::npos) << r;
  r = RunProgram(Bench(), {"--presets", "warp"}, dir_.string());
  EXPECT_EQ(r.code, 2) << r;
  EXPECT_NE(r.err.find("--presets"), std::string::npos) << r;
  EXPECT_NE(r.err.find("warp"), std::string::npos) << r;
  r = RunProgram(Bench(), {"--crfs", "x"}, dir_.string());
  EXPECT_EQ(r.code, 2) << r;
  EXPECT_NE(r.err.find("--crfs: 'x' is not a number"), std::string::npos) << r;
  r = RunProgram(Bench(), {"--help"}, dir_.string());
  EXPECT_EQ(r.code, 0) << r;
  EXPECT_NE(r.out.find("--layouts"), std::string::npos) << r;
}

// --codecs: the same rows for the other codecs (video/codecs.h), each with its own CRF steps, in
// the JSON and the charts; an unknown codec or a CRF off its scale is refused before any work.
TEST_F(VideoBenchTest, MeasuresTheOtherCodecsBesideH264) {
  testing::RunResult r = RunProgram(Bench(),
                                    {"--datasets",
                                     "synthetic",
                                     "--synthetic-frames",
                                     "2",
                                     "--layouts",
                                     "interleaved",
                                     "--codecs",
                                     "h264,hevc,vp9,av1",
                                     "--presets",
                                     "ultrafast",
                                     "--crfs",
                                     "20",
                                     "--bitrates",
                                     "",
                                     "--hevc-presets",
                                     "ultrafast",
                                     "--hevc-crfs",
                                     "20",
                                     "--vp9-crfs",
                                     "30",
                                     "--av1-crfs",
                                     "30",
                                     "--no-sgbm",
                                     "--no-depth",
                                     "--colour-presets",
                                     "ultrafast",
                                     "--colour-crfs",
                                     "24",
                                     "--colour-bitrates",
                                     "",
                                     "--hevc-colour-presets",
                                     "ultrafast",
                                     "--hevc-colour-crfs",
                                     "24",
                                     "--vp9-colour-crfs",
                                     "32",
                                     "--av1-colour-crfs",
                                     "32",
                                     "--jpeg-qualities",
                                     "80",
                                     "--json",
                                     Path("codecs.json"),
                                     "--plots",
                                     Path("plots")},
                                    dir_.string());
  ASSERT_EQ(r.code, 0) << r;
  EXPECT_NE(r.out.find("hevc ultrafast"), std::string::npos) << r;
  const auto j = nlohmann::json::parse(ReadText(Path("codecs.json")));
  std::map<std::string, int> lossy, lossless;
  for (const auto& row : j["stereo"]) {
    (row["lossless"].get<bool>() ? lossless : lossy)[row["codec"].get<std::string>()]++;
    EXPECT_GT(row["bytes_per_pair"].get<double>(), 0) << row.dump();
  }
  EXPECT_EQ(lossy, (std::map<std::string, int>{{"h264", 1}, {"hevc", 1}, {"vp9", 1}, {"av1", 1}}));
  // qp 0 where the codec has a lossless mode (libaom's real-time mode is not offered one here).
  EXPECT_EQ(lossless, (std::map<std::string, int>{{"h264", 1}, {"hevc", 1}, {"vp9", 1}}));
  // Colour: each codec's 4:2:0 and 4:4:4, and JPEG.
  ASSERT_EQ(j["colour"].size(), 9u) << j.dump(1);
  for (const auto& row : j["colour"]) {
    EXPECT_GT(row["psnr_db"].get<double>(), 20.0) << row.dump();
  }
  EXPECT_GT(std::filesystem::file_size(Path("plots") + "/video_stereo_synthetic.png"), 1000u);

  r = RunProgram(Bench(), {"--codecs", "h264,mpeg2"}, dir_.string());
  EXPECT_EQ(r.code, 2) << r;
  EXPECT_NE(r.err.find("--codecs: unknown codec 'mpeg2'"), std::string::npos) << r;
  r = RunProgram(Bench(), {"--codecs", "vp9", "--vp9-crfs", "70"}, dir_.string());
  EXPECT_EQ(r.code, 2) << r;
  EXPECT_NE(r.err.find("--vp9-crfs"), std::string::npos) << r;
  r = RunProgram(Bench(), {"--codecs", "hevc", "--hevc-presets", "warp"}, dir_.string());
  EXPECT_EQ(r.code, 2) << r;
  EXPECT_NE(r.err.find("--hevc-presets"), std::string::npos) << r;
}

}  // namespace
}  // namespace cloudcast
