#include "cloudcast/linkemu/emulated_link.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace cloudcast::linkemu {

absl::StatusOr<std::unique_ptr<EmulatedLink>> EmulatedLink::Start(const Options& options) {
  std::vector<std::string> argv = {options.binary};
  argv.insert(argv.end(), options.flags.begin(), options.flags.end());
  argv.push_back("--timeout");
  argv.push_back(std::to_string(options.timeout_s));
  int fds[2];
  if (pipe2(fds, O_CLOEXEC) != 0) return absl::InternalError("pipe failed");
  std::vector<char*> args;
  for (std::string& a : argv) args.push_back(a.data());
  args.push_back(nullptr);
  const pid_t parent = getpid();
  const pid_t pid = fork();
  if (pid < 0) return absl::InternalError(absl::StrCat("fork: ", std::strerror(errno)));
  if (pid == 0) {
    prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (getppid() != parent) _exit(1);  // the parent died before prctl
    dup2(fds[1], 1);
    execv(args[0], args.data());
    _exit(127);
  }
  close(fds[1]);
  std::unique_ptr<EmulatedLink> link(new EmulatedLink());
  link->pid_ = pid;
  link->out_fd_ = fds[0];
  for (;;) {
    absl::StatusOr<std::string> line = link->ReadLine(options.ready_within_s);
    if (!line.ok()) {
      return absl::UnavailableError(absl::StrCat(
          options.binary, " gave no ready line: ", line.status().message(), " (see its stderr)"));
    }
    nlohmann::json parsed = nlohmann::json::parse(*line, nullptr, false);
    if (parsed.is_object() && parsed.value("event", "") == "ready") {
      link->ready_ = std::move(parsed);
      return link;
    }
  }
}

absl::StatusOr<std::string> EmulatedLink::ReadLine(double within_s) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(within_s);
  for (;;) {
    const std::size_t newline = buffered_.find('\n');
    if (newline != std::string::npos) {
      std::string line = buffered_.substr(0, newline);
      buffered_.erase(0, newline + 1);
      return line;
    }
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) return absl::DeadlineExceededError("timed out");
    pollfd pfd{out_fd_, POLLIN, 0};
    const int ready = poll(&pfd, 1, static_cast<int>(left.count()));
    if (ready < 0 && errno == EINTR) continue;
    if (ready <= 0) continue;
    char buffer[4096];
    const ssize_t n = read(out_fd_, buffer, sizeof(buffer));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return absl::UnavailableError("the emulator exited");
    buffered_.append(buffer, static_cast<std::size_t>(n));
  }
}

absl::StatusOr<nlohmann::json> EmulatedLink::Stop() {
  if (pid_ < 0) return absl::FailedPreconditionError("already stopped");
  kill(pid_, SIGTERM);
  nlohmann::json stats;
  for (;;) {
    absl::StatusOr<std::string> line = ReadLine(15);
    if (!line.ok()) break;
    nlohmann::json parsed = nlohmann::json::parse(*line, nullptr, false);
    if (parsed.is_object() && parsed.value("event", "") == "stats") stats = std::move(parsed);
  }
  int status = 0;
  if (waitpid(pid_, &status, WNOHANG) == 0) {
    kill(pid_, SIGKILL);
    waitpid(pid_, &status, 0);
  }
  pid_ = -1;
  close(out_fd_);
  out_fd_ = -1;
  if (stats.is_null()) return absl::InternalError("the emulator printed no stats line");
  return stats;
}

EmulatedLink::~EmulatedLink() {
  if (pid_ >= 0) (void)Stop();
}

}  // namespace cloudcast::linkemu
