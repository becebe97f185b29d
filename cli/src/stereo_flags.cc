#include "cloudcast/cli/stereo_flags.h"

#include <tuple>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_replace.h"
#include "cloudcast/proto/convert.h"

namespace cloudcast::cli {
namespace {

// The integer members a user tunes: flag, StereoParams member, StreamConfig setter, help.
using IntMember = std::tuple<const char*, int StereoParams::*,
                             void (v1::StereoConfig::*)(std::int32_t), const char*>;
const std::vector<IntMember>& IntMembers() {
  static const std::vector<IntMember> members = {
      {"--min-disparity", &StereoParams::min_disparity, &v1::StereoConfig::set_min_disparity,
       "Smallest disparity searched, pixels"},
      {"--num-disparities", &StereoParams::num_disparities,
       &v1::StereoConfig::set_num_disparities,
       "Disparities searched from --min-disparity: a positive multiple of 16 (their sum at most "
       "2048)"},
      {"--block-size", &StereoParams::block_size, &v1::StereoConfig::set_block_size,
       "sgm: the census window, 3, 5 or 7; OpenCV's matchers: the block, odd, 1..255 (bm: "
       "5..255)"},
      {"--p1", &StereoParams::p1, &v1::StereoConfig::set_p1,
       "Smoothness penalty for a disparity change of 1; 0: the matcher's own (sgm: 5 for block "
       "5; OpenCV: 8 x block^2)"},
      {"--p2", &StereoParams::p2, &v1::StereoConfig::set_p2,
       "Penalty for larger changes, > --p1; 0: the matcher's own (sgm: 19 for block 5; "
       "OpenCV: 32 x block^2)"},
      {"--uniqueness-ratio", &StereoParams::uniqueness_ratio,
       &v1::StereoConfig::set_uniqueness_ratio,
       "Percent by which the best cost must beat the second best, 0..99"},
      {"--speckle-window-size", &StereoParams::speckle_window_size,
       &v1::StereoConfig::set_speckle_window_size,
       "Largest blob of disparities removed as speckle noise, pixels; 0: no speckle filter"},
      {"--speckle-range", &StereoParams::speckle_range, &v1::StereoConfig::set_speckle_range,
       "Largest disparity step within one speckle blob, pixels"},
      {"--disp12-max-diff", &StereoParams::disp12_max_diff,
       &v1::StereoConfig::set_disp12_max_diff,
       "Left-right consistency tolerance, pixels; -1: no check"},
      {"--paths", &StereoParams::paths, &v1::StereoConfig::set_paths,
       "sgm: 4 or 8 aggregation paths"},
  };
  return members;
}

std::vector<std::string> MatcherNames() {
  std::vector<std::string> names;
  for (StereoMatcher m : AllStereoMatchers()) names.emplace_back(Name(m));
  return names;
}

}  // namespace

CLI::Option* AddInputFlag(CLI::App& app, std::string* kind, const std::vector<std::string>& kinds,
                          const std::string& group) {
  return app
      .add_option("--input", *kind,
                  "What each frame holds: disparity (a disparity map + colour, from the robot's "
                  "own matcher), depth (a depth image + colour: 16-bit mm or float m) or stereo "
                  "(a rectified left + right pair, matched by the server)")
      ->check(CLI::IsMember(kinds))
      ->capture_default_str()
      ->group(group);
}

StereoFlags::StereoFlags(CLI::App& app, const std::string& group)
    : app_(app), matcher_(Name(StereoParams{}.matcher)) {
  app.add_option("--matcher", matcher_,
                 "The server's stereo matcher: sgm (cloudcast's own, the fast one), sgbm, "
                 "sgbm-3way, hh (OpenCV StereoSGBM's modes) or bm (OpenCV StereoBM, cheapest)")
      ->check(CLI::IsMember(MatcherNames()))
      ->capture_default_str()
      ->group(group);
  for (const auto& [flag, member, setter, help] : IntMembers()) {
    app.add_option(flag, params_.*member, help)->capture_default_str()->type_name("INT")->group(
        group);
  }
  app.add_flag("--return-disparity", params_.return_disparity,
               "The server sends the matched disparity map back with each cloud (zstd)")
      ->group(group);
}

std::vector<std::string> StereoFlags::GivenFlags() const {
  std::vector<std::string> given;
  if (app_.count("--matcher") > 0) given.emplace_back("--matcher");
  for (const auto& [flag, member, setter, help] : IntMembers()) {
    if (app_.count(flag) > 0) given.emplace_back(flag);
  }
  if (app_.count("--return-disparity") > 0) given.emplace_back("--return-disparity");
  return given;
}

StereoParams StereoFlags::Params() const {
  StereoParams p = params_;
  ParseStereoMatcher(matcher_, &p.matcher);  // checked by IsMember
  return p;
}

absl::Status StereoFlags::Check() const {
  const absl::Status s = Params().Validate("stereo");
  if (s.ok()) return s;
  // StereoParams names its members (stereo.num_disparities); the user typed flags.
  std::vector<std::pair<std::string, std::string>> renames = {{"stereo.matcher", "--matcher"}};
  for (const auto& [flag, member, setter, help] : IntMembers()) {
    std::string name = std::string(flag).substr(2);
    absl::StrReplaceAll({{"-", "_"}}, &name);
    renames.emplace_back(absl::StrCat("stereo.", name), flag);
  }
  return absl::Status(s.code(), absl::StrReplaceAll(s.message(), renames));
}

v1::StereoConfig StereoFlags::GivenStereoConfig() const {
  v1::StereoConfig c;
  const StereoParams p = Params();
  if (app_.count("--matcher") > 0) c.set_matcher(convert::ToProto(p.matcher));
  for (const auto& [flag, member, setter, help] : IntMembers()) {
    if (app_.count(flag) > 0) (c.*setter)(p.*member);
  }
  if (app_.count("--return-disparity") > 0) c.set_return_disparity(p.return_disparity);
  return c;
}

}  // namespace cloudcast::cli
