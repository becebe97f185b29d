#include "request_reader.h"

#include <algorithm>
#include <cstdint>

#include "cloudcast/proto/wire.h"
#include "google/protobuf/io/zero_copy_stream.h"
#include "grpcpp/support/proto_buffer_reader.h"

namespace cloudcast::server {
namespace {

// The path to the pixel fields. StreamRequest and ProcessRequest share their frame's number, and
// the image messages (disparity, depth, colour) and their raw messages share their numbers, so one
// walk serves them all.
constexpr int N(int number) { return number; }  // the generated constants are distinct enums
static_assert(N(v1::StreamRequest::kFrameFieldNumber) == N(v1::ProcessRequest::kFrameFieldNumber));
static_assert(N(v1::DisparityImage::kRawFieldNumber) == N(v1::ColorImage::kRawFieldNumber));
static_assert(N(v1::DisparityImage::kEncodedFieldNumber) == N(v1::ColorImage::kEncodedFieldNumber));
static_assert(N(v1::DisparityImage::kCompressedFieldNumber) ==
              N(v1::ColorImage::kCompressedFieldNumber));
static_assert(N(v1::RawDisparity::kPixelsFieldNumber) == N(v1::RawColor::kPixelsFieldNumber));
static_assert(N(v1::DepthImage::kRawFieldNumber) == N(v1::ColorImage::kRawFieldNumber));
static_assert(N(v1::DepthImage::kEncodedFieldNumber) == N(v1::ColorImage::kEncodedFieldNumber));
static_assert(N(v1::DepthImage::kCompressedFieldNumber) ==
              N(v1::ColorImage::kCompressedFieldNumber));
static_assert(N(v1::RawDepth::kPixelsFieldNumber) == N(v1::RawColor::kPixelsFieldNumber));

enum class Level { kRequest, kFrame, kImage, kRaw };
enum class Plane { kNone, kDisparity, kDepth, kColour, kRight };

// The plane a frame's field holds, or kNone for a field off the path.
Plane PlaneOf(std::uint64_t number) {
  switch (number) {
    case v1::Frame::kDisparityFieldNumber:
      return Plane::kDisparity;
    case v1::Frame::kDepthFieldNumber:
      return Plane::kDepth;
    case v1::Frame::kColorFieldNumber:
      return Plane::kColour;
    case v1::Frame::kRightFieldNumber:
      return Plane::kRight;
    default:
      return Plane::kNone;
  }
}

using wire::kWireFixed32;
using wire::kWireFixed64;
using wire::kWireLen;
using wire::kWireVarint;
constexpr int kMaxDepth = 3;  // request > frame > image > raw

// What a field is to the walk.
enum class Role {
  kOther,    // passed on to protobuf as it is
  kDescend,  // a message on the path to the pixels
  kPixels,   // the bytes left in place
  kClears,   // a oneof sibling of the path: setting it clears what the path set
};

// The numbers of the fields that share `field`'s oneof, `field` excepted (none when it is in no
// oneof).
std::vector<std::uint64_t> OneofSiblings(const google::protobuf::FieldDescriptor* field) {
  std::vector<std::uint64_t> out;
  const google::protobuf::OneofDescriptor* oneof = field->containing_oneof();
  for (int i = 0; oneof != nullptr && i < oneof->field_count(); ++i) {
    if (oneof->field(i) != field)
      out.push_back(static_cast<std::uint64_t>(oneof->field(i)->number()));
  }
  return out;
}

bool Contains(const std::vector<std::uint64_t>& numbers, std::uint64_t number) {
  return std::find(numbers.begin(), numbers.end(), number) != numbers.end();
}

// Which fields replace the path's, read from the descriptors once: the proto's oneofs, not a
// list kept beside them (a hand-kept list missed ColorImage.video when contract revision 3 added
// it, and the walk kept pixels that protobuf's parse clears).
struct PathOneofs {
  std::vector<std::uint64_t> stream_request;  // StreamRequest.frame's siblings (config)
  std::vector<std::uint64_t> process_request;
  // Per plane (indexed by Plane): the siblings of its image's raw, and the planes its frame field
  // shares a oneof with (Frame.geometry: disparity, depth and right).
  std::vector<std::uint64_t> raw[5];
  std::vector<Plane> geometry[5];

