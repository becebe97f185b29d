// The state of one client stream, without gRPC: what to write next on the current call, which
// frames wait, which were replaced, answered, dropped or lost, when to open a new call after a
// lost one (resilient streams), and when to give up. The gRPC side (stream_core.h) feeds it the
// call's events and carries out what it asks for; the library's Stream, the ROS bridge and
// cloudcast-load all run on that one pair. Tested on its own (stream_machine_test), like the
// server's StreamQueue.
//
// Rules:
// - One write at a time on a call (gRPC's rule). A new call writes the stream's config first,
//   then (DELIVERY_ALL, resilient) every frame the lost call left unanswered, in send order, then
//   the queue: frames and Reconfigure's configs in the order they were given.
// - DELIVERY_LATEST (`Options::latest`): Submit never waits. A frame that is still queued when a
//   newer one arrives is replaced (settled kReplaced): only the newest unsent frame waits for the
//   write slot. With `replace_queued` off (frames made only when the machine has room: video,
//   whose encoded pictures must all be sent), nothing queued is replaced: the owner asks
//   WantRoom before it makes a frame, replaces what it has not made yet itself, and reports
//   those frames with Unmade (counted and settled kReplaced like the machine's own); Submit
//   answers kFull past `max_queued` as with DELIVERY_ALL.
// - DELIVERY_ALL: nothing is replaced; Submit answers kFull while `max_queued` frames wait, and
//   the caller waits (lossless back-pressure) or, with max_queued 0, never.
// - Every frame submitted is settled exactly once: answered (a reply, cloud or error), replaced
//   (never sent), dropped (sent, skipped by the server or lost with its call under
//   DELIVERY_LATEST), lost (sent, never answered when the stream ended) or unsent (queued when
//   the stream ended).
// - Resilient streams: a call that ends UNAVAILABLE, or CANCELLED that the stream did not ask
//   for, is replaced by a new one (the first at once, later ones after a doubling backoff) until
//   `reconnect_timeout` has passed since the calls started failing; then the stream gives up.
//
// Not thread-safe: the owner holds its lock around every call, then carries out TakeEffects()
// outside it. Times come in as arguments, so tests drive the clock.
#pragma once

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "cloudcast/client/resend_ledger.h"

namespace cloudcast::client {

// How a frame given to a stream ended. Every frame ends in exactly one.
enum class FrameFate {
  kAnswered,  // the server replied: a cloud, or a FrameError naming what was wrong
  kReplaced,  // DELIVERY_LATEST: a newer frame took its place before it was sent
  kDropped,   // DELIVERY_LATEST: sent, then skipped by the server or lost with its call
  kLost,      // sent and never answered: the stream ended (or gave up) first
  kUnsent,    // still waiting to be sent when the stream ended
};

inline const char* FateName(FrameFate fate) {
  switch (fate) {
    case FrameFate::kAnswered:
      return "answered";
    case FrameFate::kReplaced:
      return "replaced";
    case FrameFate::kDropped:
      return "dropped";
    case FrameFate::kLost:
      return "lost";
    case FrameFate::kUnsent:
      return "unsent";
  }
  return "unknown";
}

struct StreamMachineOptions {
  std::string name = "stream";  // in messages: "stream to host:port"
  bool latest = false;          // DELIVERY_LATEST: a newer frame replaces a queued one
  // DELIVERY_LATEST: false: a queued frame is never replaced (its owner makes frames only when
  // WantRoom says there is room, and replaces unmade frames itself).
  bool replace_queued = true;
  std::size_t max_queued = 1;   // DELIVERY_ALL: frames that may wait for the write slot; 0: any
  bool resilient = false;
  std::chrono::nanoseconds reconnect_timeout = std::chrono::seconds(30);
  // How the give-up message names the setting (the library's option, a program's flag).
  std::string reconnect_timeout_name = "StreamOptions::reconnect_timeout";
  std::chrono::nanoseconds first_backoff = std::chrono::milliseconds(20);
  std::chrono::nanoseconds max_backoff = std::chrono::seconds(1);
};

// What a reply tells the machine (the owner reads it out of the protocol message).
struct ReplyInfo {
  bool answers_frame = true;  // false: a config error, or a reply with neither cloud nor error
  std::uint64_t sequence = 0;
  std::uint64_t server_dropped = 0;  // the call's frames_dropped so far (server's count)
  std::string instance;              // the replica that answered
};

// A lost call was replaced.
struct Reconnected {
  int attempt = 0;  // 1 for the stream's first reconnect, then 2, ...
  absl::Status cause;
  std::string old_instance;  // the replica that answered last before
  std::chrono::nanoseconds took{0};
  std::uint64_t frames_resent = 0;
  std::uint64_t frames_dropped = 0;
};

template <typename Payload, typename Record>
class StreamMachine {
 public:
  using Clock = std::chrono::steady_clock;

