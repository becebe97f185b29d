#include "cloudcast/core/frame_codec.h"

#define ZSTD_STATIC_LINKING_ONLY  // ZSTD_getFrameHeader
#include <zstd.h>

#include <cstring>
#include <limits>
#include <string>

#include "absl/strings/str_cat.h"

namespace cloudcast {
namespace {

// Samples read and written through these may alias the byte buffers they live in.
using U16 = std::uint16_t __attribute__((may_alias));
using U32 = std::uint32_t __attribute__((may_alias));

constexpr Limits kNoLimits{std::numeric_limits<std::uint32_t>::max(),
                           std::numeric_limits<std::uint64_t>::max()};

std::string S(std::string_view v) { return std::string(v); }

// A byte buffer that grows without zero-filling and never shrinks.
class Buffer {
 public:
  std::uint8_t* Reserve(std::size_t n) {
    if (n > capacity_) {
      data_.reset(new std::uint8_t[n]);  // default-initialised: no zero fill
      capacity_ = n;
    }
    return data_.get();
  }
  std::uint8_t* data() const { return data_.get(); }
  std::size_t capacity() const { return capacity_; }

 private:
  std::unique_ptr<std::uint8_t[]> data_;
  std::size_t capacity_ = 0;
};

template <typename T>
void ApplyUpT(const PlaneLayout& l, const std::uint8_t* src, std::size_t stride,
              std::uint8_t* dst) {
  const std::size_t row_bytes = std::size_t{l.width} * l.bpp;
  const std::size_t n = row_bytes / sizeof(T);
  std::memcpy(dst, src, row_bytes);
  for (std::uint32_t v = 1; v < l.height; ++v) {
    const T* cur = reinterpret_cast<const T*>(src + v * stride);
    const T* up = reinterpret_cast<const T*>(src + (v - 1) * stride);
    T* out = reinterpret_cast<T*>(dst + v * row_bytes);
    for (std::size_t i = 0; i < n; ++i) out[i] = static_cast<T>(cur[i] - up[i]);
  }
}

template <typename T>
void UndoUpT(const PlaneLayout& l, std::uint8_t* pixels) {
  const std::size_t row_bytes = std::size_t{l.width} * l.bpp;
  const std::size_t n = row_bytes / sizeof(T);
  for (std::uint32_t v = 1; v < l.height; ++v) {
    T* cur = reinterpret_cast<T*>(pixels + v * row_bytes);
    const T* up = reinterpret_cast<const T*>(pixels + (v - 1) * row_bytes);
    for (std::size_t i = 0; i < n; ++i) cur[i] = static_cast<T>(cur[i] + up[i]);
  }
}

template <typename T>
void ApplyLeftT(const PlaneLayout& l, const std::uint8_t* src, std::size_t stride,
                std::uint8_t* dst) {
  const std::size_t row_bytes = std::size_t{l.width} * l.bpp;
  const std::size_t n = row_bytes / sizeof(T);
  const std::size_t c = l.bpp / sizeof(T);  // samples per pixel
  for (std::uint32_t v = 0; v < l.height; ++v) {
    const T* in = reinterpret_cast<const T*>(src + v * stride);
    T* out = reinterpret_cast<T*>(dst + v * row_bytes);
    for (std::size_t i = 0; i < c && i < n; ++i) out[i] = in[i];
    for (std::size_t i = c; i < n; ++i) out[i] = static_cast<T>(in[i] - in[i - c]);
  }
}

template <typename T>
void UndoLeftT(const PlaneLayout& l, std::uint8_t* pixels) {
  const std::size_t row_bytes = std::size_t{l.width} * l.bpp;
  const std::size_t n = row_bytes / sizeof(T);
  const std::size_t c = l.bpp / sizeof(T);
  for (std::uint32_t v = 0; v < l.height; ++v) {
    T* x = reinterpret_cast<T*>(pixels + v * row_bytes);
    for (std::size_t i = c; i < n; ++i) x[i] = static_cast<T>(x[i] + x[i - c]);
  }
}

template <typename View>
absl::Status CheckView(const View& view, std::string_view field) {
  if (view.rows != nullptr) {
    // Compress() reads rows `stride_bytes` apart; a row table is only made for frames received.
    return absl::InvalidArgumentError(
        absl::StrCat(std::string(field),
                     " has a row table (rows in scattered memory); compress an image "
                     "whose rows are stride_bytes apart"));
  }
  return ValidateView(view, kNoLimits, field);
}

}  // namespace

std::string_view Name(Predictor predictor) {
  switch (predictor) {
    case Predictor::kNone:
      return "none";
    case Predictor::kUp:
      return "up";
    case Predictor::kLeft:
      return "left";
  }
  return "?";
}

PlaneLayout LayoutOf(DisparityEncoding encoding, std::uint32_t width, std::uint32_t height) {
  const std::size_t bpp = BytesPerPixel(encoding);
  return PlaneLayout{width, height, bpp, bpp};
}

PlaneLayout LayoutOf(DepthEncoding encoding, std::uint32_t width, std::uint32_t height) {
  const std::size_t bpp = BytesPerPixel(encoding);
  return PlaneLayout{width, height, bpp, bpp};
}

PlaneLayout LayoutOf(ColorEncoding encoding, std::uint32_t width, std::uint32_t height) {
  return PlaneLayout{width, height, BytesPerPixel(encoding), 1};
}

PlaneLayout LayoutOf(const DisparityView& view) {
  return LayoutOf(view.encoding, view.width, view.height);
}

PlaneLayout LayoutOf(const DepthView& view) {
  return LayoutOf(view.encoding, view.width, view.height);
}

PlaneLayout LayoutOf(const ColorView& view) {
  return LayoutOf(view.encoding, view.width, view.height);
}

void ApplyPredictor(Predictor predictor, const PlaneLayout& layout, const void* src_bytes,
                    std::size_t src_stride, std::uint8_t* dst) {
  const auto* src = static_cast<const std::uint8_t*>(src_bytes);
  const std::size_t row_bytes = std::size_t{layout.width} * layout.bpp;
  switch (predictor) {
    case Predictor::kNone:
      for (std::uint32_t v = 0; v < layout.height; ++v) {
        std::memcpy(dst + v * row_bytes, src + v * src_stride, row_bytes);
      }
      return;
    case Predictor::kUp:
      if (layout.sample_bytes == 2) return ApplyUpT<U16>(layout, src, src_stride, dst);
      if (layout.sample_bytes == 4) return ApplyUpT<U32>(layout, src, src_stride, dst);
      return ApplyUpT<std::uint8_t>(layout, src, src_stride, dst);
    case Predictor::kLeft:
      if (layout.sample_bytes == 2) return ApplyLeftT<U16>(layout, src, src_stride, dst);
      if (layout.sample_bytes == 4) return ApplyLeftT<U32>(layout, src, src_stride, dst);
      return ApplyLeftT<std::uint8_t>(layout, src, src_stride, dst);
  }
}

void UndoPredictor(Predictor predictor, const PlaneLayout& layout, std::uint8_t* pixels) {
  switch (predictor) {
    case Predictor::kNone:
      return;
    case Predictor::kUp:
      if (layout.sample_bytes == 2) return UndoUpT<U16>(layout, pixels);
      if (layout.sample_bytes == 4) return UndoUpT<U32>(layout, pixels);
      return UndoUpT<std::uint8_t>(layout, pixels);
    case Predictor::kLeft:
      if (layout.sample_bytes == 2) return UndoLeftT<U16>(layout, pixels);
      if (layout.sample_bytes == 4) return UndoLeftT<U32>(layout, pixels);
      return UndoLeftT<std::uint8_t>(layout, pixels);
  }
}

// ---------------------------------------------------------------------------------------------

struct PlaneCompressor::Impl {
  ZSTD_CCtx* cctx = ZSTD_createCCtx();
  Buffer packed;  // predictor output (or packed rows)
  Buffer out;     // zstd output, then copied into the caller's string
  ~Impl() { ZSTD_freeCCtx(cctx); }
};

PlaneCompressor::PlaneCompressor() : impl_(std::make_unique<Impl>()) {}
PlaneCompressor::~PlaneCompressor() = default;

absl::Status PlaneCompressor::Compress(const DisparityView& view, Predictor predictor, int level,
                                       std::string_view field, std::string* out) {
  if (absl::Status s = CheckView(view, field); !s.ok()) return s;
  return Compress(view.data, view.stride_bytes, LayoutOf(view), predictor, level, out);
}

absl::Status PlaneCompressor::Compress(const DepthView& view, Predictor predictor, int level,
                                       std::string_view field, std::string* out) {
  if (absl::Status s = CheckView(view, field); !s.ok()) return s;
  return Compress(view.data, view.stride_bytes, LayoutOf(view), predictor, level, out);
}

absl::Status PlaneCompressor::Compress(const ColorView& view, Predictor predictor, int level,
                                       std::string_view field, std::string* out) {
  if (absl::Status s = CheckView(view, field); !s.ok()) return s;
  return Compress(view.data, view.stride_bytes, LayoutOf(view), predictor, level, out);
}

absl::Status PlaneCompressor::Compress(const void* data, std::size_t stride,
                                       const PlaneLayout& layout, Predictor predictor, int level,
                                       std::string* out) {
  const std::size_t bytes = layout.bytes();
  const std::size_t row_bytes = std::size_t{layout.width} * layout.bpp;
  const void* input = data;
  if (predictor != Predictor::kNone || stride != row_bytes) {
    std::uint8_t* packed = impl_->packed.Reserve(bytes);
    ApplyPredictor(predictor, layout, data, stride, packed);
    input = packed;
  }
  const std::size_t bound = ZSTD_compressBound(bytes);
  std::uint8_t* dst = impl_->out.Reserve(bound);
  ZSTD_CCtx_reset(impl_->cctx, ZSTD_reset_session_and_parameters);
  ZSTD_CCtx_setParameter(impl_->cctx, ZSTD_c_compressionLevel, level);
  ZSTD_CCtx_setParameter(impl_->cctx, ZSTD_c_contentSizeFlag, 1);
  ZSTD_CCtx_setParameter(impl_->cctx, ZSTD_c_checksumFlag, 1);
  const std::size_t n = ZSTD_compress2(impl_->cctx, dst, bound, input, bytes);
  if (ZSTD_isError(n)) {
    return absl::InternalError(absl::StrCat("zstd compression failed: ", ZSTD_getErrorName(n)));
  }
  out->assign(reinterpret_cast<const char*>(dst), n);
  return absl::OkStatus();
}

// ---------------------------------------------------------------------------------------------

struct PlaneDecompressor::Impl {
  ZSTD_DCtx* dctx = ZSTD_createDCtx();
  Buffer pixels;
  ~Impl() { ZSTD_freeDCtx(dctx); }
};

PlaneDecompressor::PlaneDecompressor() : impl_(std::make_unique<Impl>()) {}
PlaneDecompressor::~PlaneDecompressor() = default;

std::size_t PlaneDecompressor::capacity() const { return impl_->pixels.capacity(); }

absl::Status PlaneDecompressor::Decompress(std::string_view payload, const PlaneLayout& layout,
                                           Predictor predictor, std::string_view field,
                                           std::string_view what, const std::uint8_t** pixels) {
  const std::uint64_t expected = layout.bytes();
  auto mismatch = [&](std::uint64_t got) {
    return absl::InvalidArgumentError(
        absl::StrCat(S(field), " decompresses to ", got, " bytes; ", S(what), " needs ", expected));
  };
  if (payload.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(S(field), " is empty"));
  }
  // The header first: a bomb says here that it holds more than the image needs.
  const unsigned long long declared = ZSTD_getFrameContentSize(payload.data(), payload.size());
  if (declared == ZSTD_CONTENTSIZE_ERROR) {
    return absl::InvalidArgumentError(
        absl::StrCat(S(field), " is not a zstd frame (", payload.size(), " bytes)"));
  }
  if (declared == ZSTD_CONTENTSIZE_UNKNOWN) {
    return absl::InvalidArgumentError(
        absl::StrCat(S(field), " is a zstd frame that does not declare its content size; ", S(what),
                     " needs ", expected, " bytes declared"));
  }
  if (declared != expected) return mismatch(declared);
  // The content checksum (XXH64, about 0.05 ms a frame) is what catches a corrupt payload that
  // would otherwise decode to other pixels.
  ZSTD_frameHeader header;
  if (ZSTD_getFrameHeader(&header, payload.data(), payload.size()) != 0 ||
      header.frameType != ZSTD_frame || !header.checksumFlag) {
    return absl::InvalidArgumentError(absl::StrCat(
        S(field), " is a zstd frame without a content checksum; the checksum flag is required"));
  }
  // Then the block headers, still without decompressing: a truncated payload, or one with bytes
  // after its frame, is refused before the pixel buffer grows.
  const std::size_t frame_bytes = ZSTD_findFrameCompressedSize(payload.data(), payload.size());
  if (ZSTD_isError(frame_bytes)) {
    return absl::InvalidArgumentError(absl::StrCat(
        S(field), " is truncated or corrupt (zstd: ", ZSTD_getErrorName(frame_bytes), ")"));
  }
  if (frame_bytes != payload.size()) {
    return absl::InvalidArgumentError(absl::StrCat(S(field), " holds ", payload.size(),
                                                   " bytes, of which its zstd frame is ",
                                                   frame_bytes, "; it must be one frame alone"));
  }
  std::uint8_t* dst = impl_->pixels.Reserve(expected);
  const std::size_t n =
      ZSTD_decompressDCtx(impl_->dctx, dst, expected, payload.data(), payload.size());
  if (ZSTD_isError(n)) {
    return absl::InvalidArgumentError(
        absl::StrCat(S(field), " is corrupt (zstd: ", ZSTD_getErrorName(n), ")"));
  }
  if (n != expected) return mismatch(n);
  UndoPredictor(predictor, layout, dst);
  *pixels = dst;
  return absl::OkStatus();
}

}  // namespace cloudcast
