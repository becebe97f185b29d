// The image decoders of the encoded-frame path, through PrepareFrameImages as a worker calls it
// (one DecodeScratch kept from input to input, as a worker keeps it): PNG, JPEG, TIFF and PNM
// bytes checked by CheckEncodedImage and decoded by OpenCV, PFM by io/src/pfm.cc (seed
// pfm_header_opencv_reads_otherwise: OpenCV left a file in /tmp for it), and the zstd uplink
// (convert::DecodeCompressed, core/frame_codec's PlaneDecompressor and predictors).
//
// Input layout (fuzz/make_seeds.cc writes the seeds in it):
//   byte 0 = mode % 4:
//     0  frame.disparity.encoded = the rest; colour a raw 1x1 grey pixel
//     1  frame.color.encoded = the rest; disparity a raw 1x1 U8 pixel
//     2  frame.disparity.compressed; 3  frame.color.compressed; the other image raw 1x1:
//        byte 1 encoding, byte 2 compression, bytes 3-4 width, 5-6 height (little endian),
//        the rest the payload
// A decoded image larger than 1x1 then fails the same-size check, after it was decoded.
#include <cstddef>
#include <cstdint>
#include <string>

#include "cloudcast/core/limits.h"
#include "cloudcast/v1/cloudcast.pb.h"
#include "frame_input.h"

using namespace cloudcast;

namespace {

std::uint32_t Le16(const std::uint8_t* p) { return std::uint32_t{p[0]} | std::uint32_t{p[1]} << 8; }

void SetRawDisparity(v1::DisparityImage* d) {
  v1::RawDisparity* raw = d->mutable_raw();
  raw->set_encoding(v1::DISPARITY_U8);
  raw->set_width(1);
  raw->set_height(1);
  raw->set_pixels(std::string(1, '\x10'));
}

void SetRawColour(v1::ColorImage* c) {
  v1::RawColor* raw = c->mutable_raw();
  raw->set_encoding(v1::COLOR_MONO8);
  raw->set_width(1);
  raw->set_height(1);
  raw->set_pixels(std::string(1, '\x80'));
}

template <typename View>
void Touch(const View& view) {
  volatile std::uint8_t sum = 0;
  const std::size_t row_bytes = std::size_t{view.width} * BytesPerPixel(view.encoding);
  for (std::uint32_t v = 0; v < view.height; ++v) {
    const std::uint8_t* row = view.row(v);
    for (std::size_t i = 0; i < row_bytes; ++i) sum = sum + row[i];
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static server::DecodeScratch* scratch = new server::DecodeScratch;
  // Small enough that one input costs milliseconds; the checks are the same at any limit.
  Limits limits;
  limits.max_side = 512;
  limits.max_pixels = 1u << 17;
  if (size < 1) return 0;
  const int mode = data[0] % 4;
  v1::Frame frame;
  if (mode <= 1) {
    const std::string bytes(reinterpret_cast<const char*>(data + 1), size - 1);
    if (mode == 0) {
      frame.mutable_disparity()->set_encoded(bytes);
      SetRawColour(frame.mutable_color());
    } else {
      SetRawDisparity(frame.mutable_disparity());
      frame.mutable_color()->set_encoded(bytes);
    }
  } else {
    if (size < 7) return 0;
    const std::string payload(reinterpret_cast<const char*>(data + 7), size - 7);
    const auto compression = static_cast<v1::Compression>(data[2] % 5);
    if (mode == 2) {
      v1::CompressedDisparity* c = frame.mutable_disparity()->mutable_compressed();
      c->set_encoding(static_cast<v1::DisparityEncoding>(data[1] % 5));
      c->set_compression(compression);
      c->set_width(Le16(data + 3));
      c->set_height(Le16(data + 5));
      c->set_payload(payload);
      SetRawColour(frame.mutable_color());
    } else {
      SetRawDisparity(frame.mutable_disparity());
      v1::CompressedColor* c = frame.mutable_color()->mutable_compressed();
      c->set_encoding(static_cast<v1::ColorEncoding>(data[1] % 6));
      c->set_compression(compression);
      c->set_width(Le16(data + 3));
      c->set_height(Le16(data + 5));
      c->set_payload(payload);
    }
  }
  (void)server::FramePixels(frame);
  server::FrameImages images;
  if (server::PrepareFrameImages(frame, limits, scratch, &images).ok()) {
    // Read every pixel the views claim, as the pipeline would, so a view past its buffer is
    // caught here.
    Touch(images.disparity);
    Touch(images.colour);
  }
  return 0;
}
