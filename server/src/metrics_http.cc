#include "metrics_http.h"

#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <deque>
#include <string_view>
#include <vector>

#include "absl/strings/str_cat.h"

namespace cloudcast::server {
namespace {

using Clock = std::chrono::steady_clock;

constexpr std::size_t kMaxRequestBytes = 8192;

// "host:port" and "[v6]:port" into the two parts; the host may be empty (all interfaces).
bool SplitHostPort(const std::string& address, std::string* host, std::string* port) {
  const std::size_t colon = address.rfind(':');
  if (colon == std::string::npos) return false;
  *host = address.substr(0, colon);
  *port = address.substr(colon + 1);
  if (host->size() >= 2 && host->front() == '[' && host->back() == ']') {
    *host = host->substr(1, host->size() - 2);
  }
  return !port->empty();
}

struct Connection {
  int fd = -1;
  std::string in;
  std::string out;
  std::size_t sent = 0;
  Clock::time_point deadline;
  bool responding = false;
};

std::string Response(std::string_view status, std::string_view type, const std::string& body,
                     bool head) {
  std::string r =
      absl::StrCat("HTTP/1.1 ", std::string(status), "\r\nContent-Type: ", std::string(type),
                   "\r\nContent-Length: ", body.size(), "\r\nConnection: close\r\n\r\n");
  if (!head) r += body;
  return r;
}

}  // namespace

absl::StatusOr<std::unique_ptr<MetricsHttpServer>> MetricsHttpServer::Start(
    const Options& options, std::function<std::string()> body) {
  std::string host, port;
  if (!SplitHostPort(options.listen, &host, &port)) {
    return absl::InvalidArgumentError(
        absl::StrCat("metrics address '", options.listen, "' is not host:port"));
  }
  if (host == "localhost") host = "127.0.0.1";
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE | AI_NUMERICHOST | AI_NUMERICSERV;
  addrinfo* found = nullptr;
  if (getaddrinfo(host.empty() ? nullptr : host.c_str(), port.c_str(), &hints, &found) != 0 ||
      found == nullptr) {
    return absl::InvalidArgumentError(
        absl::StrCat("metrics address '", options.listen, "': not a numeric host and port"));
  }
  std::unique_ptr<MetricsHttpServer> server(new MetricsHttpServer());
  server->options_ = options;
  server->body_ = std::move(body);
  const int fd = socket(found->ai_family, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  const int one = 1;
  setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  const bool bound =
      fd >= 0 && bind(fd, found->ai_addr, found->ai_addrlen) == 0 && listen(fd, 128) == 0;
  const int error = errno;
  freeaddrinfo(found);
  if (!bound) {
    if (fd >= 0) close(fd);
    return absl::UnavailableError(
        absl::StrCat("cannot serve metrics on ", options.listen, ": ", std::strerror(error)));
  }
  server->listen_fd_ = fd;
  sockaddr_storage addr{};
  socklen_t len = sizeof addr;
  getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  server->port_ =
      ntohs(addr.ss_family == AF_INET6 ? reinterpret_cast<sockaddr_in6*>(&addr)->sin6_port
                                       : reinterpret_cast<sockaddr_in*>(&addr)->sin_port);
  if (pipe2(server->wake_fd_, O_NONBLOCK | O_CLOEXEC) != 0) {
    return absl::InternalError("metrics server: cannot create its wake-up pipe");
  }
  server->thread_ = std::thread([s = server.get()] { s->Loop(); });
  return server;
}

MetricsHttpServer::~MetricsHttpServer() {
  if (thread_.joinable()) {
    const char byte = 0;
    [[maybe_unused]] const ssize_t n = write(wake_fd_[1], &byte, 1);
    thread_.join();
  }
  for (int fd : {listen_fd_, wake_fd_[0], wake_fd_[1]}) {
    if (fd >= 0) close(fd);
  }
}

void MetricsHttpServer::Loop() {
  std::deque<Connection> connections;  // oldest first
  std::vector<pollfd> fds;
  for (;;) {
    const Clock::time_point now = Clock::now();
    // Connections past their deadline are closed: a slow client gets no more time.
    for (auto it = connections.begin(); it != connections.end();) {
      if (now >= it->deadline) {
        close(it->fd);
        it = connections.erase(it);
      } else {
        ++it;
      }
    }
    fds.clear();
    fds.push_back({listen_fd_, POLLIN, 0});
    fds.push_back({wake_fd_[0], POLLIN, 0});
    int timeout_ms = -1;
    for (const Connection& c : connections) {
      fds.push_back({c.fd, static_cast<short>(c.responding ? POLLOUT : POLLIN), 0});
      const auto left =
          std::chrono::duration_cast<std::chrono::milliseconds>(c.deadline - now).count() + 1;
      timeout_ms =
          timeout_ms < 0 ? static_cast<int>(left) : std::min(timeout_ms, static_cast<int>(left));
    }
    if (poll(fds.data(), fds.size(), timeout_ms) < 0 && errno != EINTR) return;
    if (fds[1].revents != 0) return;  // told to stop

    // Serve the connections that are ready (indexes match `fds` from 2 on).
    std::vector<bool> done(connections.size(), false);
    for (std::size_t i = 0; i < connections.size(); ++i) {
      const short events = fds[i + 2].revents;
      if (events == 0) continue;
      Connection& c = connections[i];
      if (events & (POLLERR | POLLHUP | POLLNVAL) && !(events & POLLIN)) {
        done[i] = true;
        continue;
      }
      if (!c.responding) {
        char buffer[2048];
        const ssize_t n = recv(c.fd, buffer, sizeof buffer, 0);
        if (n <= 0) {
          done[i] = n == 0 || (errno != EAGAIN && errno != EWOULDBLOCK);
          continue;
        }
        c.in.append(buffer, static_cast<std::size_t>(n));
        const bool complete =
            c.in.find("\r\n\r\n") != std::string::npos || c.in.find("\n\n") != std::string::npos;
        if (!complete && c.in.size() < kMaxRequestBytes) continue;
        // The request line: METHOD SP PATH SP VERSION.
        const std::string line = c.in.substr(0, c.in.find_first_of("\r\n"));
        const std::size_t sp1 = line.find(' ');
        const std::size_t sp2 = line.find(' ', sp1 == std::string::npos ? sp1 : sp1 + 1);
        const std::string method = line.substr(0, sp1);
        std::string path = sp1 == std::string::npos ? "" : line.substr(sp1 + 1, sp2 - sp1 - 1);
        path = path.substr(0, path.find('?'));
        const bool head = method == "HEAD";
        if (!complete) {
          c.out =
              Response("431 Request Header Fields Too Large", "text/plain", "too large\n", false);
        } else if (method != "GET" && !head) {
          c.out = Response("405 Method Not Allowed", "text/plain", "GET /metrics\n", false);
        } else if (path == "/metrics") {
          c.out = Response("200 OK", "text/plain; version=0.0.4; charset=utf-8", body_(), head);
        } else {
          c.out = Response("404 Not Found", "text/plain", "cloudcast serves /metrics\n", head);
        }
        c.responding = true;
        c.in.clear();
      }
      if (c.responding) {
        const ssize_t n =
            send(c.fd, c.out.data() + c.sent, c.out.size() - c.sent, MSG_NOSIGNAL | MSG_DONTWAIT);
        if (n > 0) c.sent += static_cast<std::size_t>(n);
        if (c.sent == c.out.size() || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK)) {
          done[i] = true;
        }
      }
    }
    for (std::size_t i = connections.size(); i-- > 0;) {
      if (!done[i]) continue;
      close(connections[i].fd);
      connections.erase(connections.begin() + static_cast<long>(i));
    }

    // New connections, after the old ones were served.
    if (fds[0].revents & POLLIN) {
      for (;;) {
        const int fd = accept4(listen_fd_, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
        if (fd < 0) break;
        if (connections.size() >= options_.max_connections) {
          close(connections.front().fd);  // the one idle the longest makes room
          connections.pop_front();
        }
        Connection c;
        c.fd = fd;
        c.deadline = Clock::now() + options_.request_timeout;
        connections.push_back(std::move(c));
      }
    }
  }
}

}  // namespace cloudcast::server
