// The New Tsukuba Stereo Dataset sample (../shared/data/new_tsukuba): where its frames are and
// how to load them. The data is read in place; its terms forbid copying it into the repository.
#pragma once

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "cloudcast/datasets/stereo_frame.h"
#include "cloudcast/io/image_io.h"

namespace cloudcast::tsukuba {

// The ten frames of the sample: 00001, 00200, ..., 01800.
const std::vector<std::string>& FrameIds();

// $CLOUDCAST_DATA if set, else the folder next to the checkout chosen at build time.
std::string DefaultDir();

// The left disparity map and the left (daylight) colour image of frame `id` under `dir`.
std::string DisparityPath(const std::string& dir, const std::string& id);
std::string ColourPath(const std::string& dir, const std::string& id);
// The right (daylight) colour image of frame `id`: rectified with the left one, for matching.
std::string RightColourPath(const std::string& dir, const std::string& id);

// True when frame 00001 is there.
bool Present(const std::string& dir);

// One frame: 8-bit disparity (value = disparity in pixels, 0 = invalid), BGR8 colour (the PNGs
// are RGBA; alpha is dropped).
struct Frame {
  std::string id;
  OwnedDisparity disparity;
  OwnedColor colour;
};
absl::StatusOr<Frame> Load(const std::string& dir, const std::string& id);
// Every frame present under `dir` (NotFound when there is none).
absl::StatusOr<std::vector<Frame>> LoadAll(const std::string& dir);

// One stereo pair: both colour images and the left ground truth (which reads about 1 px low:
// docs/stereo.md).
absl::StatusOr<StereoFrame> LoadStereo(const std::string& dir, const std::string& id);
// Every pair present under `dir` (NotFound when there is none).
absl::StatusOr<std::vector<StereoFrame>> LoadAllStereo(const std::string& dir);

}  // namespace cloudcast::tsukuba