  PathOneofs() {
    const auto frame_field = [](const google::protobuf::Descriptor* d) {
      return d->FindFieldByNumber(v1::StreamRequest::kFrameFieldNumber);
    };
    stream_request = OneofSiblings(frame_field(v1::StreamRequest::descriptor()));
    process_request = OneofSiblings(frame_field(v1::ProcessRequest::descriptor()));
    const google::protobuf::Descriptor* frame = v1::Frame::descriptor();
    for (const int number : {v1::Frame::kDisparityFieldNumber, v1::Frame::kDepthFieldNumber,
                             v1::Frame::kColorFieldNumber, v1::Frame::kRightFieldNumber}) {
      const google::protobuf::FieldDescriptor* field = frame->FindFieldByNumber(number);
      const auto plane = static_cast<int>(PlaneOf(static_cast<std::uint64_t>(number)));
      raw[plane] = OneofSiblings(
          field->message_type()->FindFieldByNumber(v1::DisparityImage::kRawFieldNumber));
      for (const std::uint64_t sibling : OneofSiblings(field)) {
        geometry[plane].push_back(PlaneOf(sibling));
      }
    }
  }
};

const PathOneofs& Oneofs() {
  static const PathOneofs oneofs;
  return oneofs;
}

// Reads a message from pieces, for protobuf.
class PiecesInput final : public google::protobuf::io::ZeroCopyInputStream {
 public:
  explicit PiecesInput(const std::vector<std::string_view>& pieces) : pieces_(pieces) {}

  bool Next(const void** data, int* size) override {
    if (backed_up_ > 0) {
      const std::string_view last = pieces_[next_ - 1];
      *data = last.data() + last.size() - backed_up_;
      *size = backed_up_;
      count_ += backed_up_;
      backed_up_ = 0;
      return true;
    }
    while (next_ < pieces_.size() && pieces_[next_].empty()) ++next_;
    if (next_ == pieces_.size()) return false;
    const std::string_view p = pieces_[next_++];
    *data = p.data();
    *size = static_cast<int>(p.size());
    count_ += static_cast<std::int64_t>(p.size());
    return true;
  }
  void BackUp(int count) override {
    backed_up_ = count;
    count_ -= count;
  }
  bool Skip(int count) override {
    const void* data;
    int size;
    while (count > 0) {
      if (!Next(&data, &size)) return false;
      if (size > count) {
        BackUp(size - count);
        return true;
      }
      count -= size;
    }
    return true;
  }
  std::int64_t ByteCount() const override { return count_; }

 private:
  const std::vector<std::string_view>& pieces_;
  std::size_t next_ = 0;
  int backed_up_ = 0;
  std::int64_t count_ = 0;
};

}  // namespace

// One walk over a message in slices. Positions are offsets into the message as one sequence of
// bytes. The walk goes forward only, so the slice it reads from is found by stepping.
//
// What protobuf gets: every field off the path, as it came, in order, each run of them wrapped in
// made-up headers for the path down to it (tag + length of frame, image, raw). Protobuf merges
// repeated occurrences of a message field, so these pieces parse to the message that the original
// bytes parse to, without the pixel fields. An empty wrapper is given whenever the path is entered,
// so that a `raw` holding only pixels is still set (its oneof case chosen, in order).
class RequestReader::Walk {
 public:
  Walk(const std::vector<grpc::Slice>& slices, const std::vector<std::uint64_t>& frame_siblings,
       RequestReader* reader)
      : frame_siblings_(frame_siblings),
        reader_(reader),
        views_(reader->slice_views_),
        starts_(reader->slice_starts_),
        segments_(reader->segments_) {
    views_.clear();
    starts_.clear();
    segments_.clear();
    std::size_t at = 0;
    for (const grpc::Slice& s : slices) {
      starts_.push_back(at);
      views_.emplace_back(reinterpret_cast<const char*>(s.begin()), s.size());
      at += s.size();
    }
    starts_.push_back(at);
  }

  // False when the message needs protobuf's own parse (or is not valid).
  bool Run() {
    if (!Fields(Level::kRequest, Plane::kNone, 0, starts_.back())) return false;
    // The pieces, now that the headers no longer move.
    reader_->rest_.clear();
    for (const Segment& s : segments_) {
      if (s.header) {
        reader_->rest_.emplace_back(reader_->headers_.data() + s.from, s.to - s.from);
      } else {
        Pieces(s.from, s.to, &reader_->rest_);
      }
    }
    return true;
  }

