// Our semi-global matcher: the frame-level steps around the kernels (sgm_kernels.h has the
// algorithm): padding and census, the forward and the backward pass row by row (the backward one
// choosing each row's disparities, then OpenCV's left-right check on it), and the speckle filter
// on the frame.
//
// Memory per frame: S1 (width * height * dp bytes: 39 MB at 640x480 with 128 disparities) plus
// about 1 MB of path rows and census planes, kept between frames.
#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>

#include "cloudcast/stereo/budget.h"
#include "matcher_internal.h"
#include "sgm_kernels.h"
#include "speckle.h"

namespace cloudcast::stereo {
namespace {

// Zero-filled bytes aligned to 64 (a cache line, an AVX-512 vector). Grows to what a frame needs
// and gives memory back when a frame needs less than a quarter of it.
class Scratch {
 public:
  // `bytes` usable bytes; true when (re)allocated, zero-filled.
  bool Reserve(std::size_t bytes) {
    if (bytes <= capacity_ && bytes >= capacity_ / 4) return false;
    const std::size_t rounded = (bytes + 63) / 64 * 64;
    data_.reset(
        static_cast<std::uint8_t*>(std::aligned_alloc(64, std::max<std::size_t>(rounded, 64))));
    std::memset(data_.get(), 0, rounded);
    capacity_ = rounded;
    return true;
  }
  std::uint8_t* data() const { return data_.get(); }

 private:
  struct Free {
    void operator()(std::uint8_t* p) const { std::free(p); }
  };
  std::unique_ptr<std::uint8_t, Free> data_;
  std::size_t capacity_ = 0;
};

std::size_t RoundUp(std::size_t v, std::size_t to) { return (v + to - 1) / to * to; }

const sgm::Kernels* KernelsFor(SimdLevel level) {
  switch (level) {
    case SimdLevel::kScalar:
      return &sgm::ScalarKernels();
    case SimdLevel::kAvx2:
      return sgm::Avx2Kernels();
    case SimdLevel::kAvx512:
      return sgm::Avx512Kernels();
    case SimdLevel::kAuto:
      break;
  }
  return KernelsFor(BestSimdLevel());
}

class SgmMatcher final : public Matcher {
 public:
  SgmMatcher(const StereoParams& params, const sgm::Kernels* kernels)
      : params_(params), kernels_(kernels) {
    for (int m = 0; m < 256; ++m) {
      limits_[m] = static_cast<std::int16_t>(sgm::UniquenessLimit(m, params.uniqueness_ratio));
    }
  }

  const StereoParams& params() const override { return params_; }

  absl::Status Compute(const GreyView& left, const GreyView& right, DisparityMap16* out) override {
    if (absl::Status s = CheckPair(left, right); !s.ok()) return s;
    if (absl::Status s = CheckMatchable(params_, left.width, left.height, "stereo"); !s.ok()) {
      return s;
    }
    if (absl::Status s = CheckVolume(left.width, left.height, RoundUpDp(), 1, "the sgm matcher");
        !s.ok()) {
      return s;
    }
    Prepare(static_cast<int>(left.width), static_cast<int>(left.height));
    out->width = left.width;
    out->height = left.height;
    out->values.resize(static_cast<std::size_t>(left.width) * left.height);
    Pad(left, /*mirrored=*/false, padded_left_.data());
    Pad(right, /*mirrored=*/true, padded_right_.data());
    Census(padded_left_.data(), false, left_planes_.data(), 0, left_stride_);
    Census(padded_right_.data(), true, right_planes_.data(), right_origin_, right_stride_);
    ForwardPass();
    BackwardPass(out);
    if (params_.speckle_window_size > 0) {
      speckle_.Apply(out->values.data(), shape_.width, shape_.height, params_.speckle_window_size,
                     16 * params_.speckle_range);
    }
    return absl::OkStatus();
  }

 private:
  int RoundUpDp() const {
    return static_cast<int>(RoundUp(params_.num_disparities, kernels_->lanes));
  }

