#include "cloudcast/load/frame_log.h"

#include <cstdio>
#include <utility>

#include "absl/strings/str_cat.h"

namespace cloudcast::load {

namespace {
constexpr char kHeader[] =
    "stream,sequence,intended_unix_ns,written_unix_ns,server_receive_unix_ns,"
    "server_send_unix_ns,received_unix_ns,latency_ms,image_bytes,reply_bytes,points,"
    "position_bits,over_cap,queue_us,decode_us,rectify_us,match_us,pipeline_us,encode_us,"
    "reply_cap_bytes,instance\n";
}  // namespace

absl::StatusOr<std::unique_ptr<FrameLog>> FrameLog::Open(const std::string& path,
                                                         const std::string& flag) {
  std::unique_ptr<FrameLog> log(new FrameLog(path, flag));
  log->out_.open(path, std::ios::out | std::ios::trunc);
  if (!log->out_) {
    return absl::InvalidArgumentError(absl::StrCat(flag, ": cannot create ", path));
  }
  log->out_ << kHeader;
  return log;
}

void FrameLog::Add(const FrameLogRow& r) {
  // The latency the report counts: from the intended send time to the reply.
  char latency[32];
  std::snprintf(latency, sizeof(latency), "%.3f",
                static_cast<double>(r.received_unix_ns - r.intended_unix_ns) / 1e6);
  // An instance name is the server's --instance or its host name: no commas or quotes to escape
  // in practice, but a name with either is quoted as CSV has it.
  std::string quoted;
  if (r.instance.find_first_of(",\"\n") != std::string::npos) {
    quoted = "\"";
    for (const char c : r.instance) quoted += c == '"' ? std::string("\"\"") : std::string(1, c);
    quoted += "\"";
  }
  const std::string& instance = quoted.empty() ? r.instance : quoted;
  const std::string line = absl::StrCat(
      r.stream, ",", r.sequence, ",", r.intended_unix_ns, ",", r.written_unix_ns, ",",
      r.server_receive_unix_ns, ",", r.server_send_unix_ns, ",", r.received_unix_ns, ",", latency,
      ",", r.image_bytes, ",", r.reply_bytes, ",", r.points, ",", r.position_bits, ",",
      r.over_cap ? 1 : 0, ",", r.queue_us, ",", r.decode_us, ",", r.rectify_us, ",", r.match_us,
      ",", r.pipeline_us, ",", r.encode_us, ",", r.reply_cap_bytes, ",", instance, "\n");
  std::lock_guard<std::mutex> lock(mu_);
  out_ << line;
}

absl::Status FrameLog::Close() {
  std::lock_guard<std::mutex> lock(mu_);
  out_.flush();
  const bool ok = static_cast<bool>(out_);
  out_.close();
  if (!ok) return absl::DataLossError(absl::StrCat(flag_, ": writing ", path_, " failed"));
  return absl::OkStatus();
}

}  // namespace cloudcast::load
