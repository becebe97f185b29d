#include "cloudcast/linkemu/capacity.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <string>

#include "absl/status/status.h"
#include "absl/strings/ascii.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "cloudcast/linkemu/units.h"

namespace cloudcast::linkemu {

absl::StatusOr<std::unique_ptr<RateSchedule>> RateSchedule::Make(std::vector<RateStep> steps) {
  if (steps.empty() || steps.front().at != 0) {
    return absl::InvalidArgumentError("rate schedule: the first step must be at time 0");
  }
  for (std::size_t i = 1; i < steps.size(); ++i) {
    if (steps[i].at <= steps[i - 1].at) {
      return absl::InvalidArgumentError("rate schedule: step times must increase");
    }
  }
  return std::unique_ptr<RateSchedule>(new RateSchedule(std::move(steps)));
}

Nanos RateSchedule::Finish(Nanos start, std::int64_t bytes) {
  while (segment_ + 1 < steps_.size() && steps_[segment_ + 1].at <= start) ++segment_;
  double bits = 8.0 * static_cast<double>(bytes);
  Nanos t = start;
  for (std::size_t k = segment_; k < steps_.size(); ++k) {
    const Nanos end = k + 1 < steps_.size() ? steps_[k + 1].at : kNever;
    const double rate = steps_[k].bits_per_second;
    if (rate > 0) {
      const double need = bits / rate * 1e9;  // ns at this rate
      if (end == kNever || static_cast<double>(t) + need <= static_cast<double>(end)) {
        return t + static_cast<Nanos>(std::ceil(need));
      }
      bits -= static_cast<double>(end - t) * rate / 1e9;
    }
    t = end;
  }
  return kNever;  // the last step is an outage that never ends
}

absl::StatusOr<std::vector<RateStep>> ParseSchedule(absl::string_view field, absl::string_view text,
                                                    double base) {
  std::vector<RateStep> steps = {{0, base}};
  for (absl::string_view line : absl::StrSplit(text, absl::ByAnyChar(",;\n"))) {
    line = line.substr(0, line.find('#'));
    line = absl::StripAsciiWhitespace(line);
    if (line.empty()) continue;
    const std::vector<absl::string_view> kv = absl::StrSplit(line, absl::MaxSplits('=', 1));
    if (kv.size() != 2) {
      return absl::InvalidArgumentError(
          absl::StrCat(field, ": entry '", line, "' is not TIME=RATE (e.g. 5s=3mbit, 8s=down)"));
    }
    const std::string entry = absl::StrCat(field, " entry '", line, "'");
    absl::StatusOr<Nanos> at = ParseDuration(entry, absl::StripAsciiWhitespace(kv[0]));
    if (!at.ok()) return at.status();
    const absl::string_view rate_text = absl::StripAsciiWhitespace(kv[1]);
    double rate = 0;
    if (rate_text != "down") {
      absl::StatusOr<double> parsed = ParseRate(entry, rate_text);
      if (!parsed.ok()) return parsed.status();
      rate = *parsed;
    }
    if (*at == 0) {
      steps.front().bits_per_second = rate;
    } else if (*at <= steps.back().at) {
      return absl::InvalidArgumentError(
          absl::StrCat(entry, ": times must increase from one entry to the next"));
    } else {
      steps.push_back({*at, rate});
    }
  }
  return steps;
}

std::vector<RateStep> WithOutage(const std::vector<RateStep>& steps, Nanos at, Nanos length) {
  const Nanos end = at + length;
  double after = 0;
  for (const RateStep& step : steps) {
    if (step.at <= end) after = step.bits_per_second;
  }
  std::vector<RateStep> out;
  for (const RateStep& step : steps) {
    if (step.at < at || step.at > end) out.push_back(step);
  }
  out.push_back({at, 0});
  out.push_back({end, after});
  std::sort(out.begin(), out.end(),
            [](const RateStep& a, const RateStep& b) { return a.at < b.at; });
  // An outage from 0 replaces the first step; equal times keep the later entry.
  std::vector<RateStep> unique;
  for (const RateStep& step : out) {
    if (!unique.empty() && unique.back().at == step.at) {
      unique.back() = step;
    } else {
      unique.push_back(step);
    }
  }
  return unique;
}

absl::StatusOr<std::unique_ptr<DeliveryTrace>> DeliveryTrace::Parse(absl::string_view field,
                                                                    absl::string_view text) {
  std::vector<Nanos> times;
  int line_number = 0;
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    ++line_number;
    line = absl::StripAsciiWhitespace(line);
    if (line.empty()) continue;
    std::int64_t ms = 0;
    if (!absl::SimpleAtoi(line, &ms) || ms < 0) {
      return absl::InvalidArgumentError(absl::StrCat(
          field, " line ", line_number, ": '", line,
          "' is not a time in milliseconds (Mahimahi's format: one integer per line)"));
    }
    if (!times.empty() && ms * kMillisecond < times.back()) {
      return absl::InvalidArgumentError(absl::StrCat(field, " line ", line_number, ": ", ms,
                                                     " ms is before the line above (times must not "
                                                     "decrease)"));
    }
    times.push_back(ms * kMillisecond);
  }
  if (times.empty() || times.back() <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat(field,
                     ": no delivery opportunity after time 0 (the trace's period is its "
                     "last time, which must be above 0)"));
  }
  const Nanos period = times.back();
  return std::unique_ptr<DeliveryTrace>(new DeliveryTrace(std::move(times), period));
}

double DeliveryTrace::MeanRate() const {
  return static_cast<double>(times_.size()) * kBytesPerOpportunity * 8.0 /
         (static_cast<double>(period_) / 1e9);
}

Nanos DeliveryTrace::TimeOf(std::int64_t index) const {
  const auto n = static_cast<std::int64_t>(times_.size());
  return (index / n) * period_ + times_[static_cast<std::size_t>(index % n)];
}

std::int64_t DeliveryTrace::FirstAtOrAfter(Nanos t) const {
  const auto n = static_cast<std::int64_t>(times_.size());
  const std::int64_t cycle = t / period_;
  const Nanos within = t - cycle * period_;
  const auto it = std::lower_bound(times_.begin(), times_.end(), within);
  return cycle * n + (it - times_.begin());  // past the end: the next cycle's first
}

Nanos DeliveryTrace::Finish(Nanos start, std::int64_t bytes) {
  std::int64_t remaining = bytes;
  // The rest of the last opportunity serves this packet only if the packet was waiting then.
  if (last_ >= 0 && leftover_ > 0 && start <= TimeOf(last_)) {
    const std::int64_t used = std::min(leftover_, remaining);
    leftover_ -= used;
    remaining -= used;
    if (remaining == 0) return TimeOf(last_);
  }
  std::int64_t index = std::max(last_ + 1, FirstAtOrAfter(start));
  const std::int64_t needed = (remaining + kBytesPerOpportunity - 1) / kBytesPerOpportunity;
  index += needed - 1;
  last_ = index;
  leftover_ = needed * kBytesPerOpportunity - remaining;
  return TimeOf(index);
}

}  // namespace cloudcast::linkemu
