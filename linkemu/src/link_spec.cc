#include "cloudcast/linkemu/link_spec.h"

#include <algorithm>
#include <fstream>
#include <sstream>
#include <utility>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "cloudcast/linkemu/capacity.h"
#include "cloudcast/linkemu/units.h"

namespace cloudcast::linkemu {
namespace {

absl::StatusOr<std::string> ReadFile(absl::string_view field, const std::string& path) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat(field, ": cannot read '", path, "'"));
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

std::string Flag(absl::string_view direction, absl::string_view name) {
  return absl::StrCat("--", direction, "-", name);
}

}  // namespace

DirectionSpec DirectionSpec::OverriddenBy(const DirectionSpec& specific) const {
  DirectionSpec out = *this;
  auto take = [](std::optional<std::string>& to, const std::optional<std::string>& from) {
    if (from) to = from;
  };
  take(out.rate, specific.rate);
  take(out.schedule, specific.schedule);
  take(out.trace, specific.trace);
  take(out.delay, specific.delay);
  take(out.jitter, specific.jitter);
  take(out.loss, specific.loss);
  take(out.burst_loss, specific.burst_loss);
  take(out.queue, specific.queue);
  if (!specific.outages.empty()) out.outages = specific.outages;
  return out;
}

QueueLimit DefaultQueueLimit(double bits_per_second) {
  QueueLimit limit;
  limit.bytes = std::max<std::int64_t>(15000, static_cast<std::int64_t>(bits_per_second / 8 * 0.2));
  return limit;
}