 private:
  using Segment = RequestReader::Segment;

  unsigned char At(std::size_t pos) {
    while (pos >= starts_[slice_ + 1]) ++slice_;
    return static_cast<unsigned char>(views_[slice_][pos - starts_[slice_]]);
  }

  bool Varint(std::size_t* pos, std::size_t end, std::uint64_t* value) {
    std::uint64_t v = 0;
    for (int shift = 0; shift < 64; shift += 7) {
      if (*pos >= end) return false;
      const unsigned char b = At((*pos)++);
      v |= std::uint64_t{b & 0x7fu} << shift;
      if ((b & 0x80) == 0) {
        *value = v;
        return true;
      }
    }
    return false;
  }

  // Past the value of a field whose tag was read; false on groups and bad wire types, which
  // protobuf is left to handle (or refuse).
  bool Skip(int wire, std::size_t* pos, std::size_t end) {
    std::uint64_t n;
    switch (wire) {
      case kWireVarint:
        return Varint(pos, end, &n);
      case kWireFixed64:
        n = 8;
        break;
      case kWireFixed32:
        n = 4;
        break;
      case kWireLen:
        if (!Varint(pos, end, &n)) return false;
        break;
      default:
        return false;
    }
    if (n > end - *pos) return false;
    *pos += n;
    return true;
  }

  // The fields of one message in [from, to), at `level` of the path.
  bool Fields(Level level, Plane plane, std::size_t from, std::size_t to) {
    std::size_t pos = from, run = from;
    while (pos < to) {
      const std::size_t field_start = pos;
      std::uint64_t tag;
      if (!Varint(&pos, to, &tag)) return false;
      const int wire = static_cast<int>(tag & 7);
      const std::uint64_t number = tag >> 3;
      const Role role = RoleOf(level, plane, number);
      if (role == Role::kDescend || role == Role::kPixels) {
        std::uint64_t len;
        if (wire != kWireLen || !Varint(&pos, to, &len) || len > to - pos) return false;
        Emit(run, field_start, false);
        if (role == Role::kPixels) {
          Record(plane, pos, pos + len);
        } else {
          if (depth_ == kMaxDepth) return false;
          path_[depth_++] = number;
          Emit(pos, pos, true);  // the path's message is set here, even if nothing else is
          const Level next = static_cast<Level>(static_cast<int>(level) + 1);
          const Plane child = level == Level::kFrame ? PlaneOf(number) : plane;
          // Entering a frame field clears the planes of its oneof (disparity, depth and right are
          // Frame.geometry), as protobuf's parse does.
          if (level == Level::kFrame) {
            for (const Plane other : Oneofs().geometry[static_cast<int>(child)]) {
              Pixels(other)->Clear();
            }
          }
          if (!Fields(next, child, pos, pos + len)) return false;
          --depth_;
        }
        pos += len;
        run = pos;
        continue;
      }
      if (role == Role::kClears && wire == kWireLen) {
        // Another member of the oneof replaces what the path set: the request's frame (every
        // plane) or an image's raw (its plane). (All those members are messages or bytes; with
        // another wire type the field is unknown to protobuf and replaces nothing.)
        if (plane == Plane::kNone) {
          reader_->pixels_.Clear();
        } else {
          Pixels(plane)->Clear();
        }
      }
      if (!Skip(wire, &pos, to)) return false;
    }
    Emit(run, to, false);
    return true;
  }

  Role RoleOf(Level level, Plane plane, std::uint64_t number) const {
    switch (level) {
      case Level::kRequest:
        if (number == v1::StreamRequest::kFrameFieldNumber) return Role::kDescend;
        return Contains(frame_siblings_, number) ? Role::kClears : Role::kOther;
      case Level::kFrame:
        return PlaneOf(number) != Plane::kNone ? Role::kDescend : Role::kOther;
      case Level::kImage:
        if (number == v1::DisparityImage::kRawFieldNumber) return Role::kDescend;
        return Contains(Oneofs().raw[static_cast<int>(plane)], number) ? Role::kClears
                                                                       : Role::kOther;
      case Level::kRaw:
        return number == v1::RawDisparity::kPixelsFieldNumber ? Role::kPixels : Role::kOther;
    }
    return Role::kOther;
  }