  // A frame as the machine keeps it.
  struct Frame {
    Payload payload{};  // kept after the write only where it may be sent again
    Record record{};
    Clock::time_point submitted{};
    Clock::time_point written{};  // the start of its latest write
  };
  using Ledger = ResendLedger<Frame>;

  // A frame whose fate is known.
  struct Settled {
    FrameFate fate = FrameFate::kAnswered;
    std::uint64_t sequence = 0;
    Frame frame;
    int sends = 0;        // writes of it (0: never sent)
    absl::Status why;     // kLost / kUnsent: how the stream ended (its final status)
  };

  // The write to start on the current call.
  struct Write {
    Payload payload{};
    bool is_frame = false;
    bool resend = false;
    std::uint64_t sequence = 0;  // frames only
  };

  // What the owner is to do, in this order: open a call, start a write (or half-close), release
  // the call's write hold, cancel the call; then report the rest.
  struct Effects {
    bool open_call = false;
    bool after_failure = false;  // the new call replaces a lost one (it waits for a replica)
    std::optional<Write> write;
    bool writes_done = false;
    bool release_writes = false;  // no more writes will start on the current call
    bool cancel_call = false;
    std::vector<Settled> settled;  // in the order their fates became known
    std::optional<Reconnected> reconnected;
    std::optional<Clock::time_point> wake_at;  // call Timer then (backoff, give-up deadline)
    bool queue_freed = false;  // a waiting frame left the queue: a blocked Submit may retry
    bool room = false;         // WantRoom was false, and now there is room for a frame
    bool ended = false;        // the stream is over: status() says how
  };

  enum class Submitted {
    kWriting,  // its write started at once
    kQueued,   // it waits for the write slot (with DELIVERY_LATEST it may still be replaced)
    kFull,     // DELIVERY_ALL: max_queued frames wait; nothing changed, try again later
    kClosed,   // after CloseSend
    kEnded,    // the stream is over
  };

  // The result of a reply.
  struct Answer {
    enum Kind { kFrame, kNotAFrame, kDuplicate, kUnknown } kind = kUnknown;
    std::optional<Settled> frame;  // kFrame: the frame it answers (fate kAnswered)
  };

  StreamMachine(StreamMachineOptions options, std::optional<Payload> config)
      : options_(std::move(options)), config_(std::move(config)) {}

  // Opens the first call.
  void Start(Clock::time_point now) { OpenCall(/*after_failure=*/false, now); }

  // A new frame from the application.
  Submitted Submit(std::uint64_t sequence, Payload payload, Record record, Clock::time_point now) {
    if (writes_closed_) return Submitted::kClosed;
    if (ended_) return Submitted::kEnded;
    if (options_.latest && options_.replace_queued) {
      for (auto it = queue_.begin(); it != queue_.end();) {
        if (!it->is_frame) {
          ++it;
          continue;
        }
        ++replaced_;
        effects_.settled.push_back(
            Settled{FrameFate::kReplaced, it->sequence, std::move(it->frame), 0, {}});
        it = queue_.erase(it);
        --queued_frames_;
      }
    } else if (options_.max_queued > 0 && queued_frames_ >= options_.max_queued) {
      return Submitted::kFull;
    }
    ++submitted_;
    queue_.push_back(Item{true, sequence, Frame{std::move(payload), std::move(record), now, {}}});
    ++queued_frames_;
    Pump(now);
    const bool writing = effects_.write && effects_.write->is_frame && !effects_.write->resend &&
                         effects_.write->sequence == sequence && queued_frames_ == 0;
    return writing ? Submitted::kWriting : Submitted::kQueued;
  }

