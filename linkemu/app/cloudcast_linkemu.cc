// cloudcast-linkemu: an emulated network link between a server namespace and its clients, for
// tests and benchmarks. See docs/links.md.
#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <string>

#include "CLI/CLI.hpp"
#include "cloudcast/linkemu/link_spec.h"
#include "nfqueue_relay.h"
#include "topology.h"

namespace {

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop.store(true); }

void AddDirectionFlags(CLI::App& app, const std::string& prefix, const std::string& which,
                       const std::string& group, cloudcast::linkemu::DirectionSpec* spec) {
  const std::string p = prefix.empty() ? "--" : "--" + prefix + "-";
  app.add_option(p + "rate", spec->rate,
                 "Link rate " + which +
                     ": 10mbit, 500kbit, 1gbit (bits per second of IP "
                     "packets); none: no rate limit")
      ->group(group);
  app.add_option(p + "schedule", spec->schedule,
                 "Rate changes " + which +
                     ", from the ready line: 'TIME=RATE,...' (e.g. "
                     "'5s=3mbit,10s=10mbit'; RATE 'down' = 0, packets wait), or @FILE with one "
                     "entry a line; --rate is the rate before the first")
      ->group(group);
  app.add_option(p + "trace", spec->trace,
                 "A Mahimahi packet-delivery trace " + which +
                     " (one time in ms a line, each a 1504-byte delivery opportunity; it "
                     "repeats) instead of --rate")
      ->group(group)
      ->check(CLI::ExistingFile);
  app.add_option(p + "outage", spec->outages,
                 "AT:LENGTH, e.g. 5s:300ms: the link carries nothing " + which +
                     " for LENGTH from AT (packets wait in the queue); repeatable")
      ->group(group);
  app.add_option(p + "delay", spec->delay, "One-way delay " + which + " (e.g. 20ms)")->group(group);
  app.add_option(p + "jitter", spec->jitter,
                 "Standard deviation of a normal variation of the delay " + which +
                     " (clamped at 0; packets are never reordered)")
      ->group(group);
  app.add_option(p + "loss", spec->loss, "Random packet loss " + which + ": 0.1% or 0.001")
      ->group(group);
  app.add_option(p + "burst-loss", spec->burst_loss,
                 "Gilbert-Elliott burst loss " + which +
                     ": p=GOOD_TO_BAD,r=BAD_TO_GOOD[,bad=LOSS][,good=LOSS], per packet (e.g. "
                     "p=1%,r=25%: bursts of 4 on average, 3.8% lost)")
      ->group(group);
  app.add_option(p + "queue", spec->queue,
                 "Drop-tail queue bound " + which +
                     " before the link: bytes (150kB, 64KiB) or packets (100p); default 200 ms "
                     "at the first rate, at least 15 kB")
      ->group(group);
}

}  // namespace

