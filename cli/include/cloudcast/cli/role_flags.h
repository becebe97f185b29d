// The input files' flags, one per image role and sort of file, defined once for the programs that
// send frames (cloudcast-client, cloudcast-load): --disparity-glob, --colour-video, --depth,
// --right-glob, ... Each role's flags, their help and their check against --input come from
// sources' roles (sources::RolesOf), so a new frame kind or role needs no new flag code.
//
//   RoleFlags files(app, {FileSort::kGlob}, "Frames");
//   app.parse(argc, argv);
//   auto given = files.Check(kind);           // "--depth-glob does not apply to --input disparity"
//   if (!given.ok()) ...                      // or "--colour-glob needs --right-glob (--input stereo)"
//   spec.globs = files.Given(FileSort::kGlob);
#pragma once

#include <CLI/CLI.hpp>
#include <map>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "cloudcast/sources/frame.h"

namespace cloudcast::cli {

// The sorts of file inputs: a glob of stills (natural order), a video, one still sent again.
enum class FileSort { kGlob, kVideo, kStill };

class RoleFlags {
 public:
  // Registers the flags of `sorts`, every role of each, on `app` (which must outlive this
  // object) in `group`.
  RoleFlags(CLI::App& app, const std::vector<FileSort>& sorts, const std::string& group);
  RoleFlags(const RoleFlags&) = delete;
  RoleFlags& operator=(const RoleFlags&) = delete;

  // After parsing: each sort's flags against `kind`. A flag of a role `kind` does not take, or a
  // role of `kind` left out once its sort is used, is an error naming the flags. Returns the
  // sorts given, each as its flags ("--disparity-glob + --colour-glob"): a program takes one
  // source, so more than one is the caller's usage error.
  absl::StatusOr<std::vector<std::string>> Check(sources::FrameKind kind) const;
  // The paths given of one sort (roles whose flag was not given are absent).
  sources::RolePaths Given(FileSort sort) const;

  // "--depth-glob" for (kDepth, kGlob).
  static std::string Flag(sources::ImageRole role, FileSort sort);

 private:
  std::map<FileSort, sources::RolePaths> paths_;
  std::map<std::string, CLI::Option*> options_;  // by flag
  std::vector<FileSort> sorts_;
};

}  // namespace cloudcast::cli
