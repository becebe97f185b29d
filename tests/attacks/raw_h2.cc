#include "raw_h2.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <vector>

#include "absl/strings/str_cat.h"

namespace cloudcast::attacks {
namespace {

void Put24(std::uint32_t v, std::string* out) {
  out->push_back(static_cast<char>((v >> 16) & 0xff));
  out->push_back(static_cast<char>((v >> 8) & 0xff));
  out->push_back(static_cast<char>(v & 0xff));
}

void Put32(std::uint32_t v, std::string* out) {
  out->push_back(static_cast<char>((v >> 24) & 0xff));
  Put24(v, out);
}

std::uint32_t Get32(const unsigned char* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) |
         p[3];
}

std::string WindowUpdate(std::uint32_t stream, std::uint32_t increment) {
  std::string payload;
  Put32(increment & 0x7fffffffu, &payload);
  return Frame(kWindowUpdate, 0, stream, payload);
}

bool ParseIpv4(const std::string& host, in_addr* out) {
  return inet_pton(AF_INET, host.c_str(), out) == 1;
}

}  // namespace

std::string Frame(std::uint8_t type, std::uint8_t flags, std::uint32_t stream,
                  std::string_view payload) {
  std::string f;
  f.reserve(9 + payload.size());
  Put24(static_cast<std::uint32_t>(payload.size()), &f);
  f.push_back(static_cast<char>(type));
  f.push_back(static_cast<char>(flags));
  Put32(stream & 0x7fffffffu, &f);
  f.append(payload);
  return f;
}

std::string RstStream(std::uint32_t stream, std::uint32_t error_code) {
  std::string payload;
  Put32(error_code, &payload);
  return Frame(kRstStream, 0, stream, payload);
}

void AppendHpackInteger(std::uint64_t value, int prefix_bits, std::uint8_t first_byte_flags,
                        std::string* out) {
  const std::uint64_t max_prefix = (std::uint64_t{1} << prefix_bits) - 1;
  if (value < max_prefix) {
    out->push_back(static_cast<char>(first_byte_flags | value));
    return;
  }
  out->push_back(static_cast<char>(first_byte_flags | max_prefix));
  value -= max_prefix;
  while (value >= 128) {
    out->push_back(static_cast<char>((value & 0x7f) | 0x80));
    value >>= 7;
  }
  out->push_back(static_cast<char>(value));
}

std::string HpackLiteral(std::string_view name, std::string_view value, bool incremental_indexing) {
  std::string out;
  // Index 0: the name follows as a literal.
  if (incremental_indexing) {
    AppendHpackInteger(0, 6, 0x40, &out);
  } else {
    AppendHpackInteger(0, 4, 0x00, &out);
  }
  AppendHpackInteger(name.size(), 7, 0x00, &out);  // H = 0: no Huffman
  out.append(name);
  AppendHpackInteger(value.size(), 7, 0x00, &out);
  out.append(value);
  return out;
}

std::string GrpcRequestHeaders(std::string_view path, std::string_view authority) {
  std::string block;
  for (const auto& [name, value] :
       {std::pair<std::string_view, std::string_view>{":method", "POST"},
        {":scheme", "http"},
        {":path", path},
        {":authority", authority},
        {"content-type", "application/grpc"},
        {"te", "trailers"}}) {
    block += HpackLiteral(name, value, /*incremental_indexing=*/false);
  }
  return block;
}

std::string GrpcMessage(std::string_view bytes) {
  std::string m(1, '\0');
  Put32(static_cast<std::uint32_t>(bytes.size()), &m);
  m.append(bytes);
  return m;
}

bool SplitHostPort(const std::string& target, std::string* host, int* port) {
  const std::size_t colon = target.rfind(':');
  if (colon == std::string::npos || colon == 0) return false;
  *host = target.substr(0, colon);
  try {
    std::size_t used = 0;
    *port = std::stoi(target.substr(colon + 1), &used);
    return used == target.size() - colon - 1 && *port > 0 && *port < 65536;
  } catch (...) {
    return false;
  }
}

