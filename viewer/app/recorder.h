// --record: every received cloud saved as a file, named by the frame's sequence number.
#pragma once

#include <cstdint>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/client/result.h"

namespace cloudcast::client::app {

class Recorder {
 public:
  // `format`: "pcd", "ply" or "drc". Creates `dir` when missing. Errors name --record.
  static absl::StatusOr<Recorder> Create(const std::string& dir, const std::string& format);

  // Writes `result`'s cloud to DIR/cloud_<sequence, 6 digits>.<format>. DRC files are the reply's
  // Draco bytes as received (no re-encoding, so they are exactly what the server sent); PCD and
  // PLY go through cloud_io (PCL's writers). Results without a cloud are skipped.
  absl::Status Save(const Result& result);

  std::uint64_t files_written() const { return files_written_; }
  const std::string& dir() const { return dir_; }
  const std::string& format() const { return format_; }
  // The path Save uses for `sequence`.
  std::string PathFor(std::uint64_t sequence) const;

 private:
  Recorder(std::string dir, std::string format)
      : dir_(std::move(dir)), format_(std::move(format)) {}
  std::string dir_, format_;
  std::uint64_t files_written_ = 0;
};

}  // namespace cloudcast::client::app
