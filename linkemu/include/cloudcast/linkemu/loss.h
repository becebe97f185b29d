// Packet loss models of one link direction: independent (Bernoulli) loss and Gilbert-Elliott
// burst loss (a two-state Markov chain, as in netem's "loss gemodel" and RFC 6534's terms).
#pragma once

#include <cstdint>
#include <random>
#include <string>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace cloudcast::linkemu {

// Gilbert-Elliott: in the good state a packet is lost with probability loss_good, in the bad state
// with loss_bad; after each packet the chain moves good -> bad with probability p and bad -> good
// with probability r. The stationary loss rate is (r * loss_good + p * loss_bad) / (p + r); with
// loss_good = 0 and loss_bad = 1 the mean burst length is 1 / r packets.
struct GilbertElliott {
  double p = 0;  // good -> bad, per packet
  double r = 1;  // bad -> good, per packet
  double loss_bad = 1;
  double loss_good = 0;

  bool enabled() const { return p > 0; }
  double StationaryLoss() const { return (r * loss_good + p * loss_bad) / (p + r); }
};

// Parses "p=1%,r=25%[,bad=100%][,good=0%]" (each a percentage or a fraction in [0, 1]); errors name
// `field` and the key.
absl::StatusOr<GilbertElliott> ParseGilbertElliott(absl::string_view field, absl::string_view text);
// Parses a probability: "0.1%" or "0.001"; in [0, 1].
absl::StatusOr<double> ParseProbability(absl::string_view field, absl::string_view text);

// Decides, packet by packet, whether the link loses it: first the random (Bernoulli) loss, then
// the Gilbert-Elliott chain. Seeded, so a run is reproducible.
class LossModel {
 public:
  LossModel(double random_loss, GilbertElliott burst, std::uint64_t seed);
  bool Lose();
  bool in_bad_state() const { return bad_; }

 private:
  double random_loss_;
  GilbertElliott burst_;
  bool bad_ = false;
  std::mt19937_64 rng_;
  std::uniform_real_distribution<double> unit_{0.0, 1.0};
};

}  // namespace cloudcast::linkemu
