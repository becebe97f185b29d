#include "cloudcast/cli/role_flags.h"

#include <algorithm>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"

namespace cloudcast::cli {
namespace {

using sources::ImageRole;

constexpr ImageRole kRoles[] = {ImageRole::kDisparity, ImageRole::kColour, ImageRole::kDepth,
                                ImageRole::kRight};

const char* Suffix(FileSort sort) {
  switch (sort) {
    case FileSort::kGlob:
      return "-glob";
    case FileSort::kVideo:
      return "-video";
    case FileSort::kStill:
      return "";
  }
  return "";
}

std::string Help(ImageRole role, FileSort sort) {
  switch (role) {
    case ImageRole::kDisparity:
      switch (sort) {
        case FileSort::kGlob:
          return "Disparity images, a glob in quotes (e.g. 'd/*.png'), natural sort order; "
                 "8/16-bit PNG/TIFF or float TIFF/PFM";
        case FileSort::kVideo:
          return "Disparity video; must be lossless (PNG in .avi, FFV1 in .mkv): lossy codecs "
                 "change disparities (warned)";
        case FileSort::kStill:
          return "One disparity image, sent again and again with --colour (endless)";
      }
      break;
    case ImageRole::kColour:
      switch (sort) {
        case FileSort::kGlob:
          return "Colour images (of a stereo pair: the left ones) paired with the other glob in "
                 "sorted order (the counts must match)";
        case FileSort::kVideo:
          return "Colour video (stereo: the left one) paired frame by frame with the other video "
                 "(HuffYUV in .avi: exact, and decodes faster than PNG stills)";
        case FileSort::kStill:
          return "The colour image for --disparity or --depth, or the left image for --right";
      }
      break;
    case ImageRole::kDepth:
      switch (sort) {
        case FileSort::kGlob:
          return "--input depth: depth images, a glob in quotes; 16-bit PNG (millimetres) or "
                 "float TIFF/PFM (metres)";
        case FileSort::kVideo:
          return "--input depth: a lossless 16-bit depth video (FFV1 gray16 in .mkv)";
        case FileSort::kStill:
          return "--input depth: one depth image, sent again and again with --colour (endless)";
      }
      break;
    case ImageRole::kRight:
      switch (sort) {
        case FileSort::kGlob:
          return "--input stereo: the right images of rectified pairs, a glob in quotes, paired "
                 "with --colour-glob (the left images)";
        case FileSort::kVideo:
          return "--input stereo: the right video, paired with --colour-video (the left)";
        case FileSort::kStill:
          return "--input stereo: one right image, sent again and again with --colour (the left)";
      }
      break;
  }
  return "";
}

}  // namespace

std::string RoleFlags::Flag(ImageRole role, FileSort sort) {
  return sources::RoleFlag(role, Suffix(sort));
}

RoleFlags::RoleFlags(CLI::App& app, const std::vector<FileSort>& sorts, const std::string& group)
    : sorts_(sorts) {
  for (FileSort sort : sorts_) {
    for (ImageRole role : kRoles) {
      const std::string flag = Flag(role, sort);
      options_[flag] = app.add_option(flag, paths_[sort][role], Help(role, sort))
                           ->type_name(sort == FileSort::kGlob ? "GLOB" : "FILE")
                           ->group(group);
    }
  }
}

absl::StatusOr<std::vector<std::string>> RoleFlags::Check(sources::FrameKind kind) const {
  const std::vector<ImageRole>& roles = sources::RolesOf(kind);
  const std::string input = sources::Name(kind);
  auto given = [this](const std::string& flag) { return options_.at(flag)->count() > 0; };
  std::vector<std::string> sorts_given;
  for (FileSort sort : sorts_) {
    std::vector<std::string> names;
    for (ImageRole role : kRoles) {
      const std::string flag = Flag(role, sort);
      if (!given(flag)) continue;
      if (std::find(roles.begin(), roles.end(), role) == roles.end()) {
        std::vector<std::string> wanted;
        for (ImageRole r : roles) wanted.push_back(Flag(r, sort));
        return absl::InvalidArgumentError(absl::StrCat(flag, " does not apply to --input ", input,
                                                       " (it takes ", absl::StrJoin(wanted, " and "),
                                                       ")"));
      }
      names.push_back(flag);
    }
    if (names.empty()) continue;
    for (ImageRole role : roles) {
      const std::string flag = Flag(role, sort);
      if (!given(flag)) {
        return absl::InvalidArgumentError(absl::StrCat(absl::StrJoin(names, " + "), " needs ",
                                                       flag, " (--input ", input, ")"));
      }
    }
    sorts_given.push_back(absl::StrJoin(names, " + "));
  }
  return sorts_given;
}

sources::RolePaths RoleFlags::Given(FileSort sort) const {
  sources::RolePaths given;
  auto it = paths_.find(sort);
  if (it == paths_.end()) return given;
  for (const auto& [role, path] : it->second) {
    if (options_.at(Flag(role, sort))->count() > 0) given[role] = path;
  }
  return given;
}

}  // namespace cloudcast::cli