  // Sizes every buffer for a frame; tables and path-row borders are built when the shape changes.
  void Prepare(int width, int height) {
    const int radius = CensusRadius(params_.block_size);
    sgm::Shape s;
    s.width = width;
    s.height = height;
    s.d = params_.num_disparities;
    s.dp = RoundUpDp();
    s.dmin = params_.min_disparity;
    s.census_bits = sgm::CensusBits(radius);
    s.plane_bits = kernels_->plane_bits;
    s.planes = (s.census_bits + s.plane_bits - 1) / s.plane_bits;
    s.max_cost = static_cast<std::uint8_t>(MaxCensusCost(params_.block_size));
    s.paths = params_.paths / 2;
    s.block = static_cast<std::size_t>(s.paths) * s.dp;
    radius_ = radius;

    // Padded images: radius on each side, room for a 64-byte vector read past the last column.
    padded_stride_ = RoundUp(width + 2 * radius + 64, 64);
    const std::size_t padded = padded_stride_ * (height + 2 * radius) + 64;
    padded_left_.Reserve(padded);
    padded_right_.Reserve(padded);
    // Census planes; the right image's reversed rows (sgm_kernels.h, RowArgs::right) are read
    // from -dmin to width - 1 + dmin + dp - 1: margins on both sides.
    left_stride_ = RoundUp(width, 64);
    right_origin_ = RoundUp(std::max(0, -s.dmin), 64);
    right_stride_ = RoundUp(
        right_origin_ +
            std::max<std::size_t>(RoundUp(width, 64), width + std::max(0, s.dmin) + s.dp) + 64,
        64);
    left_planes_.Reserve(left_stride_ * height * s.planes);
    right_planes_.Reserve(right_stride_ * height * s.planes);
    s1_.Reserve(static_cast<std::size_t>(width) * height * s.dp);
    totals_.Reserve(static_cast<std::size_t>(width) * s.dp);
    const std::size_t row_bytes = 64 + (width + 2) * s.block + 64;
    const bool new_rows = rows_.Reserve(kRows * row_bytes);
    // Minima rows: pixels -1 .. width, and room for the SIMD kernels' rounding (sgm_kernels.h).
    minima_stride_ = RoundUp(width + 2 + sgm::kMinimaLanes, 64);
    const bool new_minima = minima_.Reserve(kRows * 4 * minima_stride_);
    min_vectors_stride_ = RoundUp(width, sgm::kMinimaLanes) * sgm::kMinimaLanes;
    min_vectors_.Reserve(3 * min_vectors_stride_);
    const bool same = s.width == shape_.width && s.d == shape_.d && s.dp == shape_.dp &&
                      s.dmin == shape_.dmin && s.planes == shape_.planes && s.paths == shape_.paths;
    shape_ = s;
    disparity_.resize(width);
    parabola_.resize(width);
    right_disparity_.resize(width + 1);
    right_cost_.resize(width + 1);
    if (same && !new_rows && !new_minima) return;

    // Floors (sgm_kernels.h): pad, left, right, and the twins of left and right for the totals.
    floor_table_.assign(9 * s.dp, 0);
    std::uint8_t* pad = floor_table_.data();
    std::uint8_t* left = pad + s.dp;
    std::uint8_t* right = left + 2 * s.dp;
    const std::ptrdiff_t twins = 4 * s.dp;
    for (int k = s.d; k < s.dp; ++k) pad[k] = 255;
    for (int i = s.dp; i < 2 * s.dp; ++i) {
      left[i] = s.max_cost;
      left[i + twins] = sgm::kMaskedTotal;
    }
    for (int i = 0; i < s.dp; ++i) {
      right[i] = s.max_cost;
      right[i + twins] = sgm::kMaskedTotal;
    }
    floors_ = {s.dp > s.d ? pad : nullptr, left, right, twins};

    // Path rows (sgm_kernels.h): padding 255, pixels -1 and width zero predecessors; the zero
    // row (every pixel a zero predecessor) is what the first row of a pass comes from.
    std::memset(rows_.data(), 255, kRows * row_bytes);
    std::memset(minima_.data(), 0, kRows * 4 * minima_stride_);
    for (int r = 0; r < kRows; ++r) {
      path_rows_[r].costs = rows_.data() + r * row_bytes + 64 + s.block;
      for (int j = 0; j < 4; ++j) {
        path_rows_[r].minima[j] = minima_.data() + (r * 4 + j) * minima_stride_ + 1;
      }
      for (int x = -1; x <= width; ++x) {
        if (r != kZeroRow && x != -1 && x != width) continue;
        for (int j = 0; j < s.paths; ++j) {
          std::memset(path_rows_[r].costs + x * static_cast<std::ptrdiff_t>(s.block) + j * s.dp, 0,
                      s.d);
        }
      }
    }
  }

  // Biased (value ^ 0x80), border-replicated copy of a view, mirrored left to right for the right
  // image (sgm_kernels.h, CensusArgs).
  void Pad(const GreyView& view, bool mirrored, std::uint8_t* padded) const {
    const int w = shape_.width, h = shape_.height, r = radius_;
    for (int y = -r; y < h + r; ++y) {
      const std::uint8_t* src = view.row(static_cast<std::uint32_t>(std::clamp(y, 0, h - 1)));
      std::uint8_t* dst = padded + (y + r) * padded_stride_ + r;
      if (mirrored) {
        for (int x = 0; x < w; ++x) dst[x] = src[w - 1 - x] ^ 0x80;
      } else {
        for (int x = 0; x < w; ++x) dst[x] = src[x] ^ 0x80;
      }
      for (int x = 1; x <= r; ++x) {
        dst[-x] = dst[0];
        dst[w - 1 + x] = dst[w - 1];
      }
    }
  }

