#include "cloudcast/video/rvl.h"

#include <cstring>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/checks.h"

namespace cloudcast::video {
namespace {

// Debian's Abseil has its own string_view, which StrCat takes; std::string converts to both.
std::string S(std::string_view v) { return std::string(v); }

constexpr char kMagic[4] = {'R', 'V', 'L', '1'};
constexpr std::size_t kHeader = 12;

void PutU32(std::string* out, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) (*out)[at + i] = static_cast<char>((v >> (8 * i)) & 0xFF);
}
std::uint32_t GetU32(const char* p) {
  std::uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v |= std::uint32_t{static_cast<std::uint8_t>(p[i])} << (8 * i);
  return v;
}

class NibbleWriter {
 public:
  explicit NibbleWriter(std::string* out) : out_(out) {}
  void Vle(std::uint32_t value) {
    do {
      std::uint32_t nibble = value & 7;
      value >>= 3;
      if (value != 0) nibble |= 8;
      word_ = (word_ << 4) | nibble;
      if (++nibbles_ == 8) Flush();
    } while (value != 0);
  }
  void Finish() {
    if (nibbles_ == 0) return;
    word_ <<= 4 * (8 - nibbles_);
    Flush();
  }

 private:
  void Flush() {
    const std::size_t at = out_->size();
    out_->resize(at + 4);
    PutU32(out_, at, word_);
    word_ = 0;
    nibbles_ = 0;
  }
  std::string* out_;
  std::uint32_t word_ = 0;
  int nibbles_ = 0;
};

template <typename T>
void Encode(const T* pixels, std::uint32_t width, std::uint32_t height, std::string* out) {
  out->assign(kHeader, '\0');
  std::memcpy(out->data(), kMagic, 4);
  PutU32(out, 4, width);
  PutU32(out, 8, height);
  out->reserve(kHeader + std::size_t{width} * height / 2);
  NibbleWriter w(out);
  const T* p = pixels;
  const T* const end = pixels + std::size_t{width} * height;
  std::int32_t previous = 0;
  while (p != end) {
    const T* run = p;
    while (p != end && *p == 0) ++p;
    w.Vle(static_cast<std::uint32_t>(p - run));
    run = p;
    while (p != end && *p != 0) ++p;
    w.Vle(static_cast<std::uint32_t>(p - run));
    for (; run != p; ++run) {
      const std::int32_t delta = static_cast<std::int32_t>(*run) - previous;
      // Zig-zag: 0, -1, 1, -2, ... to 0, 1, 2, 3, ... (in unsigned arithmetic: no signed shift).
      w.Vle((static_cast<std::uint32_t>(delta) << 1) ^ static_cast<std::uint32_t>(delta >> 31));
      previous = *run;
    }
  }
  w.Finish();
}

}  // namespace

void EncodeRvl(const std::uint16_t* pixels, std::uint32_t width, std::uint32_t height,
               std::string* out) {
  Encode(pixels, width, height, out);
}
void EncodeRvl(const std::uint8_t* pixels, std::uint32_t width, std::uint32_t height,
               std::string* out) {
  Encode(pixels, width, height, out);
}

absl::Status DecodeRvl(std::string_view bytes, std::uint32_t width, std::uint32_t height,
                       std::uint32_t max_value, const Limits& limits, std::string_view field,
                       std::vector<std::uint16_t>* out) {
  if (absl::Status s = check::ImageSize(S(field), width, height, limits); !s.ok()) return s;
  if (bytes.size() < kHeader || std::memcmp(bytes.data(), kMagic, 4) != 0) {
    return absl::InvalidArgumentError(
        absl::StrCat(S(field), " is not RVL: it must start with \"RVL1\", width and height"));
  }
  const std::uint32_t w = GetU32(bytes.data() + 4), h = GetU32(bytes.data() + 8);
  if (w != width || h != height) {
    return absl::InvalidArgumentError(absl::StrCat(S(field), " holds a ", w, "x", h,
                                                   " image; the frame is ", width, "x", height));
  }
  if ((bytes.size() - kHeader) % 4 != 0) {
    return absl::InvalidArgumentError(absl::StrCat(S(field), ": ", bytes.size() - kHeader,
                                                   " bytes after the header are not "
                                                   "whole 32-bit words"));
  }
  const std::size_t pixels = std::size_t{width} * height;
  out->resize(pixels);
  const char* words = bytes.data() + kHeader;
  const std::size_t word_count = (bytes.size() - kHeader) / 4;
  std::size_t next_word = 0;
  std::uint32_t word = 0;
  int nibbles = 0;
  bool truncated = false;
  // Each number takes at most 11 groups of 3 bits (32 bits); more is malformed.
  const auto vle = [&](std::uint32_t* value) {
    std::uint64_t v = 0;
    for (int shift = 0; shift < 33; shift += 3) {
      if (nibbles == 0) {
        if (next_word == word_count) {
          truncated = true;
          return false;
        }
        word = GetU32(words + 4 * next_word++);
        nibbles = 8;
      }
      const std::uint32_t nibble = word >> 28;
      word <<= 4;
      --nibbles;
      v |= std::uint64_t{nibble & 7} << shift;
      if ((nibble & 8) == 0) {
        if (v > 0xFFFFFFFFu) return false;
        *value = static_cast<std::uint32_t>(v);
        return true;
      }
    }
    return false;
  };
  const auto malformed = [&](std::size_t at, const char* what) {
    return absl::InvalidArgumentError(
        truncated ? absl::StrCat(S(field), " ends at pixel ", at, " of ", pixels)
                  : absl::StrCat(S(field), " is malformed at pixel ", at, ": ", what));
  };
  std::uint16_t* dst = out->data();
  std::size_t at = 0;
  std::int64_t previous = 0;
  while (at < pixels) {
    std::uint32_t zeros = 0, nonzeros = 0;
    if (!vle(&zeros)) return malformed(at, "a run length longer than 32 bits");
    if (zeros > pixels - at) return malformed(at, "a run of zeros past the image's end");
    std::memset(dst + at, 0, std::size_t{zeros} * sizeof(std::uint16_t));
    at += zeros;
    if (!vle(&nonzeros)) return malformed(at, "a run length longer than 32 bits");
    if (nonzeros > pixels - at) return malformed(at, "a run of values past the image's end");
    for (std::uint32_t i = 0; i < nonzeros; ++i) {
      std::uint32_t zz = 0;
      if (!vle(&zz)) return malformed(at, "a value longer than 32 bits");
      const std::int64_t delta = (zz >> 1) ^ -static_cast<std::int64_t>(zz & 1);
      const std::int64_t value = previous + delta;
      if (value <= 0 || value > max_value) {
        return malformed(at, value <= 0 ? "a value of 0 or less inside a run of values"
                                        : "a value over the image's sample range");
      }
      dst[at++] = static_cast<std::uint16_t>(value);
      previous = value;
    }
  }
  return absl::OkStatus();
}

}  // namespace cloudcast::video
