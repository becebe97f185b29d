// The engine's options as a client states them: axis names, and the checks that name the field
// at fault. Plain C++ with no kernels, so the client library gets them on any architecture
// (cloudcast_core_portable) without the SIMD stages in filters.cc and pipeline.cc.
#include <string>
#include <string_view>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/checks.h"
#include "cloudcast/core/filters.h"
#include "cloudcast/core/pipeline.h"

namespace cloudcast {

std::string_view Name(Axis axis) {
  switch (axis) {
    case Axis::kX:
      return "x";
    case Axis::kY:
      return "y";
    case Axis::kZ:
      return "z";
  }
  return "?";
}

bool ParseAxis(std::string_view name, Axis* out) {
  for (auto a : {Axis::kX, Axis::kY, Axis::kZ}) {
    if (Name(a) == name) {
      *out = a;
      return true;
    }
  }
  return false;
}

absl::Status PassThroughParams::Validate(std::string_view field) const {
  if (!enabled) return absl::OkStatus();
  const std::string f(field);
  if (axis != Axis::kX && axis != Axis::kY && axis != Axis::kZ) {
    return absl::InvalidArgumentError(
        absl::StrCat(f, ".axis must be x, y or z, got ", static_cast<int>(axis)));
  }
  for (absl::Status s : {check::FiniteFloat(f + ".min", min), check::FiniteFloat(f + ".max", max),
                         check::Ordered(f + ".min", min, f + ".max", max)}) {
    if (!s.ok()) return s;
  }
  return absl::OkStatus();
}

absl::Status VoxelGridParams::Validate(std::string_view field) const {
  if (!enabled) return absl::OkStatus();
  const std::string f(field);
  for (absl::Status s : {check::Leaf(f + ".leaf_x", leaf_x), check::Leaf(f + ".leaf_y", leaf_y),
                         check::Leaf(f + ".leaf_z", leaf_z)}) {
    if (!s.ok()) return s;
  }
  return absl::OkStatus();
}

absl::Status PipelineOptions::Validate(std::string_view field) const {
  const std::string prefix = field.empty() ? "" : std::string(field) + ".";
  if (auto s = camera.Validate(prefix + "camera"); !s.ok()) return s;
  if (auto s = passthrough.Validate(prefix + "passthrough"); !s.ok()) return s;
  return voxel.Validate(prefix + "voxel");
}

}  // namespace cloudcast
