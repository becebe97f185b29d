// Where one Stream call is in its life, as one state, and the status it ends with. gRPC-free:
// the reactor (stream_reactor.h) asks it whether to read and when to Finish; tests drive it
// directly.
//
//   kReading     messages are read
//   kHalfClosed  the client closed its side (or the read side failed): the frames held are
//                answered, then the call ends OK
//   kClosing     reading stopped for good (the server drains, or bytes did not parse): the frames
//                held are answered, then the call ends with the closing status. A drain (Drain)
//                also answers the message of a read already started, which its client sent
//                before it could know, and waits for that read until StopAwaitingRead
//   kEnding      the server ends the call now (idle, or shed for a new client) with its status,
//                without waiting for the frames held
//   kBroken      the client cancelled, or a write failed: nothing more is written; ends CANCELLED
//   kFinished    Finish has been decided
//
// A state only moves down the list, and each step keeps the first status given for it (a
// half-closed stream the server drains is closing; a closing stream the client cancels is
// broken; a drain after bytes that did not parse keeps their status).
#pragma once

#include <grpcpp/support/status.h>

#include <optional>
#include <utility>

namespace cloudcast::server {

class StreamLifecycle {
 public:
  enum class State { kReading, kHalfClosed, kClosing, kEnding, kBroken, kFinished };

  State state() const { return state_; }
  // Whether the next message may be read (room for it aside).
  bool reading() const { return state_ == State::kReading; }
  // Whether a message that arrives on a read already started is answered: while reading, and
  // while closing for a drain (the client sent it before it could know of the drain; it is in the
  // server's transport already). Dropped otherwise: past bytes that did not parse, or once the
  // call is ending, broken or finished.
  bool answers_read() const {
    return state_ == State::kReading || (state_ == State::kClosing && drained_from_reading_);
  }
  // Whether the server may still end the call (idle timeout, shedding).
  bool may_end() const { return state_ < State::kEnding; }
  // Whether the call may be shed to make room: it is neither ending nor closing.
  bool sheddable() const { return state_ <= State::kHalfClosed; }
  bool finished() const { return state_ == State::kFinished; }

  void HalfClose() { MoveTo(State::kHalfClosed, grpc::Status::OK); }
  void Close(grpc::Status status) { MoveTo(State::kClosing, std::move(status)); }
  // Closing because the server drains: as Close, and a read already started is answered
  // (answers_read) and waited for (Finish's `read_started`) until StopAwaitingRead.
  void Drain(grpc::Status status) {
    const bool was_reading = state_ == State::kReading;
    Close(std::move(status));
    if (was_reading) drained_from_reading_ = awaiting_read_ = true;
  }
  // The drain waits no longer for a read already started (it may never complete: a client that
  // sends nothing more). Its message is still answered if it arrives before the call finishes.
  void StopAwaitingRead() { awaiting_read_ = false; }
  // False (nothing changes) when the call is ending, broken or finished already.
  bool End(grpc::Status status) {
    if (!may_end()) return false;
    MoveTo(State::kEnding, std::move(status));
    return true;
  }
  // False when the call was broken already or is finished.
  bool Break() {
    if (state_ >= State::kBroken) return false;
    MoveTo(State::kBroken, grpc::Status(grpc::StatusCode::CANCELLED, "stream cancelled"));
    return true;
  }

  // The status to Finish with now, if it is time (then the state is kFinished): at once when
  // broken or ending, once `nothing_held` when closing or half-closed (a drained call also once
  // no `read_started` is awaited). Only when no write is outstanding (a Finish must wait for it).
  // `cancelled` gets whether the call was broken.
  std::optional<grpc::Status> Finish(bool nothing_held, bool* cancelled,
                                     bool read_started = false) {
    *cancelled = state_ == State::kBroken;
    const bool settled = nothing_held && !(read_started && awaiting_read_);
    const bool now = state_ == State::kBroken || state_ == State::kEnding ||
                     (settled && (state_ == State::kClosing || state_ == State::kHalfClosed));
    if (!now) return std::nullopt;
    state_ = State::kFinished;
    return std::move(status_);
  }

 private:
  void MoveTo(State next, grpc::Status status) {
    if (next <= state_) return;
    state_ = next;
    status_ = std::move(status);
  }

  State state_ = State::kReading;
  bool drained_from_reading_ = false;  // closing for a drain that stopped reading (Drain)
  bool awaiting_read_ = false;         // the drain waits for a read already started
  grpc::Status status_;                // the status of the current state
};

}  // namespace cloudcast::server