  // Room for a frame now: a call that takes writes, no frame waiting for the write slot, and the
  // window (SetMaxUnanswered) open. A frame submitted now is written at once or as soon as the
  // write in progress is done.
  bool HasRoom() const {
    return !ended_ && !writes_closed_ && call_open_ && !broken_ && !writes_released_ &&
           queued_frames_ == 0 && (max_unanswered_ == 0 || ledger_.unanswered() < max_unanswered_);
  }
  // HasRoom(); when false, the first TakeEffects that finds room sets Effects::room (once).
  bool WantRoom() {
    if (HasRoom()) {
      room_wanted_ = false;
      return true;
    }
    room_wanted_ = true;
    return false;
  }

  // A frame the owner never made into a payload, settled without entering the queue: kReplaced
  // (a newer frame took its place while it waited for room; counted as submitted and replaced),
  // or kUnsent (it could not be made, or the stream ended first: `why`).
  void Unmade(FrameFate fate, std::uint64_t sequence, Record record, Clock::time_point now,
              absl::Status why = {}) {
    ++submitted_;
    if (fate == FrameFate::kReplaced) ++replaced_;
    effects_.settled.push_back(
        Settled{fate, sequence, Frame{Payload{}, std::move(record), now, {}}, 0, std::move(why)});
  }

  // A new config for the frames submitted after it (sent in order with them).
  absl::Status Reconfigure(Payload config, Clock::time_point now) {
    if (ended_) return absl::UnavailableError(absl::StrCat(options_.name, " has ended"));
    if (writes_closed_) {
      return absl::FailedPreconditionError(
          absl::StrCat(options_.name, ": already closed by CloseSend"));
    }
    queue_.push_back(Item{false, 0, Frame{std::move(config), Record{}, now, {}}});
    Pump(now);
    return absl::OkStatus();
  }

  // No more frames: the queue is still sent (or, `discard_queued`, settled unsent), then the
  // call is half-closed. Idempotent.
  void CloseSend(bool discard_queued, Clock::time_point now) {
    if (discard_queued) {
      for (auto it = queue_.begin(); it != queue_.end();) {
        if (it->is_frame) {
          effects_.settled.push_back(Settled{FrameFate::kUnsent, it->sequence,
                                             std::move(it->frame), 0,
                                             absl::CancelledError("not sent: sending stopped")});
          --queued_frames_;
        }
        it = queue_.erase(it);
      }
      effects_.queue_freed = true;
    }
    writes_closed_ = true;
    Pump(now);
  }

  // The application cancels the stream: the call is cancelled (its end ends the stream), or,
  // between calls, the stream ends now.
  void Cancel() {
    if (ended_ || cancelled_) return;
    cancelled_ = true;
    if (call_open_) {
      effects_.cancel_call = true;
    } else {
      End(absl::CancelledError(absl::StrCat(options_.name, " was cancelled")));
    }
  }

  // The current call's write finished (ok: handed to the transport).
  void WriteDone(bool ok, Clock::time_point now) {
    write_in_flight_ = false;
    if (!ok) {
      Broken(now);
      return;
    }
    // A new call that has nothing to be answered for is working once it writes.
    if (failing_since_ && after_failure_ && ledger_.empty()) Recovered();
    Pump(now);
    if (pending_reconnect_ && config_written_ && ledger_.awaiting_resend() == 0 &&
        !write_in_flight_resend_) {
      Reconnected r = std::move(*pending_reconnect_);
      pending_reconnect_.reset();
      r.attempt = ++reconnects_;
      r.took = now - failing_since_.value_or(now);
      r.frames_resent = resent_this_call_;
      effects_.reconnected = std::move(r);
    }
  }

