#include "speckle.h"

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

namespace cloudcast::stereo {

struct SpeckleFilter::Buffer {
  cv::Mat mat;
};

SpeckleFilter::SpeckleFilter() : buffer_(std::make_unique<Buffer>()) {}
SpeckleFilter::~SpeckleFilter() = default;

void SpeckleFilter::Apply(std::uint16_t* values, int width, int height, int max_size,
                          int max_diff) {
  cv::Mat image(height, width, CV_16SC1, values);
  // newVal 0: our "no match", which the filter also skips as already invalid.
  cv::filterSpeckles(image, 0, max_size, max_diff, buffer_->mat);
}

}  // namespace cloudcast::stereo
