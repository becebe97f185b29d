// A raw HTTP/2 client over a plain TCP socket, for the attacks a client library never sends:
// frames are written by hand and header blocks are HPACK literals (no Huffman coding, no table
// references), so every byte on the wire is the attacker's choice. It reads what the server sends
// on a thread of its own and behaves as a peer must on the connection level (SETTINGS and PING
// acknowledged, received DATA given back as window, unless a WindowPolicy says otherwise), so
// that what the server suffers is the attack and nothing else; it counts the GOAWAY and
// RST_STREAM frames it gets. SendData sends a stream's body as the peer's flow-control windows
// allow (RFC 9113, section 5.2), as a real client must.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <thread>

#include "absl/status/statusor.h"

namespace cloudcast::attacks {

// Frame types and flags (RFC 9113, section 6).
enum FrameType : std::uint8_t {
  kData = 0,
  kHeaders = 1,
  kRstStream = 3,
  kSettings = 4,
  kPing = 6,
  kGoAway = 7,
  kWindowUpdate = 8,
  kContinuation = 9,
};
constexpr std::uint8_t kEndStream = 0x1;
constexpr std::uint8_t kAck = 0x1;
constexpr std::uint8_t kEndHeaders = 0x4;
constexpr std::uint32_t kCancel = 0x8;  // RST_STREAM error code

// One frame: the 9-byte header, then `payload`.
std::string Frame(std::uint8_t type, std::uint8_t flags, std::uint32_t stream,
                  std::string_view payload);
std::string RstStream(std::uint32_t stream, std::uint32_t error_code);

// HPACK (RFC 7541): an integer with an N-bit prefix, and a literal header field with a new name
// (section 6.2): "incremental indexing" (0x40, the decoder adds it to its dynamic table) or
// "without indexing" (0x00). Strings are sent as they are (no Huffman).
void AppendHpackInteger(std::uint64_t value, int prefix_bits, std::uint8_t first_byte_flags,
                        std::string* out);
std::string HpackLiteral(std::string_view name, std::string_view value, bool incremental_indexing);

// The header block of a gRPC call: POST `path` over http, content-type application/grpc,
// te: trailers (what a gRPC server requires).
std::string GrpcRequestHeaders(std::string_view path, std::string_view authority);

// A gRPC message on the wire: a 0 byte (not compressed), its 4-byte length, the bytes.
std::string GrpcMessage(std::string_view bytes);

// How the client gives back the flow-control window of the DATA it receives. Its SETTINGS are
// empty, so it advertises HTTP/2's default window: 65,535 bytes per stream and for the
// connection.
struct WindowPolicy {
  enum Mode {
    kAsReceived,  // a WINDOW_UPDATE for the stream and the connection as each DATA frame arrives
    kNever,       // none at all: the peer may send 64 KB, then must wait for ever
    kRate,        // given back at `bytes_per_second` (the connection's and the streams' alike)
  };
  Mode mode = kAsReceived;
  double bytes_per_second = 0;
};

struct ConnectionStats {
  std::uint64_t frames_read = 0;
  std::uint64_t bytes_read = 0;
  std::uint64_t goaways = 0;
  std::uint32_t last_goaway_code = 0;
  std::uint64_t rst_streams_received = 0;
  std::uint64_t headers_received = 0;
  std::uint64_t data_bytes_received = 0;  // DATA payloads
  std::uint64_t window_given_back = 0;    // WINDOW_UPDATE increments sent (connection level)
  std::uint64_t messages_received = 0;    // whole gRPC messages in DATA, every stream
  std::uint64_t streams_ended = 0;        // streams the peer ended (END_STREAM or RST_STREAM)
};

class RawH2Connection {
 public:
  // Connects to host:port (an IPv4 address) from `source` (an IPv4 address of this machine; empty:
  // the kernel's choice), sends the client preface and an empty SETTINGS frame, and starts
  // reading. UNAVAILABLE when the connection cannot be made.
  static absl::StatusOr<std::unique_ptr<RawH2Connection>> Connect(const std::string& host, int port,
                                                                  const std::string& source,
                                                                  WindowPolicy window = {});
  ~RawH2Connection();  // closes the socket and joins the reader
  RawH2Connection(const RawH2Connection&) = delete;
  RawH2Connection& operator=(const RawH2Connection&) = delete;

  // Writes all of `bytes`, or gives up at `deadline`; false when the connection is gone (or the
  // deadline passed first: a server that stops reading holds the writer back no longer).
  bool Write(std::string_view bytes, std::chrono::steady_clock::time_point deadline);

  // Opens `stream` (odd, above every stream opened before) with a HEADERS frame carrying
  // `header_block` (END_HEADERS; END_STREAM when `end_stream`), and starts counting its window.
  bool OpenStream(std::uint32_t stream, std::string_view header_block, bool end_stream,
                  std::chrono::steady_clock::time_point deadline);
  // Sends `bytes` on an open stream as DATA frames of at most the peer's SETTINGS_MAX_FRAME_SIZE,
  // each when the peer's connection and stream windows have room for it (waiting for its
  // WINDOW_UPDATEs), END_STREAM on the last when `end_stream`. False when the connection is gone,
  // the peer reset the stream, or the deadline passed first.
  bool SendData(std::uint32_t stream, std::string_view bytes, bool end_stream,
                std::chrono::steady_clock::time_point deadline);
  // The peer ended the stream (END_STREAM or RST_STREAM).
  bool StreamEnded(std::uint32_t stream) const;

  // Stops reading what the peer sends (it stays in the socket, as with a process that has
  // stopped: closing the socket then resets the connection when anything is left unread).
  void StopReading();
  // Closing the socket will reset the connection at once (SO_LINGER 0), whatever is unsent.
  void ResetOnClose();

  // The server closed the connection (or it failed).
  bool closed() const { return closed_.load(); }
  ConnectionStats stats() const;

 private:
  // What the client knows of one stream: the peer's window for it, what it owes the peer, the
  // gRPC message it is in the middle of reading.
  struct Stream {
    std::int64_t send_window = 0;
    std::uint64_t owed = 0;  // received, not yet given back
    bool ended = false;
    unsigned char prefix[5] = {};
    std::size_t prefix_have = 0;
    std::uint64_t body_left = 0;
  };

  RawH2Connection(int fd, WindowPolicy window);
  void Read();
  bool WriteLocked(std::string_view bytes, std::chrono::steady_clock::time_point deadline);
  // Under stats_mu_: counts the gRPC messages in a DATA payload of `s`.
  void CountMessages(Stream* s, const unsigned char* p, std::size_t n);
  // Under stats_mu_: the WINDOW_UPDATEs that WindowPolicy::kRate allows by now.
  std::string PacedWindowUpdates(std::chrono::steady_clock::time_point now);

  const int fd_;
  const WindowPolicy window_;
  std::mutex write_mu_;
  std::atomic<bool> closed_{false};
  std::atomic<bool> stop_{false};
  mutable std::mutex stats_mu_;  // also the windows and streams below
  std::condition_variable window_cv_;
  ConnectionStats stats_;
  std::int64_t peer_initial_window_ = 65535;
  std::size_t peer_max_frame_ = 16384;
  std::int64_t conn_send_window_ = 65535;
  std::uint64_t conn_owed_ = 0;
  double rate_budget_ = 0;
  std::chrono::steady_clock::time_point rate_last_;
  std::uint32_t rate_next_stream_ = 0;
  std::map<std::uint32_t, Stream> streams_;
  std::thread reader_;
};

// "host:port" split; false when it is not one.
bool SplitHostPort(const std::string& target, std::string* host, int* port);

}  // namespace cloudcast::attacks
