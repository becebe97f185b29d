#include "cloudcast/cli/rate_flags.h"

#include <chrono>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "cloudcast/cli/checks.h"

namespace cloudcast::cli {
namespace {

const char* const kFlags[] = {"--rate-target-delay-ms", "--rate-start-mbps", "--rate-min-mbps",
                              "--rate-max-mbps", "--rate-reply-cap"};

}  // namespace

RateFlags::RateFlags(CLI::App& app, const std::string& group) : app_(app) {
  const CLI::Validator kMbps =
      NumberCheck("0.01 to 10000 Mbit/s", [](double v) { return v >= 0.01 && v <= 10000; });
  app.add_option("--rate-target-delay-ms", target_delay_ms_,
                 "With --rate-control: the queueing delay (ms) over which the link counts as "
                 "full. Lower keeps latency lower at the cost of bytes per frame (docs/links.md "
                 "measures it)")
      ->check(NumberCheck("1 to 1000 ms", [](double v) { return v >= 1 && v <= 1000; }))
      ->capture_default_str()
      ->group(group);
  app.add_option("--rate-start-mbps", start_mbps_,
                 "With --rate-control: the bitrate a stream's frames start at, Mbit/s, and its "
                 "replies too (with --rate-reply-cap)")
      ->check(kMbps)
      ->capture_default_str()
      ->group(group);
  app.add_option("--rate-min-mbps", min_mbps_,
                 "With --rate-control: the least the controller sets, Mbit/s (the encoder's floor "
                 "may be higher)")
      ->check(kMbps)
      ->capture_default_str()
      ->group(group);
  app.add_option("--rate-max-mbps", max_mbps_,
                 "With --rate-control: the most the controller sets, Mbit/s")
      ->check(kMbps)
      ->capture_default_str()
      ->group(group);
  app.add_option("--rate-reply-cap", cap_replies_,
                 "With --rate-control: the replies follow the downlink too, each reply's cloud "
                 "capped at the bitrate the downlink carries (never above --max-reply-kb); "
                 "false: replies take what they take")
      ->capture_default_str()
      ->group(group);
}

client::RateControlOptions RateFlags::Options() const {
  client::RateControlOptions o = defaults_;
  o.target_delay = std::chrono::milliseconds(std::lround(target_delay_ms_));
  o.start_bps = start_mbps_ * 1e6;
  o.min_bps = min_mbps_ * 1e6;
  o.max_bps = max_mbps_ * 1e6;
  o.cap_replies = cap_replies_;
  return o;
}

std::vector<std::string> RateFlags::GivenFlags() const {
  std::vector<std::string> given;
  for (const char* flag : kFlags) {
    if (app_.count(flag) > 0) given.emplace_back(flag);
  }
  return given;
}

absl::Status RateFlags::Check(bool rate_control) const {
  if (!rate_control && AnyGiven()) {
    return absl::InvalidArgumentError(
        absl::StrCat(absl::StrJoin(GivenFlags(), ", "),
                     GivenFlags().size() == 1 ? " needs" : " need", " --rate-control"));
  }
  if (min_mbps_ > max_mbps_) {
    return absl::InvalidArgumentError(absl::StrCat("--rate-min-mbps (", min_mbps_,
                                                   ") is over --rate-max-mbps (", max_mbps_, ")"));
  }
  if (start_mbps_ < min_mbps_ || start_mbps_ > max_mbps_) {
    return absl::InvalidArgumentError(absl::StrCat("--rate-start-mbps (", start_mbps_,
                                                   ") is outside --rate-min-mbps .. "
                                                   "--rate-max-mbps (",
                                                   min_mbps_, " .. ", max_mbps_, ")"));
  }
  return absl::OkStatus();
}

}  // namespace cloudcast::cli
