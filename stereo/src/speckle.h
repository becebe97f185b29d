// The speckle filter our matcher ends with: cv::filterSpeckles (OpenCV inside speckle.cc only, so
// the matcher's own files stay free of OpenCV headers).
#pragma once

#include <cstdint>
#include <memory>

namespace cloudcast::stereo {

class SpeckleFilter {
 public:
  SpeckleFilter();
  ~SpeckleFilter();
  SpeckleFilter(const SpeckleFilter&) = delete;
  SpeckleFilter& operator=(const SpeckleFilter&) = delete;

  // Sets to 0 every 4-connected region of non-zero values (neighbours within max_diff of each
  // other) of at most max_size pixels. Values must be <= 32767 (they are read as int16).
  void Apply(std::uint16_t* values, int width, int height, int max_size, int max_diff);

 private:
  struct Buffer;
  std::unique_ptr<Buffer> buffer_;  // cv::filterSpeckles' scratch, kept between frames
};

}  // namespace cloudcast::stereo
