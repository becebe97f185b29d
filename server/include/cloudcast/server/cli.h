// cloudcast-server's command line: every ServerOptions field as a flag with its default shown in
// --help, plus --config for a TOML or INI file holding the same flags.
#pragma once

#include <CLI/CLI.hpp>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "cloudcast/cli/stage_flags.h"
#include "cloudcast/server/options.h"

namespace cloudcast::server {

class ServerFlags {
 public:
  // Registers the flags on `app`, which must outlive this object.
  explicit ServerFlags(CLI::App& app);

  // The options the parsed flags describe, validated. Call after app.parse().
  absl::StatusOr<ServerOptions> Options() const;
  const std::string& log_level() const { return log_level_; }
  // --ready-file: where to write the bound addresses once serving; empty: nowhere.
  const std::string& ready_file() const { return ready_file_; }

 private:
  ServerOptions options_;
  double idle_timeout_seconds_;
  double first_message_timeout_seconds_;
  std::uint64_t memory_budget_mb_;
  std::uint64_t work_memory_mb_;
  double shed_quiet_after_seconds_;
  double refusal_delay_seconds_;
  std::uint64_t transport_memory_mb_ = 0;
  std::uint64_t reading_mb_per_client_ = 0;
  double shutdown_grace_seconds_;
  double max_connection_age_seconds_ = 0;
  double max_connection_age_grace_seconds_ = 0;
  double ping_after_seconds_ = -1;
  double ping_timeout_seconds_ = 1;
  std::string delivery_;
  bool no_reflection_ = false;
  std::unique_ptr<cli::StageFlags> stages_;  // after the service flags in --help
  std::string log_level_ = "info";
  std::string ready_file_;
};

}  // namespace cloudcast::server
