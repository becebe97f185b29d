// cloudcast-null-server: answers every Stream frame at once with an empty CloudReply, doing no
// work. A test tool: cloudcast-load against it measures the generator's own ceiling.
#include <pthread.h>
#include <signal.h>

#include <CLI/CLI.hpp>
#include <iostream>

#include "cloudcast/load/null_server.h"

int main(int argc, char** argv) {
  CLI::App app{
      "cloudcast-null-server: a CloudCast.Stream that answers each frame at once with an "
      "empty CloudReply (no processing), for measuring cloudcast-load's own ceiling"};
  std::string listen = "127.0.0.1:0", instance = "null";
  app.add_option("--listen", listen, "HOST:PORT; port 0 picks a free one (printed)")
      ->capture_default_str();
  app.add_option("--instance", instance, "server_instance in every reply")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  auto server = cloudcast::load::NullServer::Start(listen, instance);
  if (!server.ok()) {
    std::cerr << "cloudcast-null-server: " << server.status().message() << "\n";
    return 1;
  }
  std::cout << "listening on " << (*server)->address() << std::endl;
  int signal_number = 0;
  sigwait(&signals, &signal_number);
  (*server)->Shutdown();
  return 0;
}
