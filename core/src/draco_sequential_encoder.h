// cloudcast's own Draco encoder for the one configuration the service runs: a point cloud with
// quantized float positions and 8-bit RGB colour, sequential coding (speed 10). It writes the
// bytes libdraco 1.5.5's ExpertEncoder writes for the same cloud and options, so that every Draco
// decoder reads them and tests compare without tolerances; it only does it faster. Internal to
// core: EncodeDraco (draco_codec.cc) picks it when the options are covered.
//
// The format, as libdraco 1.5.5 writes it for this case (little-endian; "varint" is Draco's
// LEB128):
//   header      "DRACO", version 2.3, geometry 0 (point cloud), method 0 (sequential), flags u16 0
//   geometry    int32 point count
//   attributes  u8 1 (one attributes encoder), varint 2 (attributes), then per attribute:
//               u8 type, u8 data type, u8 components, u8 normalized, varint unique id
//               (POSITION float32 x3 id 0; COLOR uint8 x3 normalized id 1), then u8 2 and u8 1:
//               the sequential encoder of each (quantization, integer)
//   values      per attribute: i8 0 (delta prediction), i8 1 (wrap transform), the corrections
//               (see below), then int32 min and max of the predicted values (the wrap's bounds)
//   transform   the position quantization: float min x3, float range, u8 bits
// The corrections are zigzag symbols of "value minus previous point's value", wrapped into the
// values' range. With entropy coding (Draco's default) they are u8 1 and Draco's symbol coding
// (tagged or raw rANS, whichever Draco's estimate picks); without it u8 0, u8 bytes per value
// and the values.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "cloudcast/core/point.h"

namespace cloudcast::internal {

// What a scan of the points finds, the way Draco finds it: per-axis minimum and maximum where
// an equal value seen later never replaces the first (so -0.0 and 0.0 come out as Draco writes
// them), and the smallest and largest colour channel value.
struct DracoCloudExtent {
  float lo[3];
  float hi[3];
  std::uint8_t color_lo = 255;
  std::uint8_t color_hi = 0;
  std::size_t finite = 0;  // points with three finite coordinates
};

// Scans `n` points, skipping those with a non-finite coordinate. SSE2 on x86-64
// (draco_sequential_encoder.cc); ScanForDracoPortable elsewhere. The encoder below exists on
// x86-64 only; elsewhere EncodeDraco leaves every cloud to libdraco, whose bytes it reproduces.
DracoCloudExtent ScanForDraco(const Point* points, std::size_t n);
// The same scan in plain C++ (draco_scan.cc), for every architecture; the tests hold it equal to
// ScanForDraco on x86-64.
DracoCloudExtent ScanForDracoPortable(const Point* points, std::size_t n);

struct DracoSequentialOptions {
  int position_bits = 10;  // 1..30
  // Draco's "use_built_in_attribute_compression": false stores the corrections unencoded.
  bool entropy_coding = true;
  // Applied to every colour channel before encoding (fewer colour bits); nullptr: none. Must be
  // non-decreasing, so that the extent's colour bounds map through it.
  const std::uint8_t* color_lut = nullptr;
};

// Writes into *out (replacing its contents) what libdraco 1.5.5 writes for the `n` points (all
// finite, n >= 1) with `extent` from ScanForDraco over them. Returns false, with *out
// unspecified, for inputs whose libdraco output it does not reproduce (libdraco then has to
// run): none are known for n < 2^31 and the options above, but the rare internal failures of
// Draco's own coder (which it does not report and would write garbage for) are left to it.
// Reuses per-thread scratch: no allocation once warm, except growing *out.
bool EncodeDracoSequential(const Point* points, std::size_t n, const DracoCloudExtent& extent,
                           const DracoSequentialOptions& options, std::string* out);

// Writes into *out what libdraco 1.5.5 writes (sequential coding) for a cloud of no points whose
// one attribute is an unquantized float POSITION: the empty file EncodeDraco produces, because
// libdraco cannot quantize no values and fails to decode 0 points with an 8-bit attribute.
void EncodeDracoEmpty(std::string* out);

}  // namespace cloudcast::internal
