#include "stream_queue.h"

#include <algorithm>

namespace cloudcast::server {

using convert::Delivery;

StreamQueue::StreamQueue(std::uint32_t max_held)
    : max_held_(std::max<std::uint32_t>(1, max_held)) {}

void StreamQueue::PushFrame(StreamSlot* slot, std::vector<StreamSlot*>* dropped) {
  slot->kind = StreamSlot::Kind::kFrame;
  if (slot->delivery == Delivery::kLatest) {
    for (auto it = waiting_.begin(); it != waiting_.end();) {
      StreamSlot* s = *it;
      if (s->kind == StreamSlot::Kind::kFrame && s->delivery == Delivery::kLatest) {
        it = waiting_.erase(it);
        --held_;
        ++dropped_;
        if (writing_) ++dropped_during_write_;
        dropped->push_back(s);
      } else {
        ++it;
      }
    }
  }
  waiting_.push_back(slot);
  ++held_;
}

void StreamQueue::PushReply(StreamSlot* slot) {
  slot->kind = StreamSlot::Kind::kReply;
  waiting_.push_back(slot);
  ++held_;
}

StreamSlot* StreamQueue::NextToProcess() {
  while (!abandoned_ && !waiting_.empty()) {
    StreamSlot* slot = waiting_.front();
    if (slot->kind == StreamSlot::Kind::kReply) {
      // Nothing to do but take its place in the reply order.
      waiting_.pop_front();
      slot->order = next_order_++;
      reorder_.push_back(slot);
      ++ready_;
      continue;
    }
    // DELIVERY_LATEST: one frame in work, and none started while a finished reply waits for the
    // writer, so a slow reader gets drops rather than a growing backlog.
    if (slot->delivery == Delivery::kLatest && (in_work_ > 0 || ready_ > 0)) return nullptr;
    waiting_.pop_front();
    slot->order = next_order_++;
    reorder_.push_back(nullptr);  // its place, filled by Processed
    ++in_work_;
    return slot;
  }
  return nullptr;
}

bool StreamQueue::Processed(StreamSlot* slot) {
  --in_work_;
  if (abandoned_) {
    --held_;
    return false;
  }
  reorder_[slot->order - next_write_order_] = slot;
  ++ready_;
  return true;
}

StreamSlot* StreamQueue::NextToWrite() {
  if (abandoned_ || writing_ || reorder_.empty() || reorder_.front() == nullptr) return nullptr;
  StreamSlot* slot = reorder_.front();
  reorder_.pop_front();
  --ready_;
  ++next_write_order_;
  writing_ = true;
  return slot;
}

void StreamQueue::Written() {
  writing_ = false;
  dropped_during_write_ = 0;
  --held_;
}

bool StreamQueue::CanRead(Delivery current) const {
  if (abandoned_) return false;
  if (current == Delivery::kAll) return held_ < max_held_;
  // A client that does not take its replies gets no more frames read than this.
  if (writing_ && dropped_during_write_ >= kMaxDropsPerWrite) return false;
  // DELIVERY_LATEST keeps reading so that the newest frame is the one waiting; a waiting frame
  // will be replaced, so it does not count. Error replies and unwritten clouds do, so that a
  // client that sends bad configs and reads nothing cannot grow the queue.
  std::uint32_t replaceable = 0;
  for (const StreamSlot* s : waiting_) {
    if (s->kind == StreamSlot::Kind::kFrame && s->delivery == Delivery::kLatest) ++replaceable;
  }
  return held_ - replaceable < std::max<std::uint32_t>(max_held_, 3);
}

void StreamQueue::Abandon(std::vector<StreamSlot*>* released) {
  if (abandoned_) return;
  abandoned_ = true;
  for (StreamSlot* s : waiting_) released->push_back(s);
  held_ -= static_cast<std::uint32_t>(waiting_.size());
  waiting_.clear();
  for (StreamSlot* s : reorder_) {
    if (s == nullptr) continue;  // in work: comes back through Processed
    released->push_back(s);
    --held_;
  }
  reorder_.clear();
  ready_ = 0;
  // A write outstanding stays counted until Written.
}

}  // namespace cloudcast::server