  // The current call's read failed: the call is ending (CallDone follows).
  void ReadFailed(Clock::time_point now) { Broken(now); }

  // A reply on the current call.
  Answer Reply(const ReplyInfo& reply) {
    Answer answer;
    if (!reply.instance.empty()) last_instance_ = reply.instance;
    server_dropped_this_call_ = std::max(server_dropped_this_call_, reply.server_dropped);
    if (!reply.answers_frame) {
      answer.kind = Answer::kNotAFrame;
      return answer;
    }
    typename Ledger::Reply booked = ledger_.Answer(reply.sequence);
    if (booked.match == Ledger::Match::kDuplicate) {
      ++duplicates_;
      answer.kind = Answer::kDuplicate;
      return answer;
    }
    if (failing_since_) Recovered();
    if (booked.match == Ledger::Match::kUnknown) {
      answer.kind = Answer::kUnknown;
      return answer;
    }
    for (typename Ledger::Entry& e : booked.skipped_entries) {
      ++dropped_;
      effects_.settled.push_back(
          Settled{FrameFate::kDropped, e.sequence, std::move(e.record), e.sends, {}});
    }
    answer.kind = Answer::kFrame;
    ++answered_;
    answer.frame = Settled{FrameFate::kAnswered, booked.entry->sequence,
                           std::move(booked.entry->record), booked.entry->sends, {}};
    return answer;
  }

  // The current call has ended with `status`.
  void CallDone(const absl::Status& status, Clock::time_point now) {
    call_open_ = false;
    write_in_flight_ = false;
    write_in_flight_resend_ = false;
    server_dropped_before_ += server_dropped_this_call_;
    server_dropped_this_call_ = 0;
    last_call_status_ = status;
    if (ended_) return;
    const bool has_work = !ledger_.empty() || queued_frames_ > 0 || !writes_closed_;
    const bool lost = status.code() == absl::StatusCode::kUnavailable ||
                      status.code() == absl::StatusCode::kCancelled;
    if (giving_up_) {
      GiveUp();
    } else if (options_.resilient && !cancelled_ && has_work && lost) {
      if (!failing_since_) failing_since_ = broken_at_.value_or(now);
      cause_ = status;
      if (now - *failing_since_ >= options_.reconnect_timeout) {
        GiveUp();
        return;
      }
      if (!pending_reconnect_) {
        pending_reconnect_ = Reconnected{};
        pending_reconnect_->cause = status;
        pending_reconnect_->old_instance = last_instance_;
      }
      std::vector<typename Ledger::Entry> dropped;
      pending_reconnect_->frames_dropped += ledger_.CallLost(&dropped);
      for (typename Ledger::Entry& e : dropped) {
        ++dropped_;
        ++dropped_by_reconnects_;
        effects_.settled.push_back(
            Settled{FrameFate::kDropped, e.sequence, std::move(e.record), e.sends, {}});
      }
      ++attempts_;
      if (attempts_ == 1) {
        OpenCall(/*after_failure=*/true, now);
      } else {
        const int doublings = std::min(attempts_ - 2, 16);
        auto backoff = options_.first_backoff * (1LL << doublings);
        backoff = std::min<std::chrono::nanoseconds>(backoff, options_.max_backoff);
        retry_at_ = now + backoff;
        Wake(*retry_at_);
      }
      Wake(*failing_since_ + options_.reconnect_timeout);
    } else {
      End(status);
    }
  }

  // At most `frames` frames written and not yet answered on the current call (0: no limit): a
  // rate controller's window. A frame past it waits in the queue (replaced there under
  // DELIVERY_LATEST); configs and resends are not held. Writes what the new window allows.
  void SetMaxUnanswered(std::size_t frames, Clock::time_point now) {
    max_unanswered_ = frames;
    Pump(now);
  }

