// The book of a resilient stream (StreamOptions::resilient): which frames were sent and not
// answered yet, what to send again after a lost call, and which replies answer nothing new.
// gRPC-free, so that the client's Stream and the load generator's stream driver keep one book,
// and so that it is tested on its own (resend_ledger_test).
//
// Rules, for a stream whose replies come in the order its frames were sent:
// - A reply answers the earliest unanswered frame of its sequence. Frames sent before that one
//   and still unanswered got no reply: the server skipped them (DELIVERY_LATEST), so they leave
//   the book and are counted as skipped.
// - When a call is lost, its unanswered frames that may be sent again (DELIVERY_ALL) wait to be
//   resent, in send order, before any new frame; the others are dropped (the server would have
//   skipped them for newer ones anyway).
// - A reply to a sequence already answered is a duplicate (exactly once per frame), as long as
//   the stream sent its sequences in increasing order (the client's default numbering and the
//   load generator's); with sequences of the caller's own, in any order, unmatched replies are
//   only "unknown".
//
// Not thread-safe: the owner holds its lock around every call. `Record` is what the owner keeps
// per frame (send times, the request's bytes to resend, ...).
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <iterator>
#include <optional>
#include <utility>
#include <vector>

namespace cloudcast::client {

template <typename Record>
class ResendLedger {
 public:
  struct Entry {
    std::uint64_t sequence = 0;
    Record record{};
    bool resendable = false;  // sent again after a lost call; dropped then otherwise
    int sends = 1;            // writes so far: the first, plus one per resend
  };

  enum class Match {
    kAnswered,   // `entry` is the frame answered; `skipped` frames before it got no reply
    kDuplicate,  // a frame answered (or skipped) before: the reply is to be ignored
    kUnknown,    // a sequence not in the book and not known to be answered
  };
  struct Reply {
    Match match = Match::kUnknown;
    std::optional<Entry> entry;  // kAnswered: the frame, out of the book
    std::uint64_t skipped = 0;   // kAnswered: unanswered frames sent before it, out of the book
    std::vector<Entry> skipped_entries;  // those frames, in send order (reported one by one)
  };

  // A new frame written on the current call.
  void Sent(std::uint64_t sequence, Record record, bool resendable) {
    increasing_ = increasing_ && (!last_sent_ || sequence > *last_sent_);
    last_sent_ = sequence;
    in_flight_.push_back(Entry{sequence, std::move(record), resendable, 1});
  }

  // Books the reply to `sequence`.
  Reply Answer(std::uint64_t sequence) {
    Reply reply;
    for (auto it = in_flight_.begin(); it != in_flight_.end(); ++it) {
      if (it->sequence != sequence) continue;
      reply.match = Match::kAnswered;
      reply.skipped = static_cast<std::uint64_t>(std::distance(in_flight_.begin(), it));
      for (auto skipped = in_flight_.begin(); skipped != it; ++skipped) {
        reply.skipped_entries.push_back(std::move(*skipped));
      }
      reply.entry = std::move(*it);
      in_flight_.erase(in_flight_.begin(), it + 1);
      last_answered_ = sequence;
      return reply;
    }
    if (increasing_ && last_answered_ && sequence <= *last_answered_) {
      reply.match = Match::kDuplicate;
    }
    return reply;
  }

  // The current call has ended. Its unanswered resendable frames wait to be sent again, ahead of
  // those still waiting from an earlier loss (they were sent before them); the others leave the
  // book (into `dropped`, in send order, when given). Returns how many left.
  std::uint64_t CallLost(std::vector<Entry>* dropped = nullptr) {
    std::uint64_t count = 0;
    std::deque<Entry> gone;
    for (auto it = in_flight_.rbegin(); it != in_flight_.rend(); ++it) {
      if (it->resendable) {
        resend_.push_front(std::move(*it));
      } else {
        ++count;
        if (dropped != nullptr) gone.push_front(std::move(*it));
      }
    }
    in_flight_.clear();
    if (dropped != nullptr) {
      for (Entry& e : gone) dropped->push_back(std::move(e));
    }
    return count;
  }

  // The next frame to send again, now counted in flight on the current call (its `sends` one
  // higher); nullptr when none waits. The pointer stays valid until the next call that changes
  // the book.
  Entry* NextResend() {
    if (resend_.empty()) return nullptr;
    in_flight_.push_back(std::move(resend_.front()));
    resend_.pop_front();
    Entry& e = in_flight_.back();
    ++e.sends;
    return &e;
  }

  // Every frame sent and not answered (in flight, then waiting for a resend), in send order; the
  // book is empty afterwards (a stream that ends reports them).
  std::vector<Entry> TakeUnanswered() {
    std::vector<Entry> out;
    out.reserve(in_flight_.size() + resend_.size());
    for (Entry& e : in_flight_) out.push_back(std::move(e));
    for (Entry& e : resend_) out.push_back(std::move(e));
    in_flight_.clear();
    resend_.clear();
    return out;
  }

  std::size_t in_flight() const { return in_flight_.size(); }     // on the current call
  std::size_t awaiting_resend() const { return resend_.size(); }  // for the next call
  std::size_t unanswered() const { return in_flight() + awaiting_resend(); }
  bool empty() const { return unanswered() == 0; }

 private:
  std::deque<Entry> in_flight_;  // sent on the current call, in send order
  std::deque<Entry> resend_;     // sent on a lost call, to be sent again, in send order
  std::optional<std::uint64_t> last_sent_, last_answered_;
  bool increasing_ = true;  // every sequence sent was above the one before
};

}  // namespace cloudcast::client
