#include "cloudcast/proto/wire.h"

namespace cloudcast::wire {

std::size_t VarintSize(std::uint64_t v) {
  std::size_t n = 1;
  while (v >= 0x80) v >>= 7, ++n;
  return n;
}

void PutVarint(std::uint64_t v, std::string* out) {
  while (v >= 0x80) {
    out->push_back(static_cast<char>((v & 0x7f) | 0x80));
    v >>= 7;
  }
  out->push_back(static_cast<char>(v));
}

void PutNestedHeaders(const std::uint64_t* path, int depth, std::uint64_t content_bytes,
                      std::string* out) {
  constexpr int kMaxDepth = 16;
  if (depth <= 0 || depth > kMaxDepth) return;
  // Lengths from the inside out: each covers the headers inside it.
  std::uint64_t inner[kMaxDepth + 1];
  inner[depth] = content_bytes;
  for (int j = depth - 1; j >= 0; --j) {
    inner[j] = VarintSize((path[j] << 3) | kWireLen) + VarintSize(inner[j + 1]) + inner[j + 1];
  }
  for (int j = 0; j < depth; ++j) {
    PutVarint((path[j] << 3) | kWireLen, out);
    PutVarint(inner[j + 1], out);
  }
}

}  // namespace cloudcast::wire
