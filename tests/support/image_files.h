// Image files written by hand (PNG with stored deflate blocks, TIFF, PNM, PFM), so that the tests
// need no image library of their own and control every byte the decoder sees.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <string>
#include <string_view>
#include <tuple>
#include <vector>

namespace cloudcast::testing {

inline void WriteFile(const std::string& path, const std::string& bytes) {
  std::ofstream file(path, std::ios::binary);
  file.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(file.good()) << path;
}

inline void PutBe32(std::string* s, std::uint32_t v) {
  for (int shift = 24; shift >= 0; shift -= 8) s->push_back(static_cast<char>(v >> shift));
}
inline void PutLe(std::string* s, std::uint32_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) s->push_back(static_cast<char>(v >> (8 * i)));
}

inline std::uint32_t Crc32(const std::string& bytes) {
  std::uint32_t crc = 0xFFFFFFFFu;
  for (unsigned char c : bytes) {
    crc ^= c;
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  return crc ^ 0xFFFFFFFFu;
}

// A PNG of `rows` (already in PNG sample order, 16-bit samples big-endian).
// colour_type: 0 grey, 2 RGB, 4 grey + alpha, 6 RGBA.
inline std::string Png(std::uint32_t w, std::uint32_t h, int bit_depth, int colour_type,
                       const std::string& rows) {
  const std::size_t row_bytes = rows.size() / h;
  std::string raw;
  for (std::uint32_t v = 0; v < h; ++v) raw += '\0' + rows.substr(v * row_bytes, row_bytes);
  std::string zlib = "\x78\x01";
  for (std::size_t at = 0; at < raw.size() || at == 0; at += 65535) {
    const std::size_t n = std::min<std::size_t>(65535, raw.size() - at);
    zlib.push_back(at + n >= raw.size() ? 1 : 0);
    PutLe(&zlib, static_cast<std::uint32_t>(n), 2);
    PutLe(&zlib, static_cast<std::uint32_t>(~n & 0xFFFF), 2);
    zlib += raw.substr(at, n);
  }
  std::uint32_t a = 1, b = 0;
  for (unsigned char c : raw) {
    a = (a + c) % 65521;
    b = (b + a) % 65521;
  }
  PutBe32(&zlib, (b << 16) | a);
  auto chunk = [](const std::string& type, const std::string& data) {
    std::string c;
    PutBe32(&c, static_cast<std::uint32_t>(data.size()));
    c += type + data;
    PutBe32(&c, Crc32(type + data));
    return c;
  };
  std::string ihdr;
  PutBe32(&ihdr, w);
  PutBe32(&ihdr, h);
  ihdr += {static_cast<char>(bit_depth), static_cast<char>(colour_type), 0, 0, 0};
  return std::string("\x89PNG\r\n\x1a\n", 8) + chunk("IHDR", ihdr) + chunk("IDAT", zlib) +
         chunk("IEND", "");
}

inline std::string Bytes(const std::vector<std::uint8_t>& v) {
  return std::string(v.begin(), v.end());
}
inline std::string Be16(const std::vector<std::uint16_t>& v) {
  std::string s;
  for (std::uint16_t x : v) s += {static_cast<char>(x >> 8), static_cast<char>(x & 0xFF)};
  return s;
}

// BGR8 rows -> RGBA PNG rows with the given alpha pattern (as New Tsukuba's colour PNGs).
inline std::string RgbaRowsFromBgr(const std::vector<std::uint8_t>& bgr) {
  std::string s;
  for (std::size_t i = 0; i + 2 < bgr.size(); i += 3) {
    const std::uint8_t alpha = static_cast<std::uint8_t>((i / 3) % 3 == 0 ? 0 : 136 + i % 120);
    s += {static_cast<char>(bgr[i + 2]), static_cast<char>(bgr[i + 1]), static_cast<char>(bgr[i]),
          static_cast<char>(alpha)};
  }
  return s;
}

using TiffEntry = std::tuple<int, int, std::uint32_t>;  // tag, type (3 SHORT, 4 LONG), value

// A little-endian TIFF: `pixels` at offset 8, then one image file directory of `entries` (count 1
// each), written in the order given (the spec wants ascending tags; tests of bad files do not).
inline std::string Tiff(std::string_view pixels, const std::vector<TiffEntry>& entries) {
  std::string s("II*\0", 4);
  PutLe(&s, static_cast<std::uint32_t>(8 + pixels.size()), 4);  // the IFD follows the pixels
  s.append(pixels);
  PutLe(&s, static_cast<std::uint32_t>(entries.size()), 2);
  for (const auto& [tag, type, value] : entries) {
    PutLe(&s, tag, 2);
    PutLe(&s, type, 2);
    PutLe(&s, 1, 4);
    PutLe(&s, value, 4);  // SHORT values sit in the low bytes (little-endian)
  }
  PutLe(&s, 0, 4);
  return s;
}

// Baseline little-endian TIFF, one strip, uncompressed, one 32-bit float sample per pixel.
inline std::string FloatTiff(std::uint32_t w, std::uint32_t h, const std::vector<float>& v) {
  const std::uint32_t data_bytes = static_cast<std::uint32_t>(v.size() * 4);
  return Tiff(std::string_view(reinterpret_cast<const char*>(v.data()), data_bytes),
              {{256, 4, w}, {257, 4, h}, {258, 3, 32}, {259, 3, 1}, {262, 3, 1},
               {273, 4, 8}, {277, 3, 1}, {278, 4, h}, {279, 4, data_bytes}, {339, 3, 3}});
}

inline std::string PnmHeader(const char* magic, std::uint32_t w, std::uint32_t h, int maxval) {
  return std::string(magic) + "\n" + std::to_string(w) + " " + std::to_string(h) + "\n" +
         std::to_string(maxval) + "\n";
}

// PFM: grey float, little-endian (negative scale), rows stored bottom to top.
inline std::string Pfm(std::uint32_t w, std::uint32_t h, const std::vector<float>& v) {
  std::string s = "Pf\n" + std::to_string(w) + " " + std::to_string(h) + "\n-1.0\n";
  for (std::uint32_t r = h; r-- > 0;) {
    s.append(reinterpret_cast<const char*>(v.data() + std::size_t{r} * w), w * sizeof(float));
  }
  return s;
}

template <typename T>
inline std::vector<T> Samples(const std::vector<std::uint8_t>& bytes) {
  std::vector<T> v(bytes.size() / sizeof(T));
  std::memcpy(v.data(), bytes.data(), v.size() * sizeof(T));
  return v;
}

}  // namespace cloudcast::testing
