// libcloudcast_tcp_cc.so: LD_PRELOAD it with CLOUDCAST_TCP_CC=cubic (or bbr, reno) and every TCP
// socket the program opens uses that congestion control, set per socket (TCP_CONGESTION).
// Why: this kernel lets a network namespace make only the host's "allowed" algorithms its default
// (here reno and bbr), and the benchmarks must not change the host; per socket, a root process may
// pick any available algorithm, and accepted connections inherit their listener's. It lets the
// benchmarks run today's unmodified server and load generator with CUBIC, as robots do.
#include <dlfcn.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>

extern "C" int socket(int domain, int type, int protocol) {
  using SocketFn = int (*)(int, int, int);
  static SocketFn real = reinterpret_cast<SocketFn>(dlsym(RTLD_NEXT, "socket"));
  const int fd = real(domain, type, protocol);
  const char* name = std::getenv("CLOUDCAST_TCP_CC");
  if (fd >= 0 && name != nullptr && *name != '\0' && (domain == AF_INET || domain == AF_INET6) &&
      (type & 0xf) == SOCK_STREAM) {
    if (setsockopt(fd, IPPROTO_TCP, TCP_CONGESTION, name,
                   static_cast<socklen_t>(std::strlen(name))) != 0) {
      // Say so once: a figure measured with the wrong algorithm would be mislabelled.
      static bool said = false;
      if (!said) {
        said = true;
        std::fprintf(stderr, "libcloudcast_tcp_cc: cannot set TCP congestion control '%s'\n", name);
      }
    }
  }
  return fd;
}