  void Census(const std::uint8_t* padded, bool mirrored, std::uint8_t* planes, std::size_t origin,
              std::size_t stride) const {
    sgm::CensusArgs a;
    a.padded = reinterpret_cast<const std::int8_t*>(padded);
    a.stride = padded_stride_;
    a.width = shape_.width;
    a.height = shape_.height;
    a.radius = radius_;
    a.mirrored = mirrored;
    a.plane_bits = shape_.plane_bits;
    for (int j = 0; j < shape_.planes; ++j)
      a.planes[j] = planes + j * stride * shape_.height + origin;
    a.plane_stride = stride;
    kernels_->census(a);
  }

  sgm::RowArgs RowArgsFor(int y) const {
    sgm::RowArgs a;
    a.shape = &shape_;
    a.floors = floors_;
    a.p1 = static_cast<std::uint8_t>(params_.EffectiveP1());
    a.p2 = static_cast<std::uint8_t>(params_.EffectiveP2());
    a.paths = shape_.paths;
    for (int j = 0; j < shape_.planes; ++j) {
      a.left[j] = left_planes_.data() + (j * shape_.height + y) * left_stride_;
      a.right[j] = right_planes_.data() + (j * shape_.height + y) * right_stride_ + right_origin_;
    }
    a.min_vectors = min_vectors_.data();
    a.min_vectors_stride = min_vectors_stride_;
    a.s1 = s1_.data() + static_cast<std::size_t>(y) * shape_.width * shape_.dp;
    return a;
  }

  // Path rows 0 and 1 take turns as the previous row and this one.
  void ForwardPass() {
    for (int y = 0; y < shape_.height; ++y) {
      sgm::RowArgs a = RowArgsFor(y);
      a.prev = y == 0 ? path_rows_[kZeroRow] : path_rows_[(y + 1) % 2];
      a.cur = path_rows_[y % 2];
      kernels_->forward_row(a);
    }
  }

  void BackwardPass(DisparityMap16* out) {
    for (int y = shape_.height - 1; y >= 0; --y) {
      sgm::RowArgs a = RowArgsFor(y);
      a.prev = y == shape_.height - 1 ? path_rows_[kZeroRow] : path_rows_[(y + 1) % 2];
      a.cur = path_rows_[y % 2];
      a.totals = totals_.data();
      std::fill(right_disparity_.begin(), right_disparity_.end(), sgm::kNoMatch);
      std::fill(right_cost_.begin(), right_cost_.end(), INT32_MAX);
      a.choice.limits = limits_;
      a.choice.disparity = disparity_.data();
      a.choice.parabola = parabola_.data();
      a.choice.right_disparity = right_disparity_.data();
      a.choice.right_cost = right_cost_.data();
      kernels_->backward_row(a);
      sgm::CheckArgs check;
      check.disparity = disparity_.data();
      check.parabola = parabola_.data();
      check.right_disparity = right_disparity_.data();
      check.width = shape_.width;
      check.tolerance = params_.disp12_max_diff;
      check.out = out->values.data() + static_cast<std::size_t>(y) * shape_.width;
      kernels_->check_row(check);
    }
  }

  static constexpr int kZeroRow = 2;
  static constexpr int kRows = 3;

  const StereoParams params_;
  const sgm::Kernels* const kernels_;
  sgm::Shape shape_;
  int radius_ = 0;
  std::size_t padded_stride_ = 0, left_stride_ = 0, right_stride_ = 0, right_origin_ = 0;
  Scratch padded_left_, padded_right_, left_planes_, right_planes_, s1_, totals_, rows_, minima_,
      min_vectors_;
  std::size_t minima_stride_ = 0, min_vectors_stride_ = 0;
  sgm::PathRow path_rows_[kRows];
  std::vector<std::uint8_t> floor_table_;
  sgm::Floors floors_;
  std::int16_t limits_[256];
  std::vector<std::int32_t> disparity_, right_disparity_, right_cost_;
  std::vector<std::uint32_t> parabola_;
  SpeckleFilter speckle_;
};

}  // namespace

std::unique_ptr<Matcher> MakeSgmMatcher(const StereoParams& params, SimdLevel level) {
  return std::make_unique<SgmMatcher>(params, KernelsFor(level));
}

}  // namespace cloudcast::stereo
