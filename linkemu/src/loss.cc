#include "cloudcast/linkemu/loss.h"

#include <cmath>
#include <cstdlib>
#include <string>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"

namespace cloudcast::linkemu {

absl::StatusOr<double> ParseProbability(absl::string_view field, absl::string_view text) {
  const bool percent = absl::ConsumeSuffix(&text, "%");
  const std::string number(text);
  char* end = nullptr;
  const double value = std::strtod(number.c_str(), &end);
  if (number.empty() || end != number.c_str() + number.size() || !std::isfinite(value)) {
    return absl::InvalidArgumentError(absl::StrCat(
        field, ": '", number, percent ? "%" : "",
        "' is not a probability (a percentage such as 0.1% or a fraction such as 0.001)"));
  }
  const double probability = percent ? value / 100.0 : value;
  if (probability < 0 || probability > 1) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, ": ", number, percent ? "%" : "", " is outside [0, 100%]"));
  }
  return probability;
}

absl::StatusOr<GilbertElliott> ParseGilbertElliott(absl::string_view field,
                                                   absl::string_view text) {
  GilbertElliott model;
  bool have_p = false, have_r = false;
  for (absl::string_view item : absl::StrSplit(text, ',', absl::SkipWhitespace())) {
    const std::vector<absl::string_view> kv = absl::StrSplit(item, absl::MaxSplits('=', 1));
    if (kv.size() != 2) {
      return absl::InvalidArgumentError(absl::StrCat(
          field, ": '", item, "' is not key=value (keys: p, r, bad, good; e.g. p=1%,r=25%)"));
    }
    const std::string name = absl::StrCat(field, ".", kv[0]);
    absl::StatusOr<double> value = ParseProbability(name, kv[1]);
    if (!value.ok()) return value.status();
    if (kv[0] == "p") {
      model.p = *value;
      have_p = true;
    } else if (kv[0] == "r") {
      model.r = *value;
      have_r = true;
    } else if (kv[0] == "bad") {
      model.loss_bad = *value;
    } else if (kv[0] == "good") {
      model.loss_good = *value;
    } else {
      return absl::InvalidArgumentError(
          absl::StrCat(field, ": unknown key '", kv[0], "' (keys: p, r, bad, good)"));
    }
  }
  if (!have_p || !have_r) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, ": needs both p (good -> bad) and r (bad -> good), e.g. p=1%,r=25%"));
  }
  if (model.r <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, ".r: must be above 0 (else the bad state never ends)"));
  }
  return model;
}

LossModel::LossModel(double random_loss, GilbertElliott burst, std::uint64_t seed)
    : random_loss_(random_loss), burst_(burst), rng_(seed) {}

bool LossModel::Lose() {
  bool lost = random_loss_ > 0 && unit_(rng_) < random_loss_;
  if (burst_.enabled()) {
    const double loss = bad_ ? burst_.loss_bad : burst_.loss_good;
    if (loss > 0 && unit_(rng_) < loss) lost = true;
    // The state for the next packet.
    bad_ = bad_ ? !(unit_(rng_) < burst_.r) : unit_(rng_) < burst_.p;
  }
  return lost;
}

}  // namespace cloudcast::linkemu
