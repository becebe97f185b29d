#include "cloudcast/client/config.h"

#include <cmath>
#include <cstdint>
#include <string>
#include <string_view>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/draco_codec.h"

namespace cloudcast::client {

absl::Status SetMaxCloudBytes(std::uint64_t max_cloud_bytes, StreamConfig* config,
                              int min_color_bits, std::string_view field) {
  if (max_cloud_bytes != 0 && max_cloud_bytes < kMinCloudBytesCap) {
    return absl::InvalidArgumentError(absl::StrCat(
        std::string(field), " is ", max_cloud_bytes, "; it must be 0 (no cap) or at least ",
        kMinCloudBytesCap, " bytes (a Draco header alone takes about 30)"));
  }
  if (min_color_bits < 0 || min_color_bits > 8) {
    return absl::InvalidArgumentError(
        absl::StrCat("config.draco.min_color_bits is ", min_color_bits,
                     "; it must be in [1, 8] (0: the server's default)"));
  }
  v1::DracoConfig* draco = config->mutable_draco();
  if (max_cloud_bytes == 0) {
    draco->clear_max_cloud_bytes();
  } else {
    draco->set_max_cloud_bytes(max_cloud_bytes);
  }
  if (min_color_bits > 0) draco->set_min_color_bits(min_color_bits);
  return absl::OkStatus();
}

absl::StatusOr<std::uint64_t> MaxCloudBytesFromKb(double kb, std::string_view flag) {
  constexpr double kMinKb = static_cast<double>(kMinCloudBytesCap) / 1000.0;
  // Up to 4 GB: far above any cloud (a reply is bounded by gRPC's message size anyway).
  if (!std::isfinite(kb) || kb < 0 || (kb > 0 && kb < kMinKb) || kb > 4e6) {
    return absl::InvalidArgumentError(absl::StrCat(
        std::string(flag), " is ", kb,
        "; it must be 0 (no cap) or a number of kB (1000 bytes) from ", kMinKb, " to 4000000"));
  }
  return static_cast<std::uint64_t>(std::llround(kb * 1000.0));
}

}  // namespace cloudcast::client