absl::StatusOr<std::unique_ptr<RawH2Connection>> RawH2Connection::Connect(const std::string& host,
                                                                          int port,
                                                                          const std::string& source,
                                                                          WindowPolicy window) {
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(static_cast<std::uint16_t>(port));
  if (!ParseIpv4(host, &to.sin_addr)) {
    return absl::InvalidArgumentError(
        absl::StrCat("--target: '", host, "' is not an IPv4 address"));
  }
  const int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return absl::UnavailableError(absl::StrCat("socket: ", std::strerror(errno)));
  if (!source.empty()) {
    sockaddr_in from{};
    from.sin_family = AF_INET;
    if (!ParseIpv4(source, &from.sin_addr)) {
      close(fd);
      return absl::InvalidArgumentError(
          absl::StrCat("--source: '", source, "' is not an IPv4 address"));
    }
    if (bind(fd, reinterpret_cast<sockaddr*>(&from), sizeof from) != 0) {
      const int e = errno;
      close(fd);
      return absl::UnavailableError(
          absl::StrCat("--source ", source, ": cannot bind: ", std::strerror(e)));
    }
  }
  if (connect(fd, reinterpret_cast<sockaddr*>(&to), sizeof to) != 0) {
    const int e = errno;
    close(fd);
    return absl::UnavailableError(
        absl::StrCat("cannot connect to ", host, ":", port, ": ", std::strerror(e)));
  }
  const int one = 1;
  setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  std::unique_ptr<RawH2Connection> c(new RawH2Connection(fd, window));
  const std::string preface =
      std::string("PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n") + Frame(kSettings, 0, 0, "");
  if (!c->Write(preface, std::chrono::steady_clock::now() + std::chrono::seconds(2))) {
    return absl::UnavailableError("the server closed the connection during the preface");
  }
  return c;
}

RawH2Connection::RawH2Connection(int fd, WindowPolicy window)
    : fd_(fd), window_(window), rate_last_(std::chrono::steady_clock::now()) {
  reader_ = std::thread([this] { Read(); });
}

RawH2Connection::~RawH2Connection() {
  stop_.store(true);
  shutdown(fd_, SHUT_RDWR);
  if (reader_.joinable()) reader_.join();
  close(fd_);
}

void RawH2Connection::StopReading() {
  stop_.store(true);
  if (reader_.joinable()) reader_.join();
}

void RawH2Connection::ResetOnClose() {
  const linger l{1, 0};
  setsockopt(fd_, SOL_SOCKET, SO_LINGER, &l, sizeof l);
}

ConnectionStats RawH2Connection::stats() const {
  std::lock_guard<std::mutex> lock(stats_mu_);
  return stats_;
}

bool RawH2Connection::Write(std::string_view bytes,
                            std::chrono::steady_clock::time_point deadline) {
  std::lock_guard<std::mutex> lock(write_mu_);
  return WriteLocked(bytes, deadline);
}

bool RawH2Connection::OpenStream(std::uint32_t stream, std::string_view header_block,
                                 bool end_stream, std::chrono::steady_clock::time_point deadline) {
  {
    std::lock_guard<std::mutex> lock(stats_mu_);
    streams_[stream].send_window = peer_initial_window_;
  }
  return Write(Frame(kHeaders, kEndHeaders | (end_stream ? kEndStream : 0), stream, header_block),
               deadline);
}

bool RawH2Connection::StreamEnded(std::uint32_t stream) const {
  std::lock_guard<std::mutex> lock(stats_mu_);
  const auto it = streams_.find(stream);
  return it == streams_.end() || it->second.ended;
}

bool RawH2Connection::SendData(std::uint32_t stream, std::string_view bytes, bool end_stream,
                               std::chrono::steady_clock::time_point deadline) {
  for (;;) {
    std::size_t n = 0;
    {
      std::unique_lock<std::mutex> lock(stats_mu_);
      for (;;) {
        const auto it = streams_.find(stream);
        if (closed_.load() || it == streams_.end() || it->second.ended) return false;
        if (bytes.empty()) break;  // END_STREAM alone needs no window
        const std::int64_t room = std::min(conn_send_window_, it->second.send_window);
        if (room > 0) {
          n = std::min({bytes.size(), peer_max_frame_, static_cast<std::size_t>(room)});
          conn_send_window_ -= static_cast<std::int64_t>(n);
          it->second.send_window -= static_cast<std::int64_t>(n);
          break;
        }
        const auto now = std::chrono::steady_clock::now();
        if (now >= deadline) return false;
        // Bounded waits: the reader does not signal a closed connection.
        window_cv_.wait_until(lock, std::min(deadline, now + std::chrono::milliseconds(100)));
      }
    }
    const bool last = n == bytes.size();
    if (!Write(Frame(kData, last && end_stream ? kEndStream : 0, stream, bytes.substr(0, n)),
               deadline)) {
      return false;
    }
    bytes.remove_prefix(n);
    if (last) return true;
  }
}

