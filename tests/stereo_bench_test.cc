// cloudcast-stereo-bench's own behaviour (never its times): one pair through two modes, its JSON,
// its errors.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cloudcast/datasets/middlebury.h"
#include "cloudcast/datasets/tsukuba.h"
#include "support/program_support.h"

namespace cloudcast {
namespace {

using testing::BinDir;
using testing::ReadText;
using testing::RunProgram;

class StereoBenchTest : public testing::ScratchDirTest {
 protected:
  std::string Bench() const { return BinDir() + "/cloudcast-stereo-bench"; }
};

TEST_F(StereoBenchTest, MatchesAPairWithEachModeAndWritesItsTable) {
  std::vector<std::string> args = {"--modes",      "sgm4,bm", "--rounds", "1",
                                   "--per-thread", "1",       "--json",   Path("stereo.json")};
  if (middlebury::AloePresent()) {
    args.insert(args.end(), {"--aloe", middlebury::AloeDir()});
  } else if (tsukuba::Present(tsukuba::DefaultDir())) {
    args.insert(args.end(), {"--frames", "1"});
  } else {
    GTEST_SKIP() << "neither Aloe (apt-get install opencv-doc) nor New Tsukuba is here";
  }
  const testing::RunResult r = RunProgram(Bench(), args, dir_.string());
  ASSERT_EQ(r.code, 0) << r;
  EXPECT_NE(r.out.find("ours 4 paths"), std::string::npos) << r;
  EXPECT_NE(r.out.find("OpenCV bm"), std::string::npos) << r;
  const auto j = nlohmann::json::parse(ReadText(Path("stereo.json")));
  ASSERT_EQ(j["modes"].size(), 2u) << j.dump(1);
  for (const auto& m : j["modes"]) {
    for (const char* key : {"bad_1_gt", "bad_1_gt_plus_1", "bad_2_gt", "bad_2_gt_plus_1", "density",
                            "median_ms", "speed_vs_SGBM", "frames_per_second", "ms_per_frame"}) {
      EXPECT_TRUE(m.contains(key)) << key << " in " << m.dump();
    }
    EXPECT_GT(m["density"].get<double>(), 0.1) << m.dump();
    EXPECT_LE(m["density"].get<double>(), 1.0);
  }
  EXPECT_EQ(j["modes"][0]["kind"], "sgm");
  EXPECT_EQ(j["modes"][0]["paths"], 4);
  EXPECT_EQ(j["modes"][1]["kind"], "bm");
}

TEST_F(StereoBenchTest, RefusesWhatItCannotRun) {
  testing::RunResult r = RunProgram(Bench(), {"--modes", "sgm4,nope"}, dir_.string());
  EXPECT_EQ(r.code, 2) << r;
  EXPECT_NE(r.err.find("unknown mode 'nope'"), std::string::npos) << r;
  r = RunProgram(Bench(), {"--num-disparities", "100"}, dir_.string());
  EXPECT_EQ(r.code, 2) << r;
  EXPECT_NE(r.err.find("num_disparities is 100"), std::string::npos) << r;
  r = RunProgram(Bench(), {"--aloe", dir_.string()}, dir_.string());
  EXPECT_EQ(r.code, 2) << r;
  EXPECT_NE(r.err.find("aloeL.jpg"), std::string::npos) << r;
  r = RunProgram(Bench(), {"--help"}, dir_.string());
  EXPECT_EQ(r.code, 0) << r;
  EXPECT_NE(r.out.find("--aloe"), std::string::npos) << r;
}

}  // namespace
}  // namespace cloudcast
