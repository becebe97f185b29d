// cli::RoleFlags, the input files' flags of cloudcast-client and cloudcast-load: one flag per role
// and sort of file, and their check against --input.
#include "cloudcast/cli/role_flags.h"

#include <gtest/gtest.h>

#include <algorithm>

#include <string>
#include <vector>

namespace cloudcast::cli {
namespace {

using sources::FrameKind;
using sources::ImageRole;

// An app with the role flags of `sorts` only; Parse takes the arguments in command-line order.
struct Parsed {
  CLI::App app;
  RoleFlags flags;
  explicit Parsed(std::vector<FileSort> sorts) : flags(app, sorts, "Source") {}
  Parsed& Parse(std::vector<std::string> args) {
    std::reverse(args.begin(), args.end());  // CLI11 takes the arguments last first
    app.parse(args);
    return *this;
  }
};

TEST(RoleFlags, EveryRoleOfEverySortIsAFlag) {
  Parsed p({FileSort::kGlob, FileSort::kVideo, FileSort::kStill});
  for (const char* flag : {"--disparity-glob", "--colour-glob", "--depth-glob", "--right-glob",
                           "--disparity-video", "--colour-video", "--depth-video", "--right-video",
                           "--disparity", "--colour", "--depth", "--right"}) {
    EXPECT_NE(p.app.get_option_no_throw(flag), nullptr) << flag;
  }
  Parsed globs_only({FileSort::kGlob});
  EXPECT_EQ(globs_only.app.get_option_no_throw("--depth-video"), nullptr);
}

TEST(RoleFlags, GivesThePathsOfTheKindsRoles) {
  Parsed p({FileSort::kGlob, FileSort::kStill});
  p.Parse({"--colour-glob", "l/*.png", "--right-glob", "r/*.png"});
  auto given = p.flags.Check(FrameKind::kStereo);
  ASSERT_TRUE(given.ok()) << given.status();
  EXPECT_EQ(*given, std::vector<std::string>{"--colour-glob + --right-glob"});
  const sources::RolePaths globs = p.flags.Given(FileSort::kGlob);
  EXPECT_EQ(globs, (sources::RolePaths{{ImageRole::kColour, "l/*.png"},
                                       {ImageRole::kRight, "r/*.png"}}));
  EXPECT_TRUE(p.flags.Given(FileSort::kStill).empty());
  EXPECT_TRUE(p.flags.Given(FileSort::kVideo).empty());  // not registered
}

TEST(RoleFlags, NothingGivenIsNoSource) {
  Parsed p({FileSort::kGlob});
  p.Parse({});
  auto given = p.flags.Check(FrameKind::kDisparity);
  ASSERT_TRUE(given.ok());
  EXPECT_TRUE(given->empty());
}

TEST(RoleFlags, ARoleOfAnotherKindNamesTheFlagsTheKindTakes) {
  Parsed p({FileSort::kGlob, FileSort::kVideo});
  p.Parse({"--depth-video", "d.mkv", "--colour-video", "c.avi"});
  auto given = p.flags.Check(FrameKind::kDisparity);
  ASSERT_FALSE(given.ok());
  EXPECT_EQ(given.status().message(),
            "--depth-video does not apply to --input disparity (it takes --disparity-video and "
            "--colour-video)");
  EXPECT_TRUE(p.flags.Check(FrameKind::kDepth).ok());
}

TEST(RoleFlags, AMissingPartnerIsNamed) {
  Parsed p({FileSort::kGlob});
  p.Parse({"--colour-glob", "c/*.png"});
  auto given = p.flags.Check(FrameKind::kStereo);
  ASSERT_FALSE(given.ok());
  EXPECT_EQ(given.status().message(), "--colour-glob needs --right-glob (--input stereo)");
}

TEST(RoleFlags, EachSortGivenIsASource) {
  Parsed p({FileSort::kGlob, FileSort::kStill});
  p.Parse({"--disparity-glob", "d/*", "--colour-glob", "c/*", "--disparity", "d.png", "--colour",
           "c.png"});
  auto given = p.flags.Check(FrameKind::kDisparity);
  ASSERT_TRUE(given.ok());
  EXPECT_EQ(*given, (std::vector<std::string>{"--disparity-glob + --colour-glob",
                                              "--disparity + --colour"}));
}

TEST(RoleFlags, AnEmptyPathGivenCountsAsGiven) {
  // `--depth ''` is a flag given (with a bad path the source reports), not a flag left out.
  Parsed p({FileSort::kStill});
  p.Parse({"--depth", "", "--colour", "c.png"});
  auto given = p.flags.Check(FrameKind::kDisparity);
  ASSERT_FALSE(given.ok());
  EXPECT_NE(given.status().message().find("--depth does not apply"), std::string::npos);
}

}  // namespace
}  // namespace cloudcast::cli
