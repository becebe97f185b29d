// The cloudcast client: connect, configure a stream, send frames, receive decoded clouds.
//
//   auto client = cloudcast::client::Client::Connect("localhost:50051");
//   if (!client.ok()) return Fail(client.status());
//   auto stream = (*client)->OpenStream(config);
//   (*stream)->Send(disparity_view, colour_view, meta);  // cloudcast::DisparityView, ColorView
//   cloudcast::client::Result r;
//   while ((*stream)->Read(&r)) Use(r);                   // typically on another thread
//   absl::Status final = (*stream)->Finish();
//
// Errors are absl::Status values with gRPC's codes (the two share numbering). RPC failures keep
// the server's message (which names the offending field) behind the call and target, e.g.
// "Process on robot-pc:50051: frame.color.raw.width is ...". cv::Mat inputs: opencv.h.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/client/config.h"
#include "cloudcast/client/frame.h"
#include "cloudcast/client/options.h"
#include "cloudcast/client/result.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace cloudcast::client {

// One bidirectional Stream call. Made by Client::OpenStream.
//
// Thread safety: one thread may Send / Reconfigure / CloseSend while another Reads (gRPC allows
// one writer and one reader at a time; writers are serialized here, so several sending threads
// are safe too). Finish, Cancel and the destructor may be called from any thread.
class Stream {
 public:
  ~Stream();  // Cancels the call unless Finish has run, and waits for its end.
  Stream(const Stream&) = delete;
  Stream& operator=(const Stream&) = delete;

  // Sends one frame. Raw pixels are copied once, straight into the buffer gRPC sends from, rows
  // packed tightly whatever the input stride; encoded images are copied as they are. The inputs may
  // be reused as soon as Send returns.
  //
  // Waiting: with DELIVERY_LATEST (set in the StreamConfig given to OpenStream) Send never
  // waits for the network: the frame waits for the write slot, and a newer frame replaces it if
  // it is still waiting then (the replaced frame comes back as a Result with fate kReplaced).
  // Otherwise (DELIVERY_ALL, or delivery unset) nothing is replaced and the stream is lossless:
  // Send waits while StreamOptions::max_queued_frames frames already wait for the write slot,
  // i.e. while gRPC flow control (or a resilient stream's reconnect) holds the stream back.
  //
  // Errors: INVALID_ARGUMENT for an input that cannot be read safely (null data, a buffer
  // smaller than its rows, a stride under the row size); FAILED_PRECONDITION after CloseSend;
  // UNAVAILABLE when the call has ended (Finish says why). Everything else (sizes that differ,
  // limits, undecodable files) is judged by the server and comes back as a Result with an error.
  absl::Status Send(const FrameInput& input, const FrameMeta& meta = {});
  // A disparity map and its colour image: Send(DisparityFrame{disparity, colour}, meta).
  absl::Status Send(const DisparityInput& disparity, const ColorInput& colour,
                    const FrameMeta& meta = {});

  // Applies `config` to the frames sent after it. Unset fields take the server defaults again
  // (the server does not merge it with the previous config).
  absl::Status Reconfigure(const StreamConfig& config);

  // Blocks for the next Result: each frame accepted by Send comes back exactly once, answered
  // (a cloud or the server's error) or with its other fate (Result::fate: replaced, dropped,
  // lost, unsent), in the order their fates became known (replies in the order the frames were
  // sent). Returns false once the stream
  // has ended (after CloseSend and the last reply, or on any failure); Finish then gives the
  // status. Not available with StreamOptions::on_result (returns false at once). Replies not
  // read yet are buffered up to a small bound; beyond it the stream stops reading, and gRPC flow
  // control holds the server back.
  bool Read(Result* result);

  // Tells the server no more frames follow (gRPC WritesDone). Replies keep coming until every
  // frame is answered. Idempotent.
  absl::Status CloseSend();

  // Ends the call and returns its final status: CloseSend, then wait for the replies still due
  // (discarding any that Read has not taken; in callback mode they are all delivered first),
  // then gRPC Finish. OK when the server ended the stream cleanly. Idempotent: later calls
  // return the same status. Do not call it while another thread is blocked in Read on a stream
  // that may never end: Cancel first.
  absl::Status Finish();

  // Aborts the call (any thread): pending Send and Read return promptly, Finish gives CANCELLED.
  void Cancel();

  // Frames accepted by Send and not replaced (each once, however often a resilient stream sent
  // it again).
  std::uint64_t frames_sent() const;
  // DELIVERY_LATEST: frames replaced by a newer one before they were sent.
  std::uint64_t frames_replaced() const;
  // StreamOptions::rate_control: the controller's estimate now (its target bitrate is what the
  // next frame's encoder should aim at). Unset without rate control.
  std::optional<RateEstimate> rate() const;
  // Image bytes of the frames accepted by Send (replaced ones included, so that the count only
  // grows): raw pixels, compressed payloads or encoded files (what the uplink carries, without
  // the protocol's few bytes of framing).
  std::uint64_t image_bytes_sent() const;
  // Resilient streams (StreamOptions::resilient): new calls opened after a lost one, and frames
  // sent again on them.
  int reconnects() const;
  std::uint64_t frames_resent() const;

 private:
  friend class Client;
  struct Impl;
  explicit Stream(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// A connection to one cloudcast server. Thread-safe: share one Client between threads.
class Client {
 public:
  // `target` is a gRPC target, e.g. "localhost:50051", "10.0.0.2:50051", "dns:///host:port",
  // "unix:///run/cloudcast.sock". Waits up to options.connect_timeout for the connection;
  // UNAVAILABLE naming the target when it cannot be made in time.
  static absl::StatusOr<std::unique_ptr<Client>> Connect(const std::string& target,
                                                         const ClientOptions& options = {});
  ~Client();
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  // Version, limits, defaults and accepted encodings of the server.
  absl::StatusOr<v1::ServerInfo> GetInfo();

  // One frame, one reply, without a stream. A frame the server rejects gives its error status
  // (INVALID_ARGUMENT / RESOURCE_EXHAUSTED naming the field). config.delivery is ignored.
  absl::StatusOr<Result> Process(const FrameInput& input, const StreamConfig& config = {},
                                 const FrameMeta& meta = {});
  absl::StatusOr<Result> Process(const DisparityInput& disparity, const ColorInput& colour,
                                 const StreamConfig& config = {}, const FrameMeta& meta = {});

  // Starts a Stream call and sends `config` as its first message (an empty config means the
  // server defaults). Fails with UNAVAILABLE when the server is unreachable (at once, or after
  // connect_timeout with wait_for_ready). A server that refuses the stream (e.g.
  // RESOURCE_EXHAUSTED: too many streams) ends it right away, which Read / Finish then report.
  absl::StatusOr<std::unique_ptr<Stream>> OpenStream(const StreamConfig& config = {},
                                                     StreamOptions options = {});

  const std::string& target() const;
  const ClientOptions& options() const;

 private:
  struct Impl;
  explicit Client(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace cloudcast::client
