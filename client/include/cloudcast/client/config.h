// Stream configuration. The protocol's StreamConfig is used as it is (every field optional: unset
// fields take the server's defaults, see Client::GetInfo); these helpers fill it from the core
// structs, so a client can state the exact parameters it would give core::Pipeline. They are the
// proto boundary's own (cloudcast/proto/convert.h), named here for the client's users.
#pragma once

#include <cstdint>
#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/proto/convert.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace cloudcast::client {

using StreamConfig = ::cloudcast::v1::StreamConfig;

// Each sets every field of its section (cx and cy included, so the principal point is the
// struct's, not the image centre), leaving the other sections alone.
using convert::SetCamera;
using convert::SetPassThrough;
using convert::SetVoxelGrid;
// max_position_error 0 (the DracoOptions default) stays unset: the server then uses a quarter of
// the voxel leaf, as the core pipeline does.
using convert::SetDraco;
// The stereo matcher's settings (StreamConfig.stereo) for frames that are stereo pairs.
using convert::SetStereo;
// A named preset's camera and passthrough, e.g. PresetConfig("new_tsukuba"), the paper's: the
// server assumes no camera, so a client states its own or a preset's.
using convert::PresetConfig;
// Camera, passthrough and voxel grid of `options` (its limits are the server's business).
// Draco and delivery stay at the server defaults.
using convert::MakeStreamConfig;

// The downlink cap (contract revision 4, DracoConfig.max_cloud_bytes): each reply's Draco cloud
// at most `max_cloud_bytes` bytes, the server quantizing positions down to the error bound and
// colours down to `min_color_bits` (0: the server's default, 5) to meet it. A cloud it cannot
// bring under the cap still comes back, with CloudReply.over_cap saying so;
// CloudReply.position_bits and color_bits say what the server chose. 0 removes the cap. Refuses
// (INVALID_ARGUMENT naming `field`) a cap from 1 to 63 bytes (a Draco header alone takes about
// 30) and min_color_bits above 8 or below 0.
absl::Status SetMaxCloudBytes(std::uint64_t max_cloud_bytes, StreamConfig* config,
                              int min_color_bits = 0,
                              std::string_view field = "config.draco.max_cloud_bytes");

// A cap given in kB (1 kB = 1000 bytes) as programs take it (--max-reply-kb), in bytes: 0 is no
// cap; otherwise a finite number of at least 0.064 (64 bytes). Errors name `flag`.
absl::StatusOr<std::uint64_t> MaxCloudBytesFromKb(double kb, std::string_view flag);

}  // namespace cloudcast::client
