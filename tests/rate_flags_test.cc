// The rate controller's flags (cloudcast/cli/rate_flags.h): what reaches RateControlOptions, and
// the errors that name the flag.
#include "cloudcast/cli/rate_flags.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace cloudcast::cli {
namespace {

// Parses `args` (without the program name) on a fresh app; the status of the parse or Check.
struct Parsed {
  CLI::App app{"test"};
  bool rate_control = false;
  RateFlags flags{app, "Rate control"};
  std::string error;
  explicit Parsed(std::vector<std::string> args) {
    app.add_flag("--rate-control", rate_control);
    std::vector<const char*> argv = {"test"};
    for (const std::string& a : args) argv.push_back(a.c_str());
    try {
      app.parse(static_cast<int>(argv.size()), argv.data());
      const absl::Status s = flags.Check(rate_control);
      if (!s.ok()) error = std::string(s.message());
    } catch (const CLI::ParseError& e) {
      error = e.what();
    }
  }
};

TEST(RateFlagsTest, DefaultsAreTheLibrarys) {
  Parsed p({"--rate-control"});
  ASSERT_EQ(p.error, "");
  const client::RateControlOptions o = p.flags.Options();
  const client::RateControlOptions d;
  EXPECT_EQ(o.target_delay, d.target_delay);
  EXPECT_EQ(o.start_bps, d.start_bps);
  EXPECT_EQ(o.min_bps, d.min_bps);
  EXPECT_EQ(o.max_bps, d.max_bps);
  EXPECT_EQ(o.cap_replies, d.cap_replies);
  EXPECT_TRUE(o.cap_replies);  // the replies follow the downlink unless told not to
  EXPECT_FALSE(p.flags.AnyGiven());
}

TEST(RateFlagsTest, GivenValuesReachTheOptions) {
  Parsed p({"--rate-control", "--rate-target-delay-ms", "15", "--rate-start-mbps", "2",
            "--rate-min-mbps", "0.5", "--rate-max-mbps", "12"});
  ASSERT_EQ(p.error, "");
  const client::RateControlOptions o = p.flags.Options();
  EXPECT_EQ(o.target_delay, std::chrono::milliseconds(15));
  EXPECT_EQ(o.start_bps, 2e6);
  EXPECT_EQ(o.min_bps, 0.5e6);
  EXPECT_EQ(o.max_bps, 12e6);
  EXPECT_EQ(p.flags.GivenFlags().size(), 4u);
  Parsed off({"--rate-control", "--rate-reply-cap", "false"});
  ASSERT_EQ(off.error, "");
  EXPECT_FALSE(off.flags.Options().cap_replies);
}

TEST(RateFlagsTest, ErrorsNameTheFlag) {
  EXPECT_NE(Parsed({"--rate-target-delay-ms", "15"}).error.find(
                "--rate-target-delay-ms needs --rate-control"),
            std::string::npos);
  EXPECT_NE(Parsed({"--rate-control", "--rate-target-delay-ms", "0"})
                .error.find("--rate-target-delay-ms"),
            std::string::npos);
  EXPECT_NE(Parsed({"--rate-control", "--rate-start-mbps", "nan"}).error.find("--rate-start-mbps"),
            std::string::npos);
  EXPECT_NE(Parsed({"--rate-control", "--rate-min-mbps", "5", "--rate-max-mbps", "2"})
                .error.find("--rate-min-mbps (5) is over --rate-max-mbps (2)"),
            std::string::npos);
  EXPECT_NE(
      Parsed({"--rate-reply-cap", "false"}).error.find("--rate-reply-cap needs --rate-control"),
      std::string::npos);
  EXPECT_NE(Parsed({"--rate-control", "--rate-reply-cap", "maybe"}).error.find("--rate-reply-cap"),
            std::string::npos);
  EXPECT_NE(Parsed({"--rate-control", "--rate-start-mbps", "200"})
                .error.find("--rate-start-mbps (200) is outside"),
            std::string::npos);
}

}  // namespace
}  // namespace cloudcast::cli
