#include "cloudcast/datasets/tsukuba.h"

#include <cstdlib>
#include <filesystem>

namespace cloudcast::tsukuba {

const std::vector<std::string>& FrameIds() {
  static const std::vector<std::string> ids = {"00001", "00200", "00400", "00600", "00800",
                                               "01000", "01200", "01400", "01600", "01800"};
  return ids;
}

std::string DefaultDir() {
  if (const char* env = std::getenv("CLOUDCAST_DATA"); env != nullptr && *env != '\0') return env;
  return CLOUDCAST_DEFAULT_DATA_DIR;
}

std::string DisparityPath(const std::string& dir, const std::string& id) {
  return dir + "/groundtruth/disparity_maps/left/tsukuba_disparity_L_" + id + ".png";
}

std::string ColourPath(const std::string& dir, const std::string& id) {
  return dir + "/illumination/daylight/left/tsukuba_daylight_L_" + id + ".png";
}

std::string RightColourPath(const std::string& dir, const std::string& id) {
  return dir + "/illumination/daylight/right/tsukuba_daylight_R_" + id + ".png";
}

bool Present(const std::string& dir) {
  return std::filesystem::exists(DisparityPath(dir, "00001")) &&
         std::filesystem::exists(ColourPath(dir, "00001"));
}

absl::StatusOr<Frame> Load(const std::string& dir, const std::string& id) {
  auto disparity = LoadDisparity(DisparityPath(dir, id));
  if (!disparity.ok()) return disparity.status();
  auto colour = LoadColor(ColourPath(dir, id));
  if (!colour.ok()) return colour.status();
  return Frame{id, *std::move(disparity), *std::move(colour)};
}

absl::StatusOr<std::vector<Frame>> LoadAll(const std::string& dir) {
  std::vector<Frame> frames;
  for (const std::string& id : FrameIds()) {
    if (!std::filesystem::exists(DisparityPath(dir, id))) continue;
    auto frame = Load(dir, id);
    if (!frame.ok()) return frame.status();
    frames.push_back(*std::move(frame));
  }
  if (frames.empty()) {
    return absl::NotFoundError("no New Tsukuba frames under " + dir +
                               " (expected groundtruth/ and illumination/; set CLOUDCAST_DATA)");
  }
  return frames;
}

absl::StatusOr<StereoFrame> LoadStereo(const std::string& dir, const std::string& id) {
  auto left = LoadColor(ColourPath(dir, id));
  if (!left.ok()) return left.status();
  auto right = LoadColor(RightColourPath(dir, id));
  if (!right.ok()) return right.status();
  auto truth = LoadDisparity(DisparityPath(dir, id));
  if (!truth.ok()) return truth.status();
  return StereoFrame{id, *std::move(left), *std::move(right), *std::move(truth)};
}

absl::StatusOr<std::vector<StereoFrame>> LoadAllStereo(const std::string& dir) {
  std::vector<StereoFrame> frames;
  for (const std::string& id : FrameIds()) {
    if (!std::filesystem::exists(RightColourPath(dir, id))) continue;
    auto frame = LoadStereo(dir, id);
    if (!frame.ok()) return frame.status();
    frames.push_back(*std::move(frame));
  }
  if (frames.empty()) {
    return absl::NotFoundError("no New Tsukuba stereo pairs under " + dir +
                               " (expected illumination/daylight/right/; set CLOUDCAST_DATA)");
  }
  return frames;
}

}  // namespace cloudcast::tsukuba
