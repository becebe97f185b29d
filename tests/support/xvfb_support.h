// A display for tests that open windows (the renderer, the client program): when $DISPLAY is
// unset the test binary starts its own Xvfb (Mesa's llvmpipe renders OpenGL into it), sets
// DISPLAY for itself and its children, and stops the server when the process exits.
//
//   TEST(MyGlTest, Draws) {
//     CLOUDCAST_REQUIRE_DISPLAY();   // skips only when Xvfb is not installed
//     ...
//   }
//
// One server per process, started on first use. Xvfb picks a free display number itself
// (-displayfd), which stays race-free when ctest runs many test processes at once; the helper
// then waits for the server's socket /tmp/.X11-unix/X<N> before using it. It runs with -noreset
// (see Start) and gets PR_SET_PDEATHSIG, so it goes away even when the test process crashes.
#pragma once

#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sys/inotify.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace cloudcast::testing {

// An Xvfb server owned by this object: started by Start, terminated (SIGTERM, then SIGKILL
// if it has not exited 5 s later) by the destructor.
class XvfbServer {
 public:
  // "1280x1024x24": the screen Xvfb emulates. Windows larger than it are clipped by X but
  // still render fully into their GL framebuffer.
  static constexpr const char* kScreen = "1280x1024x24";

  // Full path of Xvfb from $PATH, or "" when it is not installed.
  static std::string FindBinary() {
    const char* path = std::getenv("PATH");
    std::stringstream dirs(path != nullptr && *path != '\0' ? path : "/usr/bin:/bin");
    std::string dir;
    while (std::getline(dirs, dir, ':')) {
      if (dir.empty()) continue;
      const std::string candidate = dir + "/Xvfb";
      if (::access(candidate.c_str(), X_OK) == 0) return candidate;
    }
    return "";
  }

  XvfbServer() = default;
  XvfbServer(const XvfbServer&) = delete;
  XvfbServer& operator=(const XvfbServer&) = delete;
  ~XvfbServer() { Stop(); }

  // Starts `binary` and waits (up to `timeout`) until it accepts connections. Returns "" on
  // success, else what went wrong (with the tail of Xvfb's own log).
  std::string Start(const std::string& binary,
                    std::chrono::milliseconds timeout = std::chrono::seconds(20)) {
    int fds[2];
    if (::pipe(fds) != 0) return "pipe() failed";
    log_path_ = (std::filesystem::temp_directory_path() /
                 ("cloudcast-xvfb-" + std::to_string(::getpid()) + ".log"))
                    .string();
    const pid_t parent = ::getpid();
    const std::string displayfd = std::to_string(fds[1]);
    const pid_t pid = ::fork();
    if (pid < 0) {
      ::close(fds[0]);
      ::close(fds[1]);
      return "fork() failed";
    }
    if (pid == 0) {
      // Child: only async-signal-safe calls until exec.
      ::prctl(PR_SET_PDEATHSIG, SIGTERM);
      if (::getppid() != parent) ::_exit(127);  // the parent died before prctl took effect
      ::close(fds[0]);
      const int null_in = ::open("/dev/null", O_RDONLY);
      const int log = ::open(log_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
      if (null_in >= 0) ::dup2(null_in, 0);
      if (log >= 0) {
        ::dup2(log, 1);
        ::dup2(log, 2);
      }
      // -noreset: by default an X server resets when its last client disconnects, and refuses
      // connections meanwhile; tests that close their only window would race the next one.
      const char* argv[] = {
          binary.c_str(), "-displayfd", displayfd.c_str(), "-screen", "0", kScreen,
          "-nolisten",    "tcp",        "-noreset",        nullptr};
      ::execv(binary.c_str(), const_cast<char* const*>(argv));
      ::_exit(127);
    }
    pid_ = pid;
    ::close(fds[1]);

    // Xvfb writes "<N>\n" to the pipe once it listens; EOF first means it exited.
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    std::string number;
    while (number.empty() || number.back() != '\n') {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) break;
      pollfd p{fds[0], POLLIN, 0};
      if (::poll(&p, 1, static_cast<int>(left.count())) <= 0) continue;
      char buffer[16];
      const ssize_t n = ::read(fds[0], buffer, sizeof(buffer));
      if (n <= 0) break;
      number.append(buffer, static_cast<std::size_t>(n));
    }
    ::close(fds[0]);
    if (number.empty() || number.back() != '\n') {
      const std::string why = "Xvfb did not report a display number: " + LogTail();
      Stop();
      return why;
    }
    number.pop_back();
    display_ = ":" + number;
    const std::string socket = "/tmp/.X11-unix/X" + number;
    if (!WaitForFile(socket, deadline)) {
      const std::string why = "Xvfb's socket " + socket + " did not appear: " + LogTail();
      Stop();
      return why;
    }
    return "";
  }

  // ":<N>", once started.
  const std::string& display() const { return display_; }
  pid_t pid() const { return pid_; }

