// File names and folders, as the sources find them.
#pragma once

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "cloudcast/sources/frame.h"

namespace cloudcast::sources {

// Natural order: runs of digits compare by their value ("f2" < "f10", "f01" == "f1" by value),
// everything else byte by byte (unsigned). Names equal but for zero padding fall back to plain
// byte order, so the order is strict and total: "f01" < "f1".
bool NaturalLess(const std::string& a, const std::string& b);
void NaturalSort(std::vector<std::string>* names);

// The regular files a POSIX glob pattern matches (wildcards *, ? and [...] anywhere in the path;
// no braces, no ~), in natural order. Folders that match are left out. Empty when nothing
// matches; an error only when the pattern cannot be expanded (a folder that cannot be read).
absl::StatusOr<std::vector<std::string>> Glob(const std::string& pattern);

// The four-character code of a video codec as text ("FFV1", "png "), and whether that codec
// keeps 8-bit grey values exactly.
std::string FourccToString(int fourcc);
bool IsLosslessCodec(const std::string& fourcc);

// The folder of a New Tsukuba tree that holds `role`'s images: the left camera's, but for kRight.
// The data set has no depth maps: kDepth is the ground-truth disparity's folder (OpenTsukuba
// converts it).
std::string TsukubaFolder(const std::string& dir, ImageRole role, const std::string& illumination);
// Whether `dir` holds the New Tsukuba layout for `kind` (each role's folder exists).
bool LooksLikeTsukuba(const std::string& dir, const std::string& illumination,
                      FrameKind kind = FrameKind::kDisparity);

}  // namespace cloudcast::sources
