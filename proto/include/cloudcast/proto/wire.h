// The few pieces of protobuf's wire format that cloudcast writes by hand: the headers of
// length-delimited fields nested along a path. The client writes a raw frame's pixels after
// frame > image > raw > pixels headers of its own (so that they are copied once), and the server
// wraps the fields it hands protobuf in the headers of their path (RequestReader).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace cloudcast::wire {

inline constexpr int kWireVarint = 0, kWireFixed64 = 1, kWireLen = 2, kWireFixed32 = 5;

std::size_t VarintSize(std::uint64_t v);
void PutVarint(std::uint64_t v, std::string* out);

// Appends, for each field number of path[0..depth) (outermost first), its tag as a
// length-delimited field and its length, which covers the headers inside it and `content_bytes`:
// what precedes `content_bytes` of content nested at that path.
void PutNestedHeaders(const std::uint64_t* path, int depth, std::uint64_t content_bytes,
                      std::string* out);

}  // namespace cloudcast::wire