void RawH2Connection::CountMessages(Stream* s, const unsigned char* p, std::size_t n) {
  while (n > 0) {
    if (s->prefix_have < 5) {
      const std::size_t take = std::min<std::size_t>(5 - s->prefix_have, n);
      std::memcpy(s->prefix + s->prefix_have, p, take);
      s->prefix_have += take;
      p += take;
      n -= take;
      if (s->prefix_have == 5) {
        s->body_left = Get32(s->prefix + 1);
        if (s->body_left == 0) {
          ++stats_.messages_received;
          s->prefix_have = 0;
        }
      }
      continue;
    }
    const std::size_t take = static_cast<std::size_t>(std::min<std::uint64_t>(s->body_left, n));
    s->body_left -= take;
    p += take;
    n -= take;
    if (s->body_left == 0) {
      ++stats_.messages_received;
      s->prefix_have = 0;
    }
  }
}

std::string RawH2Connection::PacedWindowUpdates(std::chrono::steady_clock::time_point now) {
  if (window_.mode != WindowPolicy::kRate) return "";
  const double dt = std::chrono::duration<double>(now - rate_last_).count();
  rate_last_ = now;
  // At most a second's worth (or one frame's) saved up while nothing was owed.
  rate_budget_ = std::min(rate_budget_ + window_.bytes_per_second * dt,
                          std::max(window_.bytes_per_second, 16384.0));
  const std::uint64_t give =
      std::min<std::uint64_t>(static_cast<std::uint64_t>(rate_budget_), conn_owed_);
  if (give == 0) return "";
  rate_budget_ -= static_cast<double>(give);
  conn_owed_ -= give;
  stats_.window_given_back += give;
  std::string out = WindowUpdate(0, static_cast<std::uint32_t>(give));
  // The same amount to the streams that are owed it, round robin.
  std::uint64_t left = give;
  auto it = streams_.upper_bound(rate_next_stream_);
  for (std::size_t visited = 0; left > 0 && visited < 2 * streams_.size(); ++visited, ++it) {
    if (it == streams_.end()) it = streams_.begin();
    if (it->second.owed == 0) continue;
    const std::uint64_t g = std::min(left, it->second.owed);
    it->second.owed -= g;
    left -= g;
    rate_next_stream_ = it->first;
    out += WindowUpdate(it->first, static_cast<std::uint32_t>(g));
  }
  return out;
}

bool RawH2Connection::WriteLocked(std::string_view bytes,
                                  std::chrono::steady_clock::time_point deadline) {
  while (!bytes.empty()) {
    if (closed_.load()) return false;
    const auto left = deadline - std::chrono::steady_clock::now();
    if (left <= std::chrono::steady_clock::duration::zero()) return false;
    pollfd p{fd_, POLLOUT, 0};
    const int ms = static_cast<int>(std::min<std::int64_t>(
        100, std::chrono::duration_cast<std::chrono::milliseconds>(left).count() + 1));
    if (poll(&p, 1, ms) <= 0) continue;
    if ((p.revents & (POLLERR | POLLHUP)) != 0) {
      closed_.store(true);
      return false;
    }
    const ssize_t n = send(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
    if (n < 0) {
      if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) continue;
      closed_.store(true);
      return false;
    }
    bytes.remove_prefix(static_cast<std::size_t>(n));
  }
  return true;
}

