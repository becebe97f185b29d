#include "cloudcast/linkemu/direction.h"

#include <algorithm>
#include <cmath>
#include <utility>

namespace cloudcast::linkemu {

LinkDirection::LinkDirection(DirectionConfig config, std::unique_ptr<Capacity> capacity)
    : config_(config),
      capacity_(std::move(capacity)),
      loss_(config.loss, config.burst, config.seed),
      jitter_rng_(config.seed ^ 0x9e3779b97f4a7c15ULL),
      jitter_(0.0, static_cast<double>(config.jitter)) {}

void LinkDirection::Drain(Nanos now) {
  while (!backlog_.empty() && backlog_.front().finish <= now) {
    backlog_bytes_ -= backlog_.front().bytes;
    backlog_.pop_front();
  }
}

std::int64_t LinkDirection::QueuedBytes(Nanos now) {
  Drain(now);
  return backlog_bytes_;
}

std::int64_t LinkDirection::QueuedPackets(Nanos now) {
  Drain(now);
  return static_cast<std::int64_t>(backlog_.size());
}

LinkDirection::Decision LinkDirection::Offer(Nanos now, std::int64_t bytes) {
  ++stats_.packets;
  stats_.bytes += bytes;
  Drain(now);
  const QueueLimit& limit = config_.queue;
  if ((limit.bytes > 0 && backlog_bytes_ + bytes > limit.bytes) ||
      (limit.packets > 0 && static_cast<std::int64_t>(backlog_.size()) + 1 > limit.packets)) {
    ++stats_.queue_drops;
    return {Fate::kQueueDrop, now};
  }
  const Nanos start = std::max(now, link_free_at_);
  const Nanos finish = capacity_ ? capacity_->Finish(start, bytes) : start;
  if (capacity_) {
    link_free_at_ = finish;
    backlog_.push_back({finish, bytes});
    backlog_bytes_ += bytes;
    stats_.max_queue_bytes = std::max(stats_.max_queue_bytes, backlog_bytes_);
    stats_.max_queue_packets =
        std::max(stats_.max_queue_packets, static_cast<std::int64_t>(backlog_.size()));
    if (start != kNever) stats_.max_queue_delay = std::max(stats_.max_queue_delay, start - now);
  }
  const bool lost = loss_.Lose();
  Nanos release = kNever;
  if (finish != kNever) {
    Nanos delay = config_.delay;
    if (config_.jitter > 0) {
      delay = std::max<Nanos>(
          0, config_.delay + static_cast<Nanos>(std::llround(jitter_(jitter_rng_))));
    }
    // First in, first out: jitter stretches gaps but never reorders packets.
    release = std::max(last_release_, finish + delay);
    last_release_ = release;
  }
  if (lost) {
    ++stats_.lost;
    return {Fate::kLose, release};
  }
  ++stats_.delivered;
  stats_.delivered_bytes += bytes;
  return {Fate::kDeliver, release};
}

}  // namespace cloudcast::linkemu
