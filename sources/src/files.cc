#include "cloudcast/sources/files.h"

#include <glob.h>

#include <algorithm>
#include <cctype>
#include <filesystem>

#include "absl/strings/str_cat.h"

namespace cloudcast::sources {
namespace {

namespace fs = std::filesystem;

bool IsDigit(char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; }

}  // namespace

bool NaturalLess(const std::string& a, const std::string& b) {
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (IsDigit(a[i]) && IsDigit(b[j])) {
      std::size_t ei = i, ej = j;
      while (ei < a.size() && IsDigit(a[ei])) ++ei;
      while (ej < b.size() && IsDigit(b[ej])) ++ej;
      // Compare by value without overflow: skip leading zeros, then length, then digits.
      std::size_t zi = i, zj = j;
      while (zi + 1 < ei && a[zi] == '0') ++zi;
      while (zj + 1 < ej && b[zj] == '0') ++zj;
      if (ei - zi != ej - zj) return ei - zi < ej - zj;
      const int c = a.compare(zi, ei - zi, b, zj, ej - zj);
      if (c != 0) return c < 0;
      i = ei;
      j = ej;
      continue;
    }
    if (a[i] != b[j]) return static_cast<unsigned char>(a[i]) < static_cast<unsigned char>(b[j]);
    ++i;
    ++j;
  }
  if ((a.size() - i) != (b.size() - j)) return a.size() - i < b.size() - j;
  return a < b;  // equal up to zero padding: byte order keeps the order strict
}

void NaturalSort(std::vector<std::string>* names) {
  std::sort(names->begin(), names->end(), NaturalLess);
}

absl::StatusOr<std::vector<std::string>> Glob(const std::string& pattern) {
  glob_t g{};
  // Sorted below, naturally; glob's own sort would be byte order.
  const int rc = ::glob(pattern.c_str(), GLOB_NOSORT, nullptr, &g);
  std::vector<std::string> out;
  if (rc == 0) {
    for (std::size_t i = 0; i < g.gl_pathc; ++i) {
      std::error_code ec;
      if (fs::is_regular_file(g.gl_pathv[i], ec)) out.emplace_back(g.gl_pathv[i]);
    }
  }
  ::globfree(&g);
  if (rc != 0 && rc != GLOB_NOMATCH) {
    return absl::InvalidArgumentError(
        absl::StrCat("cannot expand '", pattern, "' (glob error ", rc, ")"));
  }
  NaturalSort(&out);
  return out;
}

std::string FourccToString(int fourcc) {
  std::string s;
  for (int i = 0; i < 4; ++i) {
    const char c = static_cast<char>((fourcc >> (8 * i)) & 0xFF);
    s += std::isprint(static_cast<unsigned char>(c)) ? c : '?';
  }
  return s;
}

bool IsLosslessCodec(const std::string& fourcc) {
  // Codecs that store 8-bit grey exactly. HuffYUV is left out: OpenCV writes grey through YUV,
  // which moved values by 1 when measured here.
  static const char* const kLossless[] = {"FFV1", "png ", "PNG ", "MPNG", "Y800", "GREY",
                                          "Y8  ", "Y16 ", "RGB ", "BGR ", "RAW ", "raw ",
                                          "DIB ", "LAGS", "UTVD", "ULY0", "ULRG", "ZMBV"};
  for (const char* c : kLossless) {
    if (fourcc == c) return true;
  }
  return false;
}

std::string TsukubaFolder(const std::string& dir, ImageRole role, const std::string& illumination) {
  switch (role) {
    case ImageRole::kDisparity:
    case ImageRole::kDepth:  // no depth maps: the ground-truth disparity, converted
      return (fs::path(dir) / "groundtruth" / "disparity_maps" / "left").string();
    case ImageRole::kColour:
      return (fs::path(dir) / "illumination" / illumination / "left").string();
    case ImageRole::kRight:
      return (fs::path(dir) / "illumination" / illumination / "right").string();
  }
  return dir;
}

bool LooksLikeTsukuba(const std::string& dir, const std::string& illumination, FrameKind kind) {
  std::error_code ec;
  for (ImageRole role : RolesOf(kind)) {
    if (!fs::is_directory(TsukubaFolder(dir, role, illumination), ec)) return false;
  }
  return true;
}

}  // namespace cloudcast::sources