  // At or after a time asked for in Effects::wake_at.
  void Timer(Clock::time_point now) {
    if (ended_ || !failing_since_) return;
    if (now - *failing_since_ >= options_.reconnect_timeout) {
      if (call_open_) {
        giving_up_ = true;  // its CallDone gives up
        effects_.cancel_call = true;
      } else {
        GiveUp();
      }
    } else if (retry_at_ && now >= *retry_at_ && !call_open_) {
      retry_at_.reset();
      OpenCall(/*after_failure=*/true, now);
    } else if (retry_at_) {
      Wake(*retry_at_);
    }
    if (!ended_ && failing_since_ && !giving_up_) {
      Wake(*failing_since_ + options_.reconnect_timeout);
    }
  }

  Effects TakeEffects() {
    if (room_wanted_ && HasRoom()) {
      room_wanted_ = false;
      effects_.room = true;
    }
    Effects out = std::move(effects_);
    effects_ = Effects{};
    return out;
  }

  bool ended() const { return ended_; }
  const absl::Status& status() const { return status_; }  // once ended
  bool gave_up() const { return gave_up_; }
  bool call_open() const { return call_open_; }
  bool writes_closed() const { return writes_closed_; }
  const absl::Status& last_call_status() const { return last_call_status_; }
  std::size_t queued_frames() const { return queued_frames_; }
  std::size_t unanswered() const { return ledger_.unanswered(); }
  // Counters of the stream's life.
  std::uint64_t submitted() const { return submitted_; }  // frames accepted by Submit
  std::uint64_t written() const { return written_; }      // distinct frames written
  std::uint64_t resent() const { return resent_; }
  std::uint64_t replaced() const { return replaced_; }
  std::uint64_t dropped() const { return dropped_; }  // skipped by the server or at reconnects
  std::uint64_t answered() const { return answered_; }
  std::uint64_t duplicates() const { return duplicates_; }
  int calls() const { return calls_; }
  int reconnects() const { return reconnects_; }
  // The server's frames_dropped over the calls so far, plus frames dropped at reconnects: what
  // Result::frames_dropped reports.
  std::uint64_t frames_dropped_reported() const {
    return server_dropped_before_ + server_dropped_this_call_ + dropped_by_reconnects_;
  }

 private:
  struct Item {
    bool is_frame = false;  // else a config
    std::uint64_t sequence = 0;
    Frame frame;
  };

  void Wake(Clock::time_point at) {
    if (!effects_.wake_at || at < *effects_.wake_at) effects_.wake_at = at;
  }

  void OpenCall(bool after_failure, Clock::time_point now) {
    call_open_ = true;
    broken_ = false;
    broken_at_.reset();
    writes_released_ = false;
    write_in_flight_ = false;
    write_in_flight_resend_ = false;
    writes_done_sent_ = false;
    config_written_ = !config_.has_value();
    resent_this_call_ = 0;
    after_failure_ = after_failure;
    ++calls_;
    effects_.open_call = true;
    effects_.after_failure = after_failure;
    if (cancelled_ || giving_up_) effects_.cancel_call = true;
    Pump(now);
  }

  void Broken(Clock::time_point now) {
    if (broken_) return;
    broken_ = true;
    broken_at_ = now;
    ReleaseWrites();
  }

  void ReleaseWrites() {
    if (writes_released_ || !call_open_) return;
    writes_released_ = true;
    effects_.release_writes = true;
  }

  void Recovered() {
    failing_since_.reset();
    attempts_ = 0;
    retry_at_.reset();
  }

  void StartWrite(Write w) {
    write_in_flight_ = true;
    write_in_flight_resend_ = w.resend;
    effects_.write = std::move(w);
  }

