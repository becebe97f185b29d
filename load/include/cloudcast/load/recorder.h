// What a load run measured, gathered from every stream's callbacks (thread-safe), and the
// per-second series the progress line and the reports show.
//
// Two latencies per answered frame:
//   latency       reply - intended send time (the schedule's): what a camera feeding the
//                 stream sees, coordinated-omission free;
//   service time  reply - actual send (when the generator handed the frame to gRPC).
// In closed loop there is no schedule, and the two are the same.
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "cloudcast/client/rate_controller.h"
#include "cloudcast/load/histogram.h"

namespace cloudcast::load {

// What the streams' rate controllers said in an interval (or the whole run).
struct RateSummary {
  std::uint64_t samples = 0;
  double target_bps = 0;  // summed over streams (the mean per stream times the streams seen)
  double rtt_ms = 0, queue_delay_ms = 0, window = 0, frame_bytes = 0;  // means
  // The downlink: the replies' bitrate (summed as target_bps; 0 while no stream limits it), the
  // cap the streams asked each reply for (mean over samples, uncapped ones counting 0), and the
  // replies' queueing delay (mean).
  double reply_target_bps = 0, reply_cap_bytes = 0, reply_queue_delay_ms = 0;
};

// One second of the run (or the last, partial one).
struct SecondStats {
  double t_end_s = 0;          // end of the interval, seconds since the run's start
  double duration_s = 0;       // the interval's length (1 but for the last)
  std::uint64_t sent = 0;      // frames handed to gRPC
  std::uint64_t answered = 0;  // clouds received
  std::uint64_t errors = 0;    // frame errors and frames lost with their call
  std::uint64_t drops = 0;     // frames the server skipped (DELIVERY_LATEST)
  std::uint64_t late = 0;      // sends that went after their intended time
  std::uint64_t resent = 0;    // frames written again on a new call
  std::uint64_t reconnects = 0;
  std::uint64_t bytes_received = 0;  // the replies of the frames answered in it
  int open_streams = 0;
  // Latency from the intended time and service time of the frames answered in it, ns.
  std::int64_t p50 = 0, p90 = 0, p99 = 0, max = 0;
  std::int64_t service_p50 = 0, service_p99 = 0;
  // The adaptive sender (--rate-control), means over the replies of the interval (0: none):
  // its target bitrate summed over the streams, round trip, queueing delay, window, and the
  // request bytes of the frames it made.
  RateSummary rate;
  double fps() const { return duration_s > 0 ? answered / duration_s : 0; }
};

struct Totals {
  std::uint64_t sent = 0;
  std::uint64_t answered = 0;
  std::uint64_t frame_errors = 0;  // FrameError replies
  std::uint64_t lost = 0;          // sent, never answered: the call ended first
  std::uint64_t unsent = 0;        // due, never sent: the call ended or the run stopped first
  std::uint64_t drops = 0;
  std::uint64_t replaced = 0;        // due, never sent: a newer frame replaced it (DELIVERY_LATEST)
  std::uint64_t server_dropped = 0;  // sum over streams of the last frames_dropped reported
  std::uint64_t late_flow_control = 0;  // the stream's previous write had not completed
  std::uint64_t late_scheduler = 0;     // the generator itself was over 1 ms behind
  std::uint64_t bytes_sent = 0, bytes_received = 0;  // resends included
  // Resilient streams.
  std::uint64_t resent = 0;              // frames written again on a new call
  std::uint64_t duplicates = 0;          // answers to a sequence already answered (ignored)
  std::uint64_t reconnects = 0;          // reconnects that worked
  std::uint64_t reconnect_attempts = 0;  // calls opened after a failure
  std::uint64_t streams_given_up = 0;    // streams that found no working call in time
  // Video streams (--encoding h264).
  std::uint64_t skipped = 0;  // due, never sent: a frame already waited for the write slot
                              // (DELIVERY_LATEST), so this one was never encoded (a replaced
                              // picture would break the bitstream)
  std::uint64_t keyframe_needed = 0;    // replies naming a bitstream that needs an IDR
  std::uint64_t keyframes_sent = 0;     // frames sent whose pictures were IDRs
  std::uint64_t keyframe_restarts = 0;  // IDRs sent because a reply asked (the sequence restarted)
  // Live video (--encoding h264 --rate-control): frames each stream encoded as it sent them, and
  // their pictures' bytes.
  std::uint64_t live_encoded = 0, live_picture_bytes = 0;
  // The downlink (contract revision 4): clouds by the Draco colour bits the server chose
  // (CloudReply.color_bits; 0 from an older server), and those over the stream's cap
  // (CloudReply.over_cap: DracoConfig.max_cloud_bytes could not be met within its bounds).
  std::map<int, std::uint64_t> color_bits;
  std::uint64_t over_cap = 0;
  std::uint64_t late() const { return late_flow_control + late_scheduler; }
  // The median colour bits of the clouds that said (0 when none did).
  int color_bits_median() const;
};

class Recorder {
 public:
  Recorder() = default;