  ScatteredBytes* Pixels(Plane plane) {
    switch (plane) {
      case Plane::kDisparity:
        return &reader_->pixels_.disparity;
      case Plane::kDepth:
        return &reader_->pixels_.depth;
      case Plane::kRight:
        return &reader_->pixels_.right;
      default:
        return &reader_->pixels_.colour;
    }
  }

  void Record(Plane plane, std::size_t from, std::size_t to) {
    ScatteredBytes* p = Pixels(plane);
    p->Clear();
    p->size = to - from;
    Pieces(from, to, &p->pieces);
  }

  // Bytes [from, to) of the message, wrapped in the headers of the path down to the current depth.
  void Emit(std::size_t from, std::size_t to, bool even_if_empty) {
    if (from == to && !even_if_empty) return;
    if (depth_ > 0) {
      std::string& h = reader_->headers_;
      const std::size_t start = h.size();
      wire::PutNestedHeaders(path_, depth_, to - from, &h);
      segments_.push_back({true, start, h.size()});
    }
    if (from < to) segments_.push_back({false, from, to});
  }

  // The slices' parts that hold [from, to).
  void Pieces(std::size_t from, std::size_t to, std::vector<std::string_view>* out) const {
    auto i = static_cast<std::size_t>(std::upper_bound(starts_.begin(), starts_.end(), from) -
                                      starts_.begin() - 1);
    while (from < to) {
      const std::size_t end = std::min(to, starts_[i + 1]);
      out->push_back(views_[i].substr(from - starts_[i], end - from));
      from = end;
      ++i;
    }
  }

  const std::vector<std::uint64_t>& frame_siblings_;  // the request's oneof around its frame
  RequestReader* const reader_;
  std::vector<std::string_view>& views_;
  std::vector<std::size_t>& starts_;  // of each slice, and the message's end
  std::vector<Segment>& segments_;
  std::size_t slice_ = 0;
  std::uint64_t path_[kMaxDepth] = {};
  int depth_ = 0;
};

bool RequestReader::Parse(grpc::ByteBuffer* bytes, v1::StreamRequest* message) {
  return ParseWith(bytes, message, Oneofs().stream_request);
}

bool RequestReader::Parse(grpc::ByteBuffer* bytes, v1::ProcessRequest* message) {
  return ParseWith(bytes, message, Oneofs().process_request);
}

namespace {
std::string Joined(const ScatteredBytes& bytes) {
  std::string out;
  out.reserve(bytes.size);
  for (std::string_view p : bytes.pieces) out.append(p);
  return out;
}
}  // namespace

void RequestReader::PutPixelsBack(v1::Frame* frame) const {
  if (pixels_.disparity.size > 0) {
    frame->mutable_disparity()->mutable_raw()->set_pixels(Joined(pixels_.disparity));
  }
  if (pixels_.depth.size > 0) {
    frame->mutable_depth()->mutable_raw()->set_pixels(Joined(pixels_.depth));
  }
  if (pixels_.colour.size > 0) {
    frame->mutable_color()->mutable_raw()->set_pixels(Joined(pixels_.colour));
  }
  if (pixels_.right.size > 0) {
    frame->mutable_right()->mutable_raw()->set_pixels(Joined(pixels_.right));
  }
}

void RequestReader::Clear() {
  slices_.clear();
  pixels_.Clear();
  headers_.clear();
  rest_.clear();
  walked_ = false;
}

bool RequestReader::ParseWith(grpc::ByteBuffer* bytes, google::protobuf::Message* message,
                              const std::vector<std::uint64_t>& frame_siblings) {
  Clear();
  if (bytes->Valid() && bytes->Dump(&slices_).ok()) {
    Walk walk(slices_, frame_siblings, this);
    if (walk.Run()) {
      PiecesInput input(rest_);
      walked_ = true;
      if (message->ParseFromZeroCopyStream(&input)) {
        // Nothing left in place (a config, an encoded or compressed frame): let the slices go
        // now, as protobuf's own parse would, rather than while the frame waits and runs.
        if (pixels_.empty()) {
          slices_.clear();
          rest_.clear();
        }
        return true;
      }
      // Not a valid message after all: protobuf said so on the same bytes.
      Clear();
      return false;
    }
    Clear();
  }
  grpc::ProtoBufferReader reader(bytes);
  return message->ParseFromZeroCopyStream(&reader);
}

}  // namespace cloudcast::server
