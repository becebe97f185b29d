// The frames of one stream between its reader and its writer, without gRPC: the delivery policy,
// the order replies are written in, drop accounting and the bounds. The stream's reactor calls it
// under its own mutex; tests drive it directly.
//
// A slot is one request: a frame to process, or a reply that needs no work (the error for a bad
// StreamConfig), which keeps its place among the frame replies. Slots are owned by the caller;
// the queue only orders them. Every slot pushed comes back exactly once: from NextToProcess (then
// Processed), from NextToWrite (then Written), or in a `released` list.
//
//   DELIVERY_LATEST  one frame in work at a time, and none started while a finished reply waits
//                    for the writer; a newer frame replaces the ones still waiting (dropped).
//                    While a reply is being written, at most kMaxDropsPerWrite frames are read
//                    and dropped; then the stream is not read until the client takes the reply,
//                    so a client that never reads costs nothing.
//   DELIVERY_ALL     every frame is processed, several at once; replies are written in order
//                    (a reorder buffer); at most `max_held` slots are held, after which the
//                    stream should not be read (gRPC flow control then slows the client).
#pragma once

#include <cstdint>
#include <deque>
#include <vector>

#include "cloudcast/proto/convert.h"

namespace cloudcast::server {

struct StreamSlot {
  enum class Kind : std::uint8_t { kFrame, kReply };
  Kind kind = Kind::kFrame;
  // The stream's delivery mode when the frame arrived (a new StreamConfig may change it).
  convert::Delivery delivery = convert::Delivery::kLatest;
  // Set by the queue: the slot's place among the stream's replies.
  std::uint64_t order = 0;
};

class StreamQueue {
 public:
  static constexpr std::uint32_t kMaxDropsPerWrite = 8;

  // `max_held`: slots held at once in DELIVERY_ALL (waiting + in work + replies not yet written).
  explicit StreamQueue(std::uint32_t max_held);
  StreamQueue(const StreamQueue&) = delete;
  StreamQueue& operator=(const StreamQueue&) = delete;

  // A frame was read. In DELIVERY_LATEST it replaces the DELIVERY_LATEST frames still waiting:
  // they are appended to `dropped` (counted in dropped()) for the caller to release.
  void PushFrame(StreamSlot* slot, std::vector<StreamSlot*>* dropped);
  // A reply that needs no work; it is written after the replies of everything pushed before it.
  void PushReply(StreamSlot* slot);

  // The next frame a worker may start now, in arrival order, or nullptr. The caller must hand it
  // back with Processed.
  StreamSlot* NextToProcess();
  // A worker is done with `slot`: its reply takes its place in the write order. False when the
  // stream was abandoned meanwhile: the caller releases the slot.
  bool Processed(StreamSlot* slot);

  // The next reply in order if it is ready, or nullptr. One at a time: call Written before the
  // next NextToWrite.
  StreamSlot* NextToWrite();
  // The write of the slot NextToWrite gave has completed; the slot is the caller's again.
  void Written();

  // Whether the stream may be read now, given its current delivery mode.
  bool CanRead(convert::Delivery current) const;
  // Nothing is waiting, in work, or unwritten (including a write outstanding).
  bool Empty() const { return held_ == 0; }

  // The call can no longer be written to. Every slot waiting or done goes to `released`; slots
  // in work come back through Processed (false). Afterwards nothing is processed or written.
  void Abandon(std::vector<StreamSlot*>* released);
  bool abandoned() const { return abandoned_; }

  int in_work() const { return in_work_; }
  std::uint32_t held() const { return held_; }
  std::uint64_t dropped() const { return dropped_; }
  std::uint64_t written() const { return next_write_order_; }

 private:
  const std::uint32_t max_held_;
  std::deque<StreamSlot*> waiting_;  // pushed, not started: frames, and replies to keep in order
  // [i] is the reply with order next_write_order_ + i; nullptr while its frame is in work.
  std::deque<StreamSlot*> reorder_;
  std::uint64_t next_order_ = 0;
  std::uint64_t next_write_order_ = 0;
  int in_work_ = 0;
  int ready_ = 0;           // done, in reorder_, not yet handed to the writer
  bool writing_ = false;    // a slot from NextToWrite is being written
  std::uint32_t held_ = 0;  // waiting + in work + ready + writing
  std::uint64_t dropped_ = 0;
  std::uint32_t dropped_during_write_ = 0;  // since the write outstanding began
  bool abandoned_ = false;
};

}  // namespace cloudcast::server
