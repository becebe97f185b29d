#include "cloudcast/core/checks.h"

#include <cmath>
#include <string>

#include "absl/strings/str_cat.h"

namespace cloudcast::check {
namespace {

// Debian's Abseil has its own string_view, which StrCat takes; std::string converts to both.
std::string S(std::string_view v) { return std::string(v); }

// A value finite and non-zero in double that float, which the pipeline computes in, loses.
absl::Status TooSmall(std::string_view field, double value) {
  return absl::InvalidArgumentError(absl::StrCat(
      S(field), " is ", value, ": its magnitude must be at least ", kMinMagnitude,
      " (smaller values are 0 or denormal in the pipeline's single precision, and every point "
      "would vanish)"));
}

}  // namespace

absl::Status Positive(std::string_view field, double value) {
  if (!std::isfinite(value) || value <= 0.0 || value > 1e9) {
    return absl::InvalidArgumentError(
        absl::StrCat(S(field), " must be finite and in (0, 1e9], got ", value));
  }
  if (value < kMinMagnitude) return TooSmall(field, value);
  return absl::OkStatus();
}

absl::Status Finite(std::string_view field, double value) {
  if (!std::isfinite(value) || std::fabs(value) > 1e9) {
    return absl::InvalidArgumentError(
        absl::StrCat(S(field), " must be finite and within +-1e9, got ", value));
  }
  return absl::OkStatus();
}

absl::Status FiniteFloat(std::string_view field, float value) {
  if (!std::isfinite(value)) {
    return absl::InvalidArgumentError(absl::StrCat(S(field), " must be finite, got ", value));
  }
  return absl::OkStatus();
}

absl::Status NonZero(std::string_view field, double value) {
  if (absl::Status s = Finite(field, value); !s.ok()) return s;
  if (value == 0.0) return absl::InvalidArgumentError(absl::StrCat(S(field), " must not be 0"));
  if (std::fabs(value) < kMinMagnitude) return TooSmall(field, value);
  return absl::OkStatus();
}

absl::Status Leaf(std::string_view field, float value) {
  if (!std::isfinite(value) || !(value > 0.0f) || !std::isfinite(1.0f / value)) {
    return absl::InvalidArgumentError(absl::StrCat(
        S(field), " must be finite and > 0 (with 1/leaf a finite float), got ", value));
  }
  return absl::OkStatus();
}

absl::Status InRange(std::string_view field, std::int64_t value, std::int64_t lo, std::int64_t hi) {
  if (value < lo || value > hi) {
    return absl::InvalidArgumentError(
        absl::StrCat(S(field), " is ", value, "; it must be in [", lo, ", ", hi, "]"));
  }
  return absl::OkStatus();
}

absl::Status Ordered(std::string_view min_field, double min, std::string_view max_field, double max,
                     std::string_view min_note, std::string_view max_note) {
  if (min > max) {
    auto note = [](std::string_view n) { return n.empty() ? std::string() : ", " + S(n); };
    return absl::InvalidArgumentError(absl::StrCat(S(min_field), " (", min, note(min_note),
                                                   ") must not exceed ", S(max_field), " (", max,
                                                   note(max_note), ")"));
  }
  return absl::OkStatus();
}

absl::Status AtMost(std::string_view field, std::size_t count, std::size_t limit) {
  if (count > limit) {
    return absl::InvalidArgumentError(
        absl::StrCat(S(field), " holds ", count, " values; the limit is ", limit));
  }
  return absl::OkStatus();
}

absl::Status ImageSize(std::string_view field, std::uint32_t width, std::uint32_t height,
                       const Limits& limits) {
  if (width == 0 || height == 0) {
    return absl::InvalidArgumentError(absl::StrCat(S(field), width == 0 ? ".width" : ".height",
                                                   " is 0; an image has at least 1x1 pixels"));
  }
  if (width > limits.max_side || height > limits.max_side) {
    return absl::ResourceExhaustedError(absl::StrCat(S(field), " is ", width, "x", height,
                                                     "; the limit is ", limits.max_side,
                                                     " pixels per side"));
  }
  const std::uint64_t pixels = std::uint64_t{width} * height;
  if (pixels > limits.max_pixels) {
    return absl::ResourceExhaustedError(
        absl::StrCat(S(field), " is ", width, "x", height, " = ", pixels, " pixels; the limit is ",
                     limits.max_pixels, " pixels (width x height)"));
  }
  return absl::OkStatus();
}

}  // namespace cloudcast::check
