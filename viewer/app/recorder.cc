#include "app/recorder.h"

#include <cstdio>
#include <filesystem>
#include <fstream>

#include "absl/strings/str_cat.h"
#include "cloudcast/io/cloud_io.h"

namespace cloudcast::client::app {

absl::StatusOr<Recorder> Recorder::Create(const std::string& dir, const std::string& format) {
  if (format != "pcd" && format != "ply" && format != "drc") {
    return absl::InvalidArgumentError(
        absl::StrCat("--record-format must be pcd, ply or drc, got '", format, "'"));
  }
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec || !std::filesystem::is_directory(dir)) {
    return absl::InvalidArgumentError(
        absl::StrCat("--record ", dir, ": cannot create the folder (",
                     ec ? ec.message() : std::string("a file of that name exists"), ")"));
  }
  return Recorder(dir, format);
}

std::string Recorder::PathFor(std::uint64_t sequence) const {
  char name[64];
  std::snprintf(name, sizeof(name), "cloud_%06llu.", static_cast<unsigned long long>(sequence));
  return (std::filesystem::path(dir_) / (name + format_)).string();
}

absl::Status Recorder::Save(const Result& result) {
  if (!result.ok()) return absl::OkStatus();
  const std::string path = PathFor(result.sequence);
  if (format_ == "drc") {
    std::ofstream file(path, std::ios::binary | std::ios::trunc);
    file.write(result.reply.draco().data(),
               static_cast<std::streamsize>(result.reply.draco().size()));
    file.close();
    if (!file) return absl::InternalError(absl::StrCat("--record: cannot write ", path));
  } else {
    absl::Status s = SaveCloud(path, result.cloud);
    if (!s.ok()) return absl::Status(s.code(), absl::StrCat("--record: ", s.message()));
  }
  ++files_written_;
  return absl::OkStatus();
}

}  // namespace cloudcast::client::app
