#include "raw_h2.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

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

absl::StatusOr<std::unique_ptr<RawH2Connection>> RawH2Connection::Connect(
    const std::string& host, int port, const std::string& source) {
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
  std::unique_ptr<RawH2Connection> c(new RawH2Connection(fd));
  const std::string preface =
      std::string("PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n") + Frame(kSettings, 0, 0, "");
  if (!c->Write(preface, std::chrono::steady_clock::now() + std::chrono::seconds(2))) {
    return absl::UnavailableError("the server closed the connection during the preface");
  }
  return c;
}

RawH2Connection::RawH2Connection(int fd) : fd_(fd) {
  reader_ = std::thread([this] { Read(); });
}

RawH2Connection::~RawH2Connection() {
  stop_.store(true);
  shutdown(fd_, SHUT_RDWR);
  reader_.join();
  close(fd_);
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
  while (!stop_.load()) {
    pollfd p{fd_, POLLIN, 0};
    if (poll(&p, 1, 100) <= 0) continue;
    const ssize_t n = recv(fd_, buf, sizeof buf, 0);
    if (n <= 0) {
      if (n < 0 && (errno == EAGAIN || errno == EINTR)) continue;
      closed_.store(true);
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
          if ((flags & kAck) == 0) replies += Frame(kSettings, kAck, 0, "");
          break;
        case kPing:
          if ((flags & kAck) == 0 && length == 8) {
            replies +=
                Frame(kPing, kAck, 0, std::string_view(reinterpret_cast<const char*>(payload), 8));
          }
          break;
        case kData:
          if (length > 0) {
            replies += WindowUpdate(0, static_cast<std::uint32_t>(length));
            replies += WindowUpdate(stream, static_cast<std::uint32_t>(length));
          }
          break;
        case kGoAway:
          ++stats_.goaways;
          if (length >= 8) stats_.last_goaway_code = Get32(payload + 4);
          break;
        case kRstStream:
          ++stats_.rst_streams_received;
          break;
        case kHeaders:
          ++stats_.headers_received;
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