void RawH2Connection::Read() {
  std::vector<unsigned char> in;
  std::size_t at = 0;
  unsigned char buf[65536];
  // Paced window updates need a finer tick than a reader's 100 ms.
  const int tick_ms = window_.mode == WindowPolicy::kRate ? 20 : 100;
  while (!stop_.load()) {
    pollfd p{fd_, POLLIN, 0};
    const int ready = poll(&p, 1, tick_ms);
    if (window_.mode == WindowPolicy::kRate) {
      std::string updates;
      {
        std::lock_guard<std::mutex> lock(stats_mu_);
        updates = PacedWindowUpdates(std::chrono::steady_clock::now());
      }
      if (!updates.empty()) {
        std::lock_guard<std::mutex> lock(write_mu_);
        WriteLocked(updates, std::chrono::steady_clock::now() + std::chrono::seconds(1));
      }
    }
    if (ready <= 0) continue;
    const ssize_t n = recv(fd_, buf, sizeof buf, 0);
    if (n <= 0) {
      if (n < 0 && (errno == EAGAIN || errno == EINTR)) continue;
      closed_.store(true);
      window_cv_.notify_all();
      return;
    }
    in.insert(in.end(), buf, buf + n);
    {
      std::lock_guard<std::mutex> lock(stats_mu_);
      stats_.bytes_read += static_cast<std::uint64_t>(n);
    }
    // Every whole frame in the buffer.
    std::string replies;
    while (in.size() - at >= 9) {
      const unsigned char* h = in.data() + at;
      const std::size_t length = (std::size_t{h[0]} << 16) | (std::size_t{h[1]} << 8) | h[2];
      if (in.size() - at < 9 + length) break;
      const std::uint8_t type = h[3], flags = h[4];
      const std::uint32_t stream = Get32(h + 5) & 0x7fffffffu;
      const unsigned char* payload = h + 9;
      std::lock_guard<std::mutex> lock(stats_mu_);
      ++stats_.frames_read;
      switch (type) {
        case kSettings:
          if ((flags & kAck) == 0) {
            for (std::size_t i = 0; i + 6 <= length; i += 6) {
              const std::uint16_t id =
                  static_cast<std::uint16_t>((payload[i] << 8) | payload[i + 1]);
              const std::uint32_t value = Get32(payload + i + 2);
              if (id == 0x4) {  // SETTINGS_INITIAL_WINDOW_SIZE: applies to open streams too
                const std::int64_t delta = std::int64_t{value} - peer_initial_window_;
                peer_initial_window_ = value;
                for (auto& entry : streams_) entry.second.send_window += delta;
              } else if (id == 0x5) {  // SETTINGS_MAX_FRAME_SIZE
                peer_max_frame_ = value;
              }
            }
            replies += Frame(kSettings, kAck, 0, "");
            window_cv_.notify_all();
          }
          break;
        case kWindowUpdate:
          if (length == 4) {
            const std::uint32_t increment = Get32(payload) & 0x7fffffffu;
            if (stream == 0) {
              conn_send_window_ += increment;
            } else if (auto it = streams_.find(stream); it != streams_.end()) {
              it->second.send_window += increment;
            }
            window_cv_.notify_all();
          }
          break;
        case kPing:
          if ((flags & kAck) == 0 && length == 8) {
            replies +=
                Frame(kPing, kAck, 0, std::string_view(reinterpret_cast<const char*>(payload), 8));
          }
          break;
        case kData: {
          stats_.data_bytes_received += length;
          Stream* s = nullptr;
          if (auto it = streams_.find(stream); it != streams_.end()) s = &it->second;
          if (s != nullptr && length > 0) {
            // A padded frame: its pad length first, its padding last (counted for flow control).
            std::size_t skip = 0, pad = 0;
            if ((flags & 0x8) != 0) {
              skip = 1;
              pad = payload[0];
            }
            if (length >= skip + pad) CountMessages(s, payload + skip, length - skip - pad);
          }
          if (s != nullptr && (flags & kEndStream) != 0 && !s->ended) {
            s->ended = true;
            ++stats_.streams_ended;
            window_cv_.notify_all();
          }
          if (length > 0) {
            if (window_.mode == WindowPolicy::kAsReceived) {
              replies += WindowUpdate(0, static_cast<std::uint32_t>(length));
              replies += WindowUpdate(stream, static_cast<std::uint32_t>(length));
              stats_.window_given_back += length;
            } else {
              conn_owed_ += length;
              if (s != nullptr) s->owed += length;
            }
          }
          break;
        }
        case kGoAway:
          ++stats_.goaways;
          if (length >= 8) stats_.last_goaway_code = Get32(payload + 4);
          break;
        case kRstStream:
          ++stats_.rst_streams_received;
          if (auto it = streams_.find(stream); it != streams_.end() && !it->second.ended) {
            it->second.ended = true;
            ++stats_.streams_ended;
            window_cv_.notify_all();
          }
          break;
        case kHeaders:
          ++stats_.headers_received;
          if ((flags & kEndStream) != 0) {  // trailers (or a trailers-only answer)
            if (auto it = streams_.find(stream); it != streams_.end() && !it->second.ended) {
              it->second.ended = true;
              ++stats_.streams_ended;
              window_cv_.notify_all();
            }
          }
          break;
        default:
          break;
      }
      at += 9 + length;
    }
    if (at > 0 && at == in.size()) {
      in.clear();
      at = 0;
    } else if (at > (1u << 20)) {
      in.erase(in.begin(), in.begin() + static_cast<std::ptrdiff_t>(at));
      at = 0;
    }
    if (!replies.empty()) {
      std::lock_guard<std::mutex> lock(write_mu_);
      WriteLocked(replies, std::chrono::steady_clock::now() + std::chrono::seconds(1));
    }
  }
}

}  // namespace cloudcast::attacks
