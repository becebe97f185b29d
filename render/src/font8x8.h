// The overlay's built-in bitmap font, so the viewer needs no font files or font libraries.
#pragma once

#include <cstdint>

namespace cloudcast::render::internal {

constexpr int kGlyphSize = 8;    // pixels, square
constexpr int kFirstGlyph = 32;  // ' '
constexpr int kLastGlyph = 126;  // '~'
constexpr int kGlyphCount = kLastGlyph - kFirstGlyph + 1;

// Row r of glyph c (ASCII kFirstGlyph + c) is kFont8x8[c][r], top row first; bit b set means
// the pixel in column b (bit 0 = leftmost) is ink.
extern const std::uint8_t kFont8x8[kGlyphCount][kGlyphSize];

}  // namespace cloudcast::render::internal
