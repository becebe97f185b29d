// The one client stream implementation: a grpc::ClientBidiReactor per call, driving the gRPC-free
// StreamMachine (stream_machine.h: queue, replacement, resends, reconnect, give-up). The
// library's Stream (blocking Read and the on_result callback), the viewer, the ROS bridge and
// cloudcast-load all send through it, so the load tests measure what robots run.
//
// Frames come in as the bytes of a StreamRequest (the library's RequestWriter, the load
// generator's FrameStore): the core never looks inside them, so frame content stays out of it.
// Replies come out parsed (v1::StreamReply), each with the record of the frame it answers.
//
// Threads: no thread of its own. Submit / Reconfigure / CloseSend / Cancel run on the caller's
// thread and never wait (Submit answers kFull instead; the caller decides whether to wait). They
// may start gRPC operations, but never run the sink: the sink runs on gRPC's callback threads
// (a reply, a completed write, the call's end, a timer), one event at a time, in order. One lock.
//
// Rate control plugs in at the sink: OnWrite tells when and how many bytes went out, OnReply
// when the answer came back and for which frame (its write time); the bitrate it decides is
// applied where frames are made (the library's Stream::Send, the load generator's FrameStore),
// before Submit. The replies' bitrate it decides the core applies itself: it writes the
// owner's config again with a new cap on each reply's cloud (reply_cap.h). Frames that must not be
// replaced once made (video pictures) are made at dispatch: the owner asks WantRoom, keeps the raw
// frame while there is none, and makes and submits it on OnRoom (the core still never looks
// inside).
#pragma once

#include <grpcpp/alarm.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "cloudcast/client/rate_controller.h"
#include "cloudcast/client/reply_cap.h"
#include "cloudcast/client/stream_machine.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace cloudcast::client {

// What the core keeps of a frame beside its bytes, handed back with the frame's fate.
struct FrameRecord {
  std::string frame_id;
  std::int64_t capture_time_unix_ns = 0;
  std::int64_t intended_ns = 0;  // steady-clock ns the frame was due (load schedules); 0: none
  std::uint64_t image_bytes = 0;
  int resolution_divisor = 1;  // FrameCoder::Resolution (Result::resolution_divisor)
};

using CoreMachine = StreamMachine<grpc::ByteBuffer, FrameRecord>;
using SettledFrame = CoreMachine::Settled;

// A write the core started: for byte counts, send times and (later) rate control.
struct WriteEvent {
  bool is_frame = false;
  bool resend = false;
  std::uint64_t sequence = 0;
  std::size_t bytes = 0;
  std::chrono::steady_clock::time_point at;
};

// The core's events, on gRPC's threads, one at a time, in order. OnEnded comes last, once.
class StreamSink {
 public:
  virtual ~StreamSink() = default;
  // A reply. `frame`: the frame it answers (fate kAnswered), or nullptr for a reply that answers
  // no frame (a rejected config) or a sequence the stream never sent. `reply` may be moved from.
  virtual void OnReply(v1::StreamReply& reply, std::size_t reply_bytes, const SettledFrame* frame,
                       std::chrono::steady_clock::time_point received) = 0;
  // A frame replaced, dropped, lost or unsent.
  virtual void OnSettled(SettledFrame& frame) = 0;
  // The stream's end: `gave_up` when the machine stopped reconnecting (status is then the last
  // call's). It may come before Start has returned (a call refused at once), so a sink learns
  // everything here and never asks the core.
  virtual void OnEnded(const absl::Status& status, bool gave_up) = 0;
  virtual void OnWrite(const WriteEvent& /*write*/) {}
  virtual void OnCallOpened(bool /*after_failure*/) {}
  virtual void OnCallEnded(const absl::Status& /*status*/) {}
  virtual void OnReconnected(const Reconnected& /*event*/) {}
  virtual void OnDuplicate() {}  // a second answer to a resent frame (ignored)
  // With rate control: the controller's estimate after a reply, just before that OnReply.
  virtual void OnRate(const RateEstimate& /*estimate*/) {}
  // StreamCore::WantRoom answered false, and now there is room for a frame: the owner makes the
  // frame it kept (video: encodes it now) and submits it. May call Submit from here.
  virtual void OnRoom() {}
};

struct StreamCoreOptions {
  StreamMachineOptions machine;
  bool wait_for_ready = false;  // of the first call; later calls always wait (for a replica)
  std::optional<grpc::ByteBuffer> config;  // written first on every call (none: nothing)
  // A sender that follows the link (rate_controller.h): frames past its window wait in the
  // queue, and rate() gives the bitrate to make frames at. None: every frame is written as soon
  // as the write slot is free (TCP's buffers then hold what the link cannot carry).
  std::optional<RateControlOptions> rate_control;
};

class StreamCore : public std::enable_shared_from_this<StreamCore> {
 public:
  using Clock = std::chrono::steady_clock;

  // Starts the first call at once. `sink` must outlive the core's last event (OnEnded), and the
  // caller keeps `channel` alive until then too: the core holds no reference of its own,
  // because it may go last on one of gRPC's callback threads, and a channel destroyed there
  // (the last user of gRPC's callback queue) would shut that queue down from its own thread.
  static std::shared_ptr<StreamCore> Start(grpc::Channel* channel, StreamCoreOptions options,
                                           StreamSink* sink);
  ~StreamCore();
  StreamCore(const StreamCore&) = delete;
  StreamCore& operator=(const StreamCore&) = delete;

