// Stream configuration. The protocol's StreamConfig is used as it is (every field optional: unset
// fields take the server's defaults, see Client::GetInfo); these helpers fill it from the core
// structs, so a client can state the exact parameters it would give core::Pipeline. They are the
// proto boundary's own (cloudcast/proto/convert.h), named here for the client's users.
#pragma once

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

}  // namespace cloudcast::client
