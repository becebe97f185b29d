// cloudcast-server: serves the CloudCast gRPC API (proto/cloudcast/v1/cloudcast.proto).
//
// SIGINT / SIGTERM start a graceful shutdown: health checks go NOT_SERVING, new calls are refused,
// frames in flight get --shutdown-grace seconds, then the process exits 0, at the latest half a
// second after the grace period (Server::Shutdown), whatever the clients do. A second signal
// exits at once. SIGHUP re-reads the TLS files and the tokens file (a bad one is logged and the one
// in use stays). Signals are taken by sigwait on the main thread, never inside a signal handler.
//
// Exit status: 0 after a shutdown, 1 when the server cannot start (address in use), 2 for a
// usage error: a bad flag, an unknown --config key, a missing or bad TLS or tokens file.
#include <malloc.h>
#include <pthread.h>
#include <signal.h>
#include <spdlog/spdlog.h>
#include <string.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <string>
#include <thread>

#include "cloudcast/server/cli.h"
#include "cloudcast/server/server.h"

namespace {

// Every frame brings megabyte-sized buffers (gRPC's read slices, the parsed pixels, decoded
// images). glibc serves blocks that large with mmap, or trims them off the heap once freed, so
// each frame faulted its buffers in again: about 100 page faults and a fifth of a millisecond of
// kernel time per raw 640x480 frame (README, part 3 of the profile). Kept on the heap, freed
// buffers are reused by the next frame; blocks over 32 MiB are still mapped and unmapped.
//
// The trim threshold bounds what stays: free memory at the top of a heap beyond 16 MiB (a dozen
// raw 640x480 frames, more than a few streams' steady state reuses) is given back when it is
// freed. It must be a bound, not "never": malloc_trim, which housekeeping calls when the server
// goes idle, releases free chunks inside every arena but the top of a thread arena's heap only
// through this threshold, so a burst's frames freed into worker arenas stayed resident (16
// streams that stopped reading left 132 to 149 MB behind, not 80).
void KeepFrameBuffersOnTheHeap() {
  mallopt(M_MMAP_THRESHOLD, 32 << 20);
  mallopt(M_TRIM_THRESHOLD, 16 << 20);
}

// gRPC 1.51's default TCP read path (its "tcp_read_chunks" experiment) sizes the next read
// buffer from what the last burst of reads brought, without a bound: a client that floods faster
// than the server parses (a CONTINUATION flood) grows it past a gigabyte, and past 2 GiB its int
// arithmetic goes negative, no buffer is allocated and an assertion aborts the process
// (tcp_posix.cc:894; issue 30, defect 5: 3 of 5 floods). The older path clamps every read buffer
// to 4 MiB (grpc.experimental.tcp_max_read_chunk_size); measured under a flood, the untouched
// read buffers went from 0.6-1.3 GB to 64 MB. gRPC reads the variable once, when it starts: it is
// set before any gRPC object exists. An operator's own setting of that experiment is kept.
void BoundTcpReadBuffers() {
  const char* current = std::getenv("GRPC_EXPERIMENTS");
  if (current != nullptr && std::strstr(current, "tcp_read_chunks") != nullptr) return;
  const std::string value = current != nullptr && *current != '\0'
                                ? std::string(current) + ",-tcp_read_chunks"
                                : std::string("-tcp_read_chunks");
  setenv("GRPC_EXPERIMENTS", value.c_str(), 1);
}

// --ready-file: the addresses the server bound, written to a temporary file renamed over the
// target, so that a reader polling for it never sees half of it. A script or test that starts the
// server on port 0 reads the port here instead of picking a "free" port first and racing every
// other process on the machine for it.
bool WriteReadyFile(const std::string& path, const cloudcast::server::Server& server) {
  const std::string temporary = path + ".tmp";
  {
    std::ofstream out(temporary, std::ios::trunc);
    out << "grpc=" << server.address() << "\nmetrics=" << server.metrics_address() << "\n";
    if (!out.flush()) return false;
  }
  return std::rename(temporary.c_str(), path.c_str()) == 0;
}

}  // namespace

int main(int argc, char** argv) {
  KeepFrameBuffersOnTheHeap();
  BoundTcpReadBuffers();
  CLI::App app{
      "cloudcast-server: stereo frames (disparity + colour) in, filtered and Draco-compressed "
      "point clouds out, over gRPC (cloudcast.v1.CloudCast). Health checking and reflection are "
      "on; Prometheus metrics are served over HTTP."};
  cloudcast::server::ServerFlags flags(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ConfigError& e) {
    std::cerr << "cloudcast-server: --config: " << e.what()
              << " (not a flag of cloudcast-server: check its spelling against --help)\n";
    return 2;
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);  // prints --help, or the error
    return code == 0 ? 0 : 2;
  }
  spdlog::set_level(spdlog::level::from_str(flags.log_level()));

  auto options = flags.Options();
  if (!options.ok()) {
    std::cerr << "cloudcast-server: " << options.status().message() << "\n";
    return 2;
  }

  // Blocked before any thread starts, so that every thread inherits the mask and only sigwait
  // below ever sees these signals.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  sigset_t with_hangup = signals;
  sigaddset(&with_hangup, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &with_hangup, nullptr);

  auto server = cloudcast::server::Server::Start(*options);
  if (!server.ok()) {
    // A file the operator named that is missing or bad is a usage error, like a bad flag.
    if (server.status().code() == absl::StatusCode::kInvalidArgument) {
      std::cerr << "cloudcast-server: " << server.status().message() << "\n";
      return 2;
    }
    spdlog::critical("{}", std::string(server.status().message()));
    return 1;
  }

  if (!flags.ready_file().empty() && !WriteReadyFile(flags.ready_file(), **server)) {
    spdlog::critical("cannot write --ready-file {}: {}", flags.ready_file(), strerror(errno));
    return 1;
  }

  int signal_number = 0;
  for (;;) {
    sigwait(&with_hangup, &signal_number);
    if (signal_number != SIGHUP) break;
    spdlog::info("SIGHUP: reloading the TLS and tokens files");
    (void)(*server)->ReloadSecurity();  // logs what it did, and any error
  }
  spdlog::info("{}: shutting down gracefully (again to stop at once)", strsignal(signal_number));
  // SIGHUP stays blocked: a reload during shutdown is pointless, and must not end the process.
  std::thread([signals] {
    int again = 0;
    sigwait(&signals, &again);
    spdlog::warn("{} during shutdown: exiting now", strsignal(again));
    std::_Exit(1);
  }).detach();

  if (!(*server)->Shutdown()) {
    // gRPC is still finishing calls nobody waits for (a flood's), past the grace period: every
    // reply and status of the service went out before, and destroying the server would wait for
    // gRPC without a bound. The process ends here, within the grace period plus
    // Server::kShutdownOverrun.
    spdlog::info("bye (gRPC's remaining calls left to the exit)");
    spdlog::default_logger()->flush();
    std::fflush(nullptr);
    std::_Exit(0);
  }
  server->reset();
  spdlog::info("bye");
  return 0;
}
