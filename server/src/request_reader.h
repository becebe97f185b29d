// Reading a request from the bytes gRPC received, leaving the raw images' pixels where they are.
//
// A raw frame is a megabyte or more, and gRPC hands it over in dozens of slices, one per HTTP/2
// DATA frame (clients may send 256 KB frames: server.cc).
// Protobuf's parser would copy every pixel out of them into the message's `pixels` strings: 11%
// of the server's CPU per frame. RequestReader walks the message's wire format instead, records
// where the raw images' pixels (frame.disparity / depth / colour / right .raw.pixels) lie in the
// slices, and gives protobuf the rest of the message (everything but those fields) to parse as
// usual.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "cloudcast/v1/cloudcast.pb.h"
#include "grpcpp/support/byte_buffer.h"
#include "grpcpp/support/slice.h"

namespace cloudcast::server {

// Bytes held in pieces, in order: a raw image's pixels as gRPC received them.
struct ScatteredBytes {
  std::vector<std::string_view> pieces;
  std::size_t size = 0;

  void Clear() {
    pieces.clear();
    size = 0;
  }
};

// The pixels of a frame's raw images that were left in gRPC's slices. An empty plane means the
// image's pixels (if any) are in the message itself, as protobuf parsed them.
struct InPlacePixels {
  ScatteredBytes disparity;  // frame.disparity.raw.pixels
  ScatteredBytes depth;      // frame.depth.raw.pixels
  ScatteredBytes colour;     // frame.color.raw.pixels
  ScatteredBytes right;      // frame.right.raw.pixels

  bool empty() const {
    return disparity.size == 0 && depth.size == 0 && colour.size == 0 && right.size == 0;
  }
  void Clear() {
    disparity.Clear();
    depth.Clear();
    colour.Clear();
    right.Clear();
  }
};

// One per request slot, reused from message to message. Not thread-safe.
class RequestReader {
 public:
  // Parses `bytes` into `message`; false when they are not a valid message (as protobuf would
  // say). `message` then equals what protobuf's own parse of `bytes` gives, except that the raw
  // images' `pixels` fields are empty and pixels() says where their bytes are. The reader keeps
  // references to the slices (not copies) until Clear or the next Parse; `bytes` may be cleared.
  //
  // A message the wire walk does not fully understand (groups, a field of the path with another
  // wire type, truncation) is parsed by protobuf whole: the walk only ever takes shortcuts that
  // give protobuf's result.
  bool Parse(grpc::ByteBuffer* bytes, v1::StreamRequest* message);
  bool Parse(grpc::ByteBuffer* bytes, v1::ProcessRequest* message);

  const InPlacePixels& pixels() const { return pixels_; }
  // Copies the pixels left in place into `frame`'s raw images: the message protobuf's own parse
  // gives, for the checks that compare the two (tests, the fuzzers). Never on the serving path.
  void PutPixelsBack(v1::Frame* frame) const;
  // Whether the last Parse left pixels in place (false: protobuf parsed the message whole).
  bool walked() const { return walked_; }

  // Lets go of the slices (and so of the pixels).
  void Clear();

 private:
  class Walk;
  // `frame_siblings`: the fields that share the request's oneof with its frame.
  bool ParseWith(grpc::ByteBuffer* bytes, google::protobuf::Message* message,
                 const std::vector<std::uint64_t>& frame_siblings);

  std::vector<grpc::Slice> slices_;
  InPlacePixels pixels_;
  bool walked_ = false;
  // The message without its pixels: pieces of the slices and headers made up for them.
  std::string headers_;
  std::vector<std::string_view> rest_;
  // The walk's scratch, kept so that a warm reader allocates nothing per message: each slice's
  // bytes and start, and what rest_ is made of ([from, to) of headers_ or of the message).
  struct Segment {
    bool header;
    std::size_t from, to;
  };
  std::vector<std::string_view> slice_views_;
  std::vector<std::size_t> slice_starts_;
  std::vector<Segment> segments_;
};

}  // namespace cloudcast::server