int main(int argc, char** argv) {
  namespace le = cloudcast::linkemu;
  CLI::App app{
      "cloudcast-linkemu: an emulated network link for tests and benchmarks. Makes a server "
      "network namespace and a router namespace (this process) between it and the clients (the "
      "host's namespace, or --client-netns), shapes both directions in userspace through "
      "NFQUEUE (rate, queue, delay, jitter, loss, schedules, Mahimahi traces), prints one JSON "
      "'ready' line on stdout (names and addresses), and on SIGTERM/SIGINT or after --timeout "
      "removes everything it made and prints a JSON 'stats' line. Needs root. Up = client to "
      "server, down = server to client; the plain flags set both directions, --up-*/--down-* "
      "one."};
  le::DirectionSpec both, up, down;
  AddDirectionFlags(app, "", "(both directions)", "Link (both directions)", &both);
  AddDirectionFlags(app, "up", "from client to server", "Uplink (client to server)", &up);
  AddDirectionFlags(app, "down", "from server to client", "Downlink (server to client)", &down);
  bool client_netns = false;
  std::string congestion_control;
  double timeout = 600;
  std::uint64_t seed = 1;
  std::uint16_t first_queue = 0;
  std::string ready_file, stats_file;
  app.add_flag("--client-netns", client_netns,
               "Put the clients' end in a namespace of its own (named in the ready line) instead "
               "of the host's, so that --cc sets the clients' congestion control too")
      ->group("Network");
  app.add_option("--cc", congestion_control,
                 "TCP congestion control set in the namespaces made here (cubic, bbr, reno); "
                 "default: the kernel's. The host's own is never changed: without "
                 "--client-netns the clients keep it (the ready line says which each end uses)")
      ->group("Network");
  app.add_option("--queue-num", first_queue,
                 "NFQUEUE numbers used in the router namespace: N (up) and N+1 (down)")
      ->group("Network");
  app.add_option("--timeout", timeout,
                 "Seconds after which the emulator removes everything and exits, whatever "
                 "happens (every run is bounded)")
      ->check(CLI::Range(0.1, 86400.0))
      ->group("Run");
  app.add_option("--seed", seed, "Seed of the loss and jitter draws (down uses seed + 1)")
      ->group("Run");
  app.add_option("--ready-file", ready_file, "Also write the ready line to this file")
      ->group("Run");
  app.add_option("--stats-file", stats_file, "Also write the stats line to this file")
      ->group("Run");
  CLI11_PARSE(app, argc, argv);

  absl::StatusOr<le::BuiltDirection> built_up =
      le::BuildDirection("up", both.OverriddenBy(up), seed);
  if (!built_up.ok()) {
    std::cerr << "cloudcast-linkemu: " << built_up.status().message() << "\n";
    return 2;
  }
  absl::StatusOr<le::BuiltDirection> built_down =
      le::BuildDirection("down", both.OverriddenBy(down), seed + 1);
  if (!built_down.ok()) {
    std::cerr << "cloudcast-linkemu: " << built_down.status().message() << "\n";
    return 2;
  }
  if (!congestion_control.empty() && congestion_control != "cubic" && congestion_control != "bbr" &&
      congestion_control != "reno") {
    std::cerr << "cloudcast-linkemu: --cc: '" << congestion_control
              << "' is not one of cubic, bbr, reno\n";
    return 2;
  }

  struct sigaction action {};
  action.sa_handler = OnSignal;  // no SA_RESTART: ppoll returns and the loop sees the flag
  sigaction(SIGTERM, &action, nullptr);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGHUP, &action, nullptr);
  signal(SIGPIPE, SIG_IGN);

  le::TopologyOptions topology_options;
  topology_options.client_namespace = client_netns;
  topology_options.congestion_control = congestion_control;
  topology_options.first_queue = first_queue;
  absl::StatusOr<std::unique_ptr<le::Topology>> topology = le::Topology::Create(topology_options);
  if (!topology.ok()) {
    std::cerr << "cloudcast-linkemu: " << topology.status().message() << "\n";
    return 1;
  }
  absl::StatusOr<std::unique_ptr<le::NfqueueRelay>> relay =
      le::NfqueueRelay::Open(built_up->link.get(), built_down->link.get(), first_queue);
  if (!relay.ok()) {
    std::cerr << "cloudcast-linkemu: " << relay.status().message() << "\n";
    return 1;
  }
  const le::TopologyInfo& info = (*topology)->info();
  const nlohmann::json ready = {
      {"event", "ready"},
      {"server_netns", info.server_netns},
      {"server_ip", info.server_ip},
      {"client_netns", info.client_netns},
      {"client_ip", info.client_ip},
      {"congestion_control",
       {{"server", info.server_congestion_control}, {"client", info.client_congestion_control}}},
      {"up", built_up->description},
      {"down", built_down->description},
      {"timeout_s", timeout},
      {"pid", getpid()}};
  std::cout << ready.dump() << std::endl;
  if (!ready_file.empty()) std::ofstream(ready_file) << ready.dump() << "\n";

  const auto started = std::chrono::steady_clock::now();
  const absl::Status run =
      (*relay)->Run(g_stop, static_cast<le::Nanos>(timeout * static_cast<double>(le::kSecond)));
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  const nlohmann::json stats = {{"event", "stats"},
                                {"seconds", seconds},
                                {"ended_by", g_stop.load() ? "signal" : "timeout"},
                                {"up", le::StatsJson(built_up->link->stats())},
                                {"down", le::StatsJson(built_down->link->stats())},
                                {"netlink_overruns", (*relay)->overruns()},
                                {"held_at_exit", (*relay)->held()}};
  relay->reset();     // the kernel drops what is still held
  topology->reset();  // the named namespaces; the router's goes with this process
  std::cout << stats.dump() << std::endl;
  if (!stats_file.empty()) std::ofstream(stats_file) << stats.dump() << "\n";
  if (!run.ok()) {
    std::cerr << "cloudcast-linkemu: " << run.message() << "\n";
    return 1;
  }
  return 0;
}
