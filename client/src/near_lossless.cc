#include "cloudcast/client/near_lossless.h"

#include <variant>

namespace cloudcast::client {
namespace {

// The quantized form of one geometry input: View is DisparityView or DepthView, Compressed its
// Compressed*View.
template <typename Compressed, typename View, typename Input>
absl::StatusOr<Input> Quantized(const Input& input, const char* field, const CameraModel& camera,
                                double bound, PointErrorQuantizer* quantizer) {
  const View* view = std::get_if<View>(&input);
  const Compressed* compressed = std::get_if<Compressed>(&input);
  if (view == nullptr && compressed == nullptr) {
    return absl::InvalidArgumentError(
        std::string(field) +
        " is an encoded file or a precompressed message; near-lossless needs its raw pixels (a "
        "view, or a Compressed view)");
  }
  View out;
  if (absl::Status s = quantizer->Quantize(view != nullptr ? *view : compressed->view, camera,
                                           bound, field, &out);
      !s.ok()) {
    return s;
  }
  if (view != nullptr) return Input(out);
  return Input(Compressed{out, compressed->compression});
}

}  // namespace

absl::StatusOr<FrameInput> NearLossless(const FrameInput& input, const CameraModel& camera,
                                        double max_point_error, PointErrorQuantizer* quantizer) {
  if (const auto* f = std::get_if<DisparityFrame>(&input)) {
    auto d = Quantized<CompressedDisparityView, DisparityView>(f->disparity, "disparity", camera,
                                                               max_point_error, quantizer);
    if (!d.ok()) return d.status();
    return FrameInput(DisparityFrame{*std::move(d), f->colour});
  }
  if (const auto* f = std::get_if<DepthFrame>(&input)) {
    auto d = Quantized<CompressedDepthView, DepthView>(f->depth, "depth", camera, max_point_error,
                                                       quantizer);
    if (!d.ok()) return d.status();
    return FrameInput(DepthFrame{*std::move(d), f->colour});
  }
  return input;  // a stereo pair: the server matches it
}

}  // namespace cloudcast::client
