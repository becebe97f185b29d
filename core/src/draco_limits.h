// What the Draco encoder (draco_codec.cc) and the options' checks (draco_decode.cc) share.
#pragma once

namespace cloudcast::internal {

// Draco's AttributeQuantizationTransform accepts 1..30 position bits.
inline constexpr int kMaxDracoPositionBits = 30;

}  // namespace cloudcast::internal
