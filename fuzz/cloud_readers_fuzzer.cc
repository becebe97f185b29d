// The PCD / PLY / DRC readers (io/cloud_io: LoadCloud, which checks headers itself before PCL's
// readers, or Draco's, see them). LoadCloud reads a path, so each input is written to a file in
// a folder of this process's own (in /dev/shm when there is one).
//   byte 0 % 3: 0 .pcd, 1 .ply, 2 .drc; the rest is the file.
#include <unistd.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "cloudcast/io/cloud_io.h"

using namespace cloudcast;

namespace {

std::string& Folder() {
  static std::string folder;
  return folder;
}

void RemoveFolder() {
  std::error_code ec;
  std::filesystem::remove_all(Folder(), ec);
}

const std::string& MakeFolder() {
  std::filesystem::path base = std::filesystem::exists("/dev/shm") ? "/dev/shm" : "/tmp";
  base /= "cloudcast-fuzz-" + std::to_string(getpid());
  std::filesystem::create_directories(base);
  Folder() = base.string();
  std::atexit(RemoveFolder);
  return Folder();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string* folder = &MakeFolder();
  static PointCloud* cloud = new PointCloud;
  if (size < 1) return 0;
  static const char* const kExtensions[] = {".pcd", ".ply", ".drc"};
  const std::string path = *folder + "/input" + kExtensions[data[0] % 3];
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) std::abort();
  if (size > 1 && std::fwrite(data + 1, 1, size - 1, f) != size - 1) std::abort();
  std::fclose(f);
  if (LoadCloud(path, cloud).ok() &&
      cloud->size() != std::size_t{cloud->width} * std::max<std::uint32_t>(cloud->height, 1)) {
    std::fprintf(stderr, "LoadCloud gave %zu points for %u x %u\n", cloud->size(), cloud->width,
                 cloud->height);
    std::abort();
  }
  return 0;
}