  void Stop() {
    if (pid_ <= 0) return;
    ::kill(pid_, SIGTERM);
    int status = 0;
    if (!WaitForExit(pid_, std::chrono::seconds(5))) {
      ::kill(pid_, SIGKILL);
    }
    ::waitpid(pid_, &status, 0);
    pid_ = -1;
    std::error_code ec;
    std::filesystem::remove(log_path_, ec);
  }

 private:
  // Waits until child `pid` has exited (not reaped yet), up to `timeout`: poll() on a pidfd,
  // which becomes readable when the process ends. False on timeout, or when the kernel has no
  // pidfd_open (then the caller kills at once).
  static bool WaitForExit(pid_t pid, std::chrono::milliseconds timeout) {
#ifdef SYS_pidfd_open
    const int fd = static_cast<int>(::syscall(SYS_pidfd_open, pid, 0));
    if (fd < 0) return false;
    pollfd p{fd, POLLIN, 0};
    const int ready = ::poll(&p, 1, static_cast<int>(timeout.count()));
    ::close(fd);
    return ready > 0;
#else
    (void)pid;
    (void)timeout;
    return false;
#endif
  }

  // Waits until `path` exists, up to `deadline`: an inotify watch on its folder wakes us when
  // entries appear. -displayfd reports the number once Xvfb listens, so the socket is normally
  // there already.
  static bool WaitForFile(const std::filesystem::path& path,
                          std::chrono::steady_clock::time_point deadline) {
    const int fd = ::inotify_init1(IN_CLOEXEC | IN_NONBLOCK);
    if (fd < 0) return std::filesystem::exists(path);
    // The watch before the check, so that an entry made in between is not missed.
    const bool watching =
        ::inotify_add_watch(fd, path.parent_path().c_str(), IN_CREATE | IN_MOVED_TO) >= 0;
    bool found = std::filesystem::exists(path);
    while (!found && watching) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) break;
      pollfd p{fd, POLLIN, 0};
      if (::poll(&p, 1, static_cast<int>(left.count())) > 0) {
        char events[4096];
        while (::read(fd, events, sizeof(events)) > 0) {
        }
      }
      found = std::filesystem::exists(path);
    }
    ::close(fd);
    return found;
  }

  std::string LogTail() const {
    std::ifstream file(log_path_);
    std::stringstream ss;
    ss << file.rdbuf();
    std::string log = ss.str();
    if (log.size() > 2000) log = "..." + log.substr(log.size() - 2000);
    return log.empty() ? std::string("(Xvfb printed nothing)") : log;
  }

  pid_t pid_ = -1;
  std::string display_;
  std::string log_path_;
};

// The process-wide display, prepared on first call: $DISPLAY if set, else a new Xvfb whose
// display is then exported as $DISPLAY (so child processes inherit it).
struct DisplayStatus {
  enum Kind { kReady, kNoXvfb, kFailed } kind = kFailed;
  std::string message;  // what is used (kReady) or why not
};

inline const DisplayStatus& EnsureDisplay() {
  static XvfbServer* server = nullptr;
  static const DisplayStatus status = [] {
    DisplayStatus s;
    if (const char* d = std::getenv("DISPLAY"); d != nullptr && *d != '\0') {
      s.kind = DisplayStatus::kReady;
      s.message = std::string("using DISPLAY=") + d;
      return s;
    }
    const std::string binary = XvfbServer::FindBinary();
    if (binary.empty()) {
      s.kind = DisplayStatus::kNoXvfb;
      s.message =
          "DISPLAY is unset and Xvfb is not installed (Debian: apt-get install xvfb); "
          "this test needs an X display with OpenGL 3.3";
      return s;
    }
    // Never destroyed as a static: stopped by atexit instead, after the tests have closed their
    // windows. A crash is covered by PR_SET_PDEATHSIG.
    server = new XvfbServer;
    if (std::string error = server->Start(binary); !error.empty()) {
      s.kind = DisplayStatus::kFailed;
      s.message = "could not start " + binary + ": " + error;
      delete server;
      server = nullptr;
      return s;
    }
    ::setenv("DISPLAY", server->display().c_str(), 1);
    std::atexit([] {
      if (server != nullptr) server->Stop();
    });
    s.kind = DisplayStatus::kReady;
    s.message = "started " + binary + " on DISPLAY=" + server->display();
    return s;
  }();
  return status;
}

// Skips the test when Xvfb is missing (and DISPLAY unset); fails it when a display should have
// been available but could not be started.
#define CLOUDCAST_REQUIRE_DISPLAY()                                              \
  do {                                                                           \
    const ::cloudcast::testing::DisplayStatus& display_status_ =                 \
        ::cloudcast::testing::EnsureDisplay();                                   \
    if (display_status_.kind == ::cloudcast::testing::DisplayStatus::kNoXvfb) {  \
      GTEST_SKIP() << display_status_.message;                                   \
    }                                                                            \
    ASSERT_EQ(display_status_.kind, ::cloudcast::testing::DisplayStatus::kReady) \
        << display_status_.message;                                              \
  } while (0)

}  // namespace cloudcast::testing
