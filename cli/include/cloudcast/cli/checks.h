// Flag checks and help formatting shared by the command-line programs (cloudcast-process,
// cloudcast-client). CLI11's own number conversion accepts "nan" and "inf"; these validators see
// the raw string and refuse them, and say what was expected.
#pragma once

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <functional>
#include <string>

namespace cloudcast::cli {

inline bool ParseDouble(const std::string& s, double* v) {
  if (s.empty()) return false;
  char* end = nullptr;
  *v = std::strtod(s.c_str(), &end);
  return end == s.c_str() + s.size();
}

// A finite number for which `ok` holds; the message reads "must be <what>, got '<text>'".
inline CLI::Validator NumberCheck(const std::string& what, std::function<bool(double)> ok) {
  return CLI::Validator(
      [what, ok = std::move(ok)](std::string& s) -> std::string {
        double v = 0;
        if (!ParseDouble(s, &v) || !std::isfinite(v) || !ok(v)) {
          return "must be " + what + ", got '" + s + "'";
        }
        return std::string();
      },
      "", "");
}

// "WIDTHxHEIGHT", e.g. 640x480.
inline bool ParseSize(const std::string& s, std::uint32_t* w, std::uint32_t* h) {
  const auto x = s.find_first_of("xX");
  if (x == std::string::npos || x == 0 || x + 1 == s.size()) return false;
  const std::string ws = s.substr(0, x), hs = s.substr(x + 1);
  auto digits = [](const std::string& t) {
    return t.size() <= 9 &&
           std::all_of(t.begin(), t.end(), [](char c) { return c >= '0' && c <= '9'; });
  };
  if (!digits(ws) || !digits(hs)) return false;
  *w = static_cast<std::uint32_t>(std::stoul(ws));
  *h = static_cast<std::uint32_t>(std::stoul(hs));
  return true;
}

// A WIDTHxHEIGHT within 1..max_side per side and at most max_pixels in all.
inline CLI::Validator SizeCheck(std::uint32_t max_side, std::uint64_t max_pixels) {
  return CLI::Validator(
      [=](std::string& s) -> std::string {
        std::uint32_t w = 0, h = 0;
        if (!ParseSize(s, &w, &h)) return "must be WIDTHxHEIGHT, e.g. 640x480, got '" + s + "'";
        if (w == 0 || h == 0 || w > max_side || h > max_side || std::uint64_t{w} * h > max_pixels) {
          return "'" + s + "' is outside the limits: 1.." + std::to_string(max_side) +
                 " pixels per side, at most " + std::to_string(max_pixels) + " pixels";
        }
        return std::string();
      },
      "", "");
}

// CLI11 2.1 does not wrap descriptions but indents the lines after a '\n', so wrapping at 64
// columns keeps --help within 100.
inline std::string Wrap(const std::string& text, std::size_t width = 64) {
  std::string out, line;
  std::size_t start = 0;
  while (start <= text.size()) {
    std::size_t end = text.find(' ', start);
    if (end == std::string::npos) end = text.size();
    const std::string word = text.substr(start, end - start);
    if (!line.empty() && line.size() + 1 + word.size() > width) {
      out += line + "\n";
      line.clear();
    }
    line += (line.empty() ? "" : " ") + word;
    start = end + 1;
  }
  return out + line;
}

}  // namespace cloudcast::cli