  void Sent(std::size_t bytes);
  void Late(bool flow_control);
  void Answered(std::int64_t latency_ns, std::int64_t service_ns, const std::string& instance,
                std::size_t bytes);
  // What an answered frame's cloud says of the downlink: its colour bits and whether it was over
  // the cap.
  void Downlink(int color_bits, bool over_cap);
  // A FrameError: its code's name (e.g. "INVALID_ARGUMENT") and message.
  void FrameError(const std::string& code, const std::string& message, const std::string& instance);
  void Dropped(std::uint64_t frames);
  // A stream's last frames_dropped; summed into server_dropped when the stream ends.
  void StreamEnded(std::uint64_t server_dropped);
  // Frames sent and never answered because their call ended with `code` / `message` (also used
  // with code "OK" for frames whose call ended cleanly without answering them).
  void Lost(std::uint64_t frames, const std::string& code, const std::string& message);
  void Unsent(std::uint64_t frames);
  // A frame replaced by a newer one before it was sent (DELIVERY_LATEST, as robots send).
  void Replaced(std::uint64_t frames);
  // Video streams: a frame not encoded because one still waited (DELIVERY_LATEST); a reply
  // asking for an IDR; a frame sent with IDRs (`asked`: because a reply asked).
  void Skipped(std::uint64_t frames);
  void KeyframeNeeded();
  void KeyframeSent(bool asked);
  // Live video: a frame a stream encoded when it was due, the encoder's CPU time on the stream's
  // thread and the pictures' bytes.
  void LiveEncoded(double encode_ms, std::size_t picture_bytes);
  void CallStatus(const std::string& code);
  // Resilient streams: a frame written again on a new call; an answer to a sequence already
  // answered; a call opened after a failure; a reconnect that worked (its time is in the
  // stream's StreamStats); a stream that gave up.
  void Resent(std::size_t bytes);
  void Duplicate();
  void ReconnectAttempt();
  void Reconnected();
  void GaveUp();
  // An adaptive stream's controller after a reply (its target, round trip and queueing delay,
  // window, and the downlink's: the replies' bitrate, cap and queueing delay), and the request
  // bytes of the frame answered.
  void RateSample(int stream, const client::RateEstimate& rate, std::size_t frame_bytes);

  // Closes the interval ending at `t_end_s` (seconds since the start) and starts the next.
  SecondStats CloseInterval(double t_end_s, int open_streams);

  // Snapshots (copies) of the totals, under the lock.
  Totals totals() const;
  Histogram latency() const;
  Histogram service() const;
  Histogram live_encode() const;  // live video: the encoder's CPU time a frame, in µs
  std::map<std::string, std::uint64_t> per_instance() const;
  std::map<std::string, std::uint64_t> status_codes() const;  // per frame: OK, error codes
  std::map<std::string, std::uint64_t> errors() const;        // "CODE: message" -> frames
  std::map<std::string, std::uint64_t> call_status() const;   // per Stream call
  std::vector<SecondStats> series() const;
  RateSummary rate() const;  // over the whole run

 private:
  mutable std::mutex mu_;
  Totals totals_;
  Histogram latency_, service_;
  Histogram live_encode_us_;
  Histogram interval_latency_, interval_service_;
  SecondStats interval_;
  double interval_start_s_ = 0;
  std::map<std::string, std::uint64_t> per_instance_, status_codes_, errors_, call_status_;
  std::vector<SecondStats> series_;
  // Rate samples: sums over the interval and the run, and each stream's last target.
  struct RateSums {
    std::uint64_t n = 0;
    double rtt = 0, queue = 0, window = 0, bytes = 0, reply_cap = 0, reply_queue = 0;
    std::map<int, double> target_sum;  // per stream
    std::map<int, double> reply_target_sum;  // per stream
    std::map<int, std::uint64_t> target_n;
    RateSummary Summary() const;
  };
  RateSums interval_rate_, run_rate_;
};

}  // namespace cloudcast::load
