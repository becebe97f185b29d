// The rate controller's settings (client::RateControlOptions), defined once for the programs
// that send frames under --rate-control (cloudcast-client, cloudcast-load): --rate-target-delay-ms,
// --rate-start-mbps, --rate-min-mbps, --rate-max-mbps, --rate-reply-cap. Defaults are the
// library's; bad values are refused by the parser with the flag's name.
//
//   cloudcast::cli::RateFlags rate(app, "Rate control");
//   app.parse(argc, argv);
//   if (!rate_control && rate.AnyGiven()) ...   // "--rate-target-delay-ms needs --rate-control"
//   stream_options.rate_control = rate.Options();
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "cloudcast/client/rate_controller.h"

namespace cloudcast::cli {

class RateFlags {
 public:
  // Registers the flags on `app` (which must outlive this object) in `group`.
  RateFlags(CLI::App& app, const std::string& group);
  RateFlags(const RateFlags&) = delete;
  RateFlags& operator=(const RateFlags&) = delete;

  client::RateControlOptions Options() const;
  // The --rate-* flags given, in the order registered (for "needs --rate-control").
  std::vector<std::string> GivenFlags() const;
  bool AnyGiven() const { return !GivenFlags().empty(); }
  // INVALID_ARGUMENT naming the flags when --rate-* settings came without --rate-control, or the
  // bitrates contradict one another (min <= start <= max).
  absl::Status Check(bool rate_control) const;

 private:
  CLI::App& app_;
  client::RateControlOptions defaults_;
  double target_delay_ms_ = static_cast<double>(defaults_.target_delay.count());
  double start_mbps_ = defaults_.start_bps / 1e6;
  double min_mbps_ = defaults_.min_bps / 1e6;
  double max_mbps_ = defaults_.max_bps / 1e6;
  bool cap_replies_ = defaults_.cap_replies;
};

}  // namespace cloudcast::cli