  // Starts the next write on the current call, if its slot is free.
  void Pump(Clock::time_point now) {
    if (!call_open_ || broken_ || writes_released_ || write_in_flight_) return;
    if (!config_written_) {
      config_written_ = true;
      StartWrite(Write{*config_, false, false, 0});
      return;
    }
    if (typename Ledger::Entry* again = ledger_.NextResend()) {
      again->record.written = now;
      ++resent_;
      ++resent_this_call_;
      StartWrite(Write{again->record.payload, true, true, again->sequence});
      return;
    }
    write_in_flight_resend_ = false;
    if (!queue_.empty()) {
      if (queue_.front().is_frame && max_unanswered_ > 0 &&
          ledger_.unanswered() >= max_unanswered_) {
        return;  // the window is full: a reply (SetMaxUnanswered) opens it again
      }
      Item item = std::move(queue_.front());
      queue_.pop_front();
      if (!item.is_frame) {
        config_ = item.frame.payload;
        StartWrite(Write{std::move(item.frame.payload), false, false, 0});
        return;
      }
      --queued_frames_;
      effects_.queue_freed = true;
      ++written_;
      item.frame.written = now;
      const bool resendable = options_.resilient && !options_.latest;
      Payload bytes = item.frame.payload;  // shares the bytes where Payload does (ByteBuffer)
      if (!resendable) item.frame.payload = Payload{};
      ledger_.Sent(item.sequence, std::move(item.frame), resendable);
      StartWrite(Write{std::move(bytes), true, false, item.sequence});
      return;
    }
    if (writes_closed_ && !writes_done_sent_) {
      writes_done_sent_ = true;
      effects_.writes_done = true;
      ReleaseWrites();
    }
  }

  void GiveUp() {
    gave_up_ = true;
    End(absl::UnavailableError(absl::StrCat(
        options_.name, " lost its call (", cause_.message(),
        ") and could not open a new one within ",
        std::chrono::duration_cast<std::chrono::milliseconds>(options_.reconnect_timeout).count(),
        " ms (", options_.reconnect_timeout_name, ")")));
  }

  // The stream is over: every frame it still holds is settled as `status` says.
  void End(absl::Status status) {
    ended_ = true;
    status_ = std::move(status);
    for (typename Ledger::Entry& e : ledger_.TakeUnanswered()) {
      // A clean end of a DELIVERY_LATEST stream with frames unanswered: the server skipped them.
      const bool skipped = status_.ok() && options_.latest;
      if (skipped) ++dropped_;
      effects_.settled.push_back(Settled{skipped ? FrameFate::kDropped : FrameFate::kLost,
                                         e.sequence, std::move(e.record), e.sends, status_});
    }
    for (Item& item : queue_) {
      if (!item.is_frame) continue;
      effects_.settled.push_back(
          Settled{FrameFate::kUnsent, item.sequence, std::move(item.frame), 0, status_});
    }
    queue_.clear();
    queued_frames_ = 0;
    effects_.queue_freed = true;
    effects_.ended = true;
  }

  const StreamMachineOptions options_;
  std::optional<Payload> config_;  // the config each new call writes first (none: no config)

  std::deque<Item> queue_;
  std::size_t queued_frames_ = 0;
  std::size_t max_unanswered_ = 0;  // SetMaxUnanswered
  bool room_wanted_ = false;        // WantRoom answered false
  Ledger ledger_;

  // The current call.
  bool call_open_ = false;
  bool broken_ = false;
  std::optional<Clock::time_point> broken_at_;
  bool writes_released_ = false;
  bool write_in_flight_ = false;
  bool write_in_flight_resend_ = false;
  bool writes_done_sent_ = false;
  bool config_written_ = false;
  bool after_failure_ = false;
  std::uint64_t resent_this_call_ = 0;
  std::uint64_t server_dropped_this_call_ = 0;

  // The stream.
  bool writes_closed_ = false;
  bool cancelled_ = false;
  bool giving_up_ = false;
  bool gave_up_ = false;
  bool ended_ = false;
  absl::Status status_;
  absl::Status last_call_status_;
  absl::Status cause_;
  std::string last_instance_;
  std::optional<Clock::time_point> failing_since_;
  std::optional<Clock::time_point> retry_at_;
  int attempts_ = 0;
  std::optional<Reconnected> pending_reconnect_;

  std::uint64_t submitted_ = 0, written_ = 0, resent_ = 0, replaced_ = 0, dropped_ = 0,
                answered_ = 0, duplicates_ = 0, dropped_by_reconnects_ = 0,
                server_dropped_before_ = 0;
  int calls_ = 0, reconnects_ = 0;

  Effects effects_;
};

}  // namespace cloudcast::client