absl::StatusOr<BuiltDirection> BuildDirection(absl::string_view name, const DirectionSpec& spec,
                                              std::uint64_t seed) {
  BuiltDirection built;
  nlohmann::json& d = built.description;
  DirectionConfig config;
  config.seed = seed;
  std::unique_ptr<Capacity> capacity;
  double first_rate = 0;

  if (spec.trace && (spec.rate || spec.schedule || !spec.outages.empty())) {
    return absl::InvalidArgumentError(absl::StrCat(
        Flag(name, "trace"), ": a trace sets the rate; leave out --rate, --schedule and --outage"));
  }
  if (spec.trace) {
    absl::StatusOr<std::string> text = ReadFile(Flag(name, "trace"), *spec.trace);
    if (!text.ok()) return text.status();
    absl::StatusOr<std::unique_ptr<DeliveryTrace>> trace =
        DeliveryTrace::Parse(Flag(name, "trace") + " " + *spec.trace, *text);
    if (!trace.ok()) return trace.status();
    first_rate = (*trace)->MeanRate();
    d["trace"] = {{"file", *spec.trace},
                  {"opportunities", (*trace)->opportunities()},
                  {"period_ms", (*trace)->period() / kMillisecond},
                  {"mean_rate_bps", first_rate}};
    capacity = std::move(*trace);
  } else if (spec.rate || spec.schedule || !spec.outages.empty()) {
    double base = 0;
    if (spec.rate) {
      absl::StatusOr<double> rate = ParseRate(Flag(name, "rate"), *spec.rate);
      if (!rate.ok()) return rate.status();
      base = *rate;
    } else if (!spec.schedule) {
      return absl::InvalidArgumentError(
          absl::StrCat(Flag(name, "outage"), ": an outage needs a rate (--rate)"));
    }
    std::vector<RateStep> steps = {{0, base}};
    if (spec.schedule) {
      std::string text = *spec.schedule;
      if (!text.empty() && text[0] == '@') {
        absl::StatusOr<std::string> file = ReadFile(Flag(name, "schedule"), text.substr(1));
        if (!file.ok()) return file.status();
        text = *file;
      }
      absl::StatusOr<std::vector<RateStep>> parsed =
          ParseSchedule(Flag(name, "schedule"), text, base);
      if (!parsed.ok()) return parsed.status();
      steps = *parsed;
    }
    for (const std::string& outage : spec.outages) {
      const std::vector<std::string> parts = absl::StrSplit(outage, absl::MaxSplits(':', 1));
      const std::string field = absl::StrCat(Flag(name, "outage"), " '", outage, "'");
      if (parts.size() != 2) {
        return absl::InvalidArgumentError(absl::StrCat(field, ": not AT:LENGTH (e.g. 5s:300ms)"));
      }
      absl::StatusOr<Nanos> at = ParseDuration(field + " AT", parts[0]);
      if (!at.ok()) return at.status();
      absl::StatusOr<Nanos> length = ParseDuration(field + " LENGTH", parts[1]);
      if (!length.ok()) return length.status();
      if (*length <= 0) return absl::InvalidArgumentError(field + ": LENGTH must be above 0");
      steps = WithOutage(steps, *at, *length);
    }
    first_rate = steps.front().bits_per_second;
    if (first_rate == 0) {
      for (const RateStep& step : steps) first_rate = std::max(first_rate, step.bits_per_second);
    }
    nlohmann::json schedule = nlohmann::json::array();
    for (const RateStep& step : steps) {
      schedule.push_back({{"at_ms", static_cast<double>(step.at) / kMillisecond},
                          {"rate_bps", step.bits_per_second}});
    }
    d["schedule"] = schedule;
    absl::StatusOr<std::unique_ptr<RateSchedule>> made = RateSchedule::Make(std::move(steps));
    if (!made.ok()) return made.status();
    capacity = std::move(*made);
  }
  if (spec.delay) {
    absl::StatusOr<Nanos> v = ParseDuration(Flag(name, "delay"), *spec.delay);
    if (!v.ok()) return v.status();
    config.delay = *v;
  }
  if (spec.jitter) {
    absl::StatusOr<Nanos> v = ParseDuration(Flag(name, "jitter"), *spec.jitter);
    if (!v.ok()) return v.status();
    config.jitter = *v;
  }
  if (spec.loss) {
    absl::StatusOr<double> v = ParseProbability(Flag(name, "loss"), *spec.loss);
    if (!v.ok()) return v.status();
    config.loss = *v;
  }
  if (spec.burst_loss) {
    absl::StatusOr<GilbertElliott> v =
        ParseGilbertElliott(Flag(name, "burst-loss"), *spec.burst_loss);
    if (!v.ok()) return v.status();
    config.burst = *v;
  }
  if (spec.queue) {
    absl::StatusOr<QueueLimit> v = ParseQueueLimit(Flag(name, "queue"), *spec.queue);
    if (!v.ok()) return v.status();
    config.queue = *v;
  } else if (capacity) {
    config.queue = DefaultQueueLimit(first_rate);
  }
  d["rate_limited"] = capacity != nullptr;
  d["delay_ms"] = static_cast<double>(config.delay) / kMillisecond;
  d["jitter_ms"] = static_cast<double>(config.jitter) / kMillisecond;
  d["loss"] = config.loss;
  if (config.burst.enabled()) {
    d["burst_loss"] = {{"p", config.burst.p},
                       {"r", config.burst.r},
                       {"bad", config.burst.loss_bad},
                       {"good", config.burst.loss_good},
                       {"stationary_loss", config.burst.StationaryLoss()}};
  }
  d["queue_bytes"] = config.queue.bytes;
  d["queue_packets"] = config.queue.packets;
  d["seed"] = seed;
  built.link = std::make_unique<LinkDirection>(config, std::move(capacity));
  return built;
}

nlohmann::json StatsJson(const DirectionStats& s) {
  return {{"packets", s.packets},
          {"bytes", s.bytes},
          {"delivered", s.delivered},
          {"delivered_bytes", s.delivered_bytes},
          {"lost", s.lost},
          {"queue_drops", s.queue_drops},
          {"max_queue_bytes", s.max_queue_bytes},
          {"max_queue_packets", s.max_queue_packets},
          {"max_queue_delay_ms", static_cast<double>(s.max_queue_delay) / kMillisecond}};
}

}  // namespace cloudcast::linkemu
