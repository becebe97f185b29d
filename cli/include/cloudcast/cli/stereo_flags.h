// The input kind and the stereo matcher flags, defined once for the programs that send frames
// (cloudcast-client, cloudcast-load): --input disparity|depth|stereo, and what a user tunes of
// core's StereoParams (--matcher, --num-disparities, --block-size, ...). Defaults shown in --help
// are StereoParams{}'s, which are also the server's out of the box; a flag left out leaves its
// field unset in the StreamConfig, so the server's configured default applies.
//
//   CLI::App app;
//   std::string input = cloudcast::cli::kDefaultInput;
//   cloudcast::cli::AddInputFlag(app, &input, sources::FrameKindNames(), "Source");
//   cloudcast::cli::StereoFlags stereo(app, "Stereo matcher (--input stereo)");
//   app.parse(argc, argv);
//   if (absl::Status s = stereo.Check(); !s.ok()) ...            // names the flag
//   if (stereo.AnyGiven()) *config.mutable_stereo() = stereo.GivenStereoConfig();
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "cloudcast/core/stereo.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace cloudcast::cli {

// The default frame kind of every program: the disparity map a robot computed itself.
inline constexpr const char* kDefaultInput = "disparity";

// Registers --input on `app`, one of `kinds` (sources::FrameKindNames()), into `*kind`.
CLI::Option* AddInputFlag(CLI::App& app, std::string* kind, const std::vector<std::string>& kinds,
                          const std::string& group);

class StereoFlags {
 public:
  // Registers the flags on `app` (which must outlive this object) in `group`.
  StereoFlags(CLI::App& app, const std::string& group);
  StereoFlags(const StereoFlags&) = delete;
  StereoFlags& operator=(const StereoFlags&) = delete;

  // After parsing: the matcher flags given, on top of StereoParams{}, checked as the server
  // will (StereoParams::Validate); errors name the flag ("--num-disparities is 100; ...").
  absl::Status Check() const;
  // Whether any matcher flag was given, and the names of those that were (for "does not apply
  // to --input depth").
  bool AnyGiven() const { return !GivenFlags().empty(); }
  std::vector<std::string> GivenFlags() const;
  // The flags given as a StereoConfig; the others stay unset.
  v1::StereoConfig GivenStereoConfig() const;
  // The flags given on top of StereoParams{}.
  StereoParams Params() const;

 private:
  CLI::App& app_;
  StereoParams params_;
  std::string matcher_;
};

}  // namespace cloudcast::cli