  CoreMachine::Submitted Submit(std::uint64_t sequence, grpc::ByteBuffer bytes,
                                FrameRecord record);
  // Waits while Submit says kFull (DELIVERY_ALL back-pressure); `give_up` (checked on every
  // wake) ends the wait with kFull.
  CoreMachine::Submitted SubmitWaiting(std::uint64_t sequence, grpc::ByteBuffer bytes,
                                       FrameRecord record,
                                       const std::function<bool()>& give_up = {});
  // Frames made at dispatch (StreamMachineOptions::replace_queued off: video, whose encoded
  // pictures must all be sent): true when a frame submitted now is written at once or after the
  // write in progress (StreamMachine::HasRoom); false arms one OnRoom for when there is.
  bool WantRoom();
  // A frame the owner never submitted (replaced while it waited for room, could not be made, or
  // the stream ended first): settled and reported like the core's own (StreamMachine::Unmade).
  void Unmade(FrameFate fate, std::uint64_t sequence, FrameRecord record, absl::Status why = {});
  absl::Status Reconfigure(grpc::ByteBuffer config);
  void CloseSend(bool discard_queued = false);
  void Cancel();
  // Reading: paused, no more replies are read (gRPC flow control then holds the server back)
  // until resumed. For consumers that buffer replies.
  void PauseReads(bool paused);

  // Waits until OnEnded has been delivered and every call's reactor is done, releases the calls
  // on this thread, and returns the final status. The owner calls it before letting the core
  // (and the channel) go; never from the sink.
  absl::Status AwaitEnd();
  bool ended() const;

  // Counters (StreamMachine's).
  std::uint64_t submitted() const;
  std::uint64_t written() const;
  std::uint64_t resent() const;
  std::uint64_t replaced() const;
  int reconnects() const;
  int calls() const;
  bool gave_up() const;
  std::uint64_t frames_dropped_reported() const;
  // The rate controller's estimate (StreamCoreOptions::rate_control; none without it).
  std::optional<RateEstimate> rate() const;

  class Call;  // stream_core.cc

 private:
  StreamCore(grpc::Channel* channel, StreamCoreOptions options, StreamSink* sink);

  // One operation on a call, carried out in order outside the lock.
  struct Op {
    enum Kind { kOpen, kWrite, kWritesDone, kReleaseWrites, kCancel, kResumeRead };
    explicit Op(Kind k) : kind(k) {}
    Kind kind;
    bool after_failure = false;
    grpc::ByteBuffer bytes;
    Call* call = nullptr;  // kResumeRead
  };
  // One event for the sink.
  struct Event {
    enum Kind {
      kReply,
      kSettled,
      kWrite,
      kCallOpened,
      kCallEnded,
      kReconnected,
      kDuplicate,
      kRoom,
      kEnded
    };
    explicit Event(Kind k) : kind(k) {}
    Kind kind;
    v1::StreamReply reply;
    std::size_t bytes = 0;
    std::optional<SettledFrame> frame;
    absl::Status status;
    Reconnected reconnected;
    WriteEvent write;
    bool after_failure = false;
    bool gave_up = false;  // kEnded
    std::optional<RateEstimate> rate;  // kReply, with rate control
    Clock::time_point at;
  };

  // Turns the machine's effects into ops and events (under mu_).
  // Under mu_: every call whose reads were paused reads again (queued as kResumeRead ops).
  void ResumePausedReadsLocked();
  void CollectLocked(Clock::time_point now);
  // Carries out the queued ops (any thread) and, `deliver`, the events (gRPC threads only; other
  // threads ask a timer to deliver them).
  void Run(bool deliver);
  void RunOps();
  void DeliverEvents();
  void KickLocked(Clock::time_point at);
  // The owner's config with the replies' cap in force, as bytes to write.
  grpc::ByteBuffer ConfigWithReplyCapLocked() const;
  // Under mu_, with reply_cap_: the cap the controller's estimate asks for, written in order with
  // the frames when it changed enough (ReplyCapFollower).
  void FollowReplyCapLocked(Clock::time_point now);
  // Under mu_: the camera made a frame (sent or not). The cap follows from the stream's second
  // frame on, before any reply: the replies start at the controller's starting bitrate.
  void CameraFrameLocked(Clock::time_point now);

  // Reactor callbacks (stream_core.cc's Call forwards them).
  void OnWriteDone(Call* call, bool ok);
  void OnReadDone(Call* call, bool ok);
  void OnDone(Call* call, const grpc::Status& status);
  void OnTimer();

  grpc::TemplatedGenericStub<grpc::ByteBuffer, grpc::ByteBuffer> stub_;
  const StreamCoreOptions options_;
  StreamSink* const sink_;

  mutable std::mutex mu_;
  std::condition_variable changed_;  // queue space, the end
  CoreMachine machine_;
  std::optional<RateController> rate_;
  // The replies' cap (RateControlOptions::cap_replies): the owner's config, parsed, which every
  // cap change is written into.
  std::optional<ReplyCapFollower> reply_cap_;
  v1::StreamRequest stream_config_;
  std::deque<std::pair<std::uint64_t, std::size_t>> written_bytes_;  // sequence, bytes (rate_)
  std::deque<Op> ops_;
  bool running_ops_ = false;
  std::deque<Event> events_;
  bool delivering_ = false;
  bool end_delivered_ = false;
  bool pause_reads_ = false;
  std::vector<std::unique_ptr<Call>> calls_;  // every call made; a few per stream
  int live_calls_ = 0;                        // started, OnDone not returned yet
  Call* current_ = nullptr;                   // ops' call (touched by the op runner only)
  // Timers (backoff, give-up, event delivery), one grpc::Alarm each.
  struct Timer {
    std::unique_ptr<grpc::Alarm> alarm;
    std::shared_ptr<std::atomic<bool>> fired;  // set by its callback
  };
  std::vector<Timer> alarms_;
  std::optional<Clock::time_point> next_wake_;
};

}  // namespace cloudcast::client
