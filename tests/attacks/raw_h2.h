// A raw HTTP/2 client over a plain TCP socket, for the attacks a client library never sends:
// frames are written by hand and header blocks are HPACK literals (no Huffman coding, no table
// references), so every byte on the wire is the attacker's choice. It reads what the server sends
// on a thread of its own and behaves as a peer must on the connection level (SETTINGS and PING
// acknowledged, received DATA given back as window), so that what the server suffers is the
// attack and nothing else; it counts the GOAWAY and RST_STREAM frames it gets.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
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

struct ConnectionStats {
  std::uint64_t frames_read = 0;
  std::uint64_t bytes_read = 0;
  std::uint64_t goaways = 0;
  std::uint32_t last_goaway_code = 0;
  std::uint64_t rst_streams_received = 0;
  std::uint64_t headers_received = 0;
};

class RawH2Connection {
 public:
  // Connects to host:port (an IPv4 address) from `source` (an IPv4 address of this machine; empty:
  // the kernel's choice), sends the client preface and an empty SETTINGS frame, and starts
  // reading. UNAVAILABLE when the connection cannot be made.
  static absl::StatusOr<std::unique_ptr<RawH2Connection>> Connect(const std::string& host, int port,
                                                                  const std::string& source);
  ~RawH2Connection();  // closes the socket and joins the reader
  RawH2Connection(const RawH2Connection&) = delete;
  RawH2Connection& operator=(const RawH2Connection&) = delete;

  // Writes all of `bytes`, or gives up at `deadline`; false when the connection is gone (or the
  // deadline passed first: a server that stops reading holds the writer back no longer).
  bool Write(std::string_view bytes, std::chrono::steady_clock::time_point deadline);

  // The server closed the connection (or it failed).
  bool closed() const { return closed_.load(); }
  ConnectionStats stats() const;

 private:
  explicit RawH2Connection(int fd);
  void Read();
  bool WriteLocked(std::string_view bytes, std::chrono::steady_clock::time_point deadline);

  const int fd_;
  std::mutex write_mu_;
  std::atomic<bool> closed_{false};
  std::atomic<bool> stop_{false};
  mutable std::mutex stats_mu_;
  ConnectionStats stats_;
  std::thread reader_;
};

// "host:port" split; false when it is not one.
bool SplitHostPort(const std::string& target, std::string* host, int* port);

}  // namespace cloudcast::attacks
