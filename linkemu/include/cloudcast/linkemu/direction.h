// One direction of the emulated link, the pure part of the emulator: for each packet offered at
// time `now` it decides whether the bounded drop-tail queue takes it, when its serialization at
// the link's rate ends, whether the link loses it, and when it comes out at the far end (one-way
// delay plus jitter, never reordered). Time is passed in, never read, so tests inject it.
#pragma once

#include <cstdint>
#include <deque>
#include <memory>
#include <random>

#include "cloudcast/linkemu/capacity.h"
#include "cloudcast/linkemu/clock.h"
#include "cloudcast/linkemu/loss.h"
#include "cloudcast/linkemu/units.h"

namespace cloudcast::linkemu {

struct DirectionConfig {
  Nanos delay = 0;   // one-way propagation delay
  Nanos jitter = 0;  // standard deviation of a normal variation of the delay (clamped at 0)
  double loss = 0;   // random (Bernoulli) loss, per packet
  GilbertElliott burst;
  QueueLimit queue;  // both 0: no bound
  std::uint64_t seed = 1;
};

struct DirectionStats {
  std::int64_t packets = 0, bytes = 0;  // offered
  std::int64_t delivered = 0, delivered_bytes = 0;
  std::int64_t lost = 0;                                    // by the loss models
  std::int64_t queue_drops = 0;                             // the queue was full
  std::int64_t max_queue_bytes = 0, max_queue_packets = 0;  // including the packet in service
  Nanos max_queue_delay = 0;                                // waiting before serialization
};

class LinkDirection {
 public:
  enum class Fate { kDeliver, kLose, kQueueDrop };
  struct Decision {
    Fate fate;
    // When to let the packet go (kDeliver) or to drop it (kLose: it used the link's time, as a
    // frame lost on the air does); `now` for kQueueDrop. kNever: the link never carries it.
    Nanos release_at;
  };

  // `capacity` null: no rate limit (only delay, jitter and loss).
  LinkDirection(DirectionConfig config, std::unique_ptr<Capacity> capacity);

  // Times passed to Offer never decrease.
  Decision Offer(Nanos now, std::int64_t bytes);
  // Bytes and packets waiting or in serialization at `now` (updates the view of the queue).
  std::int64_t QueuedBytes(Nanos now);
  std::int64_t QueuedPackets(Nanos now);
  const DirectionStats& stats() const { return stats_; }

 private:
  struct InService {
    Nanos finish;
    std::int64_t bytes;
  };
  void Drain(Nanos now);

  DirectionConfig config_;
  std::unique_ptr<Capacity> capacity_;
  LossModel loss_;
  std::mt19937_64 jitter_rng_;
  std::normal_distribution<double> jitter_;
  std::deque<InService> backlog_;  // accepted, not yet serialized, in order
  std::int64_t backlog_bytes_ = 0;
  Nanos link_free_at_ = 0;
  Nanos last_release_ = 0;
  DirectionStats stats_;
};

}  // namespace cloudcast::linkemu
