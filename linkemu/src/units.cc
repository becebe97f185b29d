#include "cloudcast/linkemu/units.h"

#include <cctype>
#include <cmath>
#include <cstdlib>
#include <string>
#include <utility>

#include "absl/status/status.h"
#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"

namespace cloudcast::linkemu {
namespace {

// Splits "12.5mbit" into 12.5 and "mbit" (lower case); false when no number leads.
bool SplitNumber(absl::string_view text, double* number, std::string* unit) {
  const std::string s(absl::StripAsciiWhitespace(text));
  char* end = nullptr;
  *number = std::strtod(s.c_str(), &end);
  if (end == s.c_str() || !std::isfinite(*number)) return false;
  *unit = absl::AsciiStrToLower(absl::StripAsciiWhitespace(absl::string_view(end)));
  return true;
}

}  // namespace

absl::StatusOr<double> ParseRate(absl::string_view field, absl::string_view text) {
  double number = 0;
  std::string unit;
  if (!SplitNumber(text, &number, &unit)) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, ": '", text, "' is not a rate (e.g. 10mbit, 500kbit, 1gbit)"));
  }
  // "mbit", "mbit/s", "mbps" and "m" are one unit.
  std::string u = unit;
  if (absl::EndsWith(u, "/s")) u.resize(u.size() - 2);
  if (absl::EndsWith(u, "bps")) u = u.substr(0, u.size() - 3) + "bit";
  static constexpr std::pair<absl::string_view, double> kUnits[] = {
      {"", 1}, {"bit", 1}, {"kbit", 1e3}, {"mbit", 1e6}, {"gbit", 1e9}, {"k", 1e3}, {"m", 1e6}};
  for (const auto& [name, scale] : kUnits) {
    if (u == name) {
      if (number < 0) return absl::InvalidArgumentError(absl::StrCat(field, ": rate is negative"));
      return number * scale;
    }
  }
  return absl::InvalidArgumentError(absl::StrCat(field, ": unknown rate unit '", unit, "' in '",
                                                 text, "' (bit, kbit, mbit, gbit)"));
}

absl::StatusOr<Nanos> ParseDuration(absl::string_view field, absl::string_view text) {
  double number = 0;
  std::string unit;
  if (!SplitNumber(text, &number, &unit)) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, ": '", text, "' is not a duration (e.g. 20ms, 1.5s)"));
  }
  double scale = 0;
  if (unit == "ns") scale = 1;
  if (unit == "us") scale = 1e3;
  if (unit == "ms") scale = 1e6;
  if (unit == "s") scale = 1e9;
  if (scale == 0) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, ": '", text, "' needs a unit: ns, us, ms or s (e.g. 20ms)"));
  }
  if (number < 0) return absl::InvalidArgumentError(absl::StrCat(field, ": duration is negative"));
  if (number * scale > 1e6 * 1e9) {
    return absl::InvalidArgumentError(absl::StrCat(field, ": '", text, "' is over 1e6 s"));
  }
  return static_cast<Nanos>(std::llround(number * scale));
}

absl::StatusOr<QueueLimit> ParseQueueLimit(absl::string_view field, absl::string_view text) {
  double number = 0;
  std::string unit;
  if (!SplitNumber(text, &number, &unit) || number <= 0 || number > 1e12) {
    return absl::InvalidArgumentError(absl::StrCat(
        field, ": '", text, "' is not a queue bound above 0 (bytes: 150kB, 64KiB; packets: 100p)"));
  }
  QueueLimit limit;
  const auto whole = static_cast<std::int64_t>(std::llround(number));
  if (unit == "p" || unit == "packets") {
    limit.packets = whole;
    return limit;
  }
  static constexpr std::pair<absl::string_view, double> kUnits[] = {
      {"b", 1}, {"kb", 1e3}, {"kib", 1024}, {"mb", 1e6}, {"mib", 1024.0 * 1024}};
  for (const auto& [name, scale] : kUnits) {
    if (unit == name) {
      limit.bytes = static_cast<std::int64_t>(std::llround(number * scale));
      return limit;
    }
  }
  return absl::InvalidArgumentError(absl::StrCat(field, ": unknown unit '", unit, "' in '", text,
                                                 "' (B, kB, KiB, MB, MiB or p for packets)"));
}

}  // namespace cloudcast::linkemu
