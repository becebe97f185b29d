// The proto boundary: the one place where the contract (cloudcast/v1/cloudcast.proto) meets the
// engine's types. Server, client library, viewer and load generator all convert through here:
//   - every enum and config mapping, in both directions;
//   - building a Frame's raw images from core image views, and core views from a Frame;
//   - validation of what a client sent, delegating to the core's field checks with the proto
//     field path, so each message is worded once and names the field the client set;
//   - FrameError <-> absl::Status, carrying the error's kind.
// Nothing outside this module rewrites or parses an error message.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/core/filters.h"
#include "cloudcast/core/frame_codec.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/limits.h"
#include "cloudcast/core/pipeline.h"
#include "cloudcast/core/settings.h"
#include "cloudcast/core/stereo.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace cloudcast::convert {

// The revision of cloudcast.proto this code speaks (ServerInfo.contract_revision); each one is
// described in docs/migration.md.
inline constexpr char kContractRevision[] = "5";

// ---------------------------------------------------------------------------------------------
// Delivery: how a stream treats frames that arrive faster than they are processed.

enum class Delivery : std::uint8_t {
  kLatest,  // real time: a newer frame replaces an older one still waiting
  kAll,     // lossless: gRPC flow control slows the client down
};
std::string_view Name(Delivery delivery);  // "latest" / "all"
bool ParseDelivery(std::string_view name, Delivery* out);

// ---------------------------------------------------------------------------------------------
// Enums. ToProto never fails. FromProto takes the field path for its message: the UNSPECIFIED
// value leaves *out alone (the caller's default) where the proto gives it that meaning, and is
// an error for image encodings.

v1::Axis ToProto(Axis axis);
v1::DisparityEncoding ToProto(DisparityEncoding encoding);
v1::DepthEncoding ToProto(DepthEncoding encoding);
v1::ColorEncoding ToProto(ColorEncoding encoding);
v1::DeliveryMode ToProto(Delivery delivery);
v1::StereoMatcher ToProto(StereoMatcher matcher);
absl::Status FromProto(v1::Axis axis, std::string_view field, Axis* out);
absl::Status FromProto(v1::DisparityEncoding encoding, std::string_view field,
                       DisparityEncoding* out);
absl::Status FromProto(v1::DepthEncoding encoding, std::string_view field, DepthEncoding* out);
absl::Status FromProto(v1::ColorEncoding encoding, std::string_view field, ColorEncoding* out);
absl::Status FromProto(v1::DeliveryMode mode, std::string_view field, Delivery* out);
absl::Status FromProto(v1::StereoMatcher matcher, std::string_view field, StereoMatcher* out);

// ---------------------------------------------------------------------------------------------
// Stream configuration.

// A StreamConfig resolved against defaults: everything a frame on that stream needs.
struct StreamSettings {
  FrameSettings frame;
  Delivery delivery = Delivery::kLatest;
};

// Resolves `config` field by field against `defaults`: a set field wins, an unset one keeps the
// default (a StreamConfig replaces the previous one whole, so `defaults` are the server's, never
// an earlier config's). Every value set is checked as it is read; an error is INVALID_ARGUMENT and
// names the field by its proto path under `field` (e.g. "config.voxel_grid.leaf must be finite
// and > 0 ..."). `defaults.frame.pipeline.limits` carry over as they are.
absl::StatusOr<StreamSettings> Resolve(const v1::StreamConfig& config,
                                       const StreamSettings& defaults,
                                       std::string_view field = "config");

// The contract's defaults, what a server starts from before its operator's flags: no camera (a
// client must give fx, and a baseline for disparities; see RequireCamera), no passthrough (its
// limits the lowest and highest floats), the core's voxel grid, Draco and stereo defaults.
StreamSettings ContractDefaults();

// Applies a CameraModel's set fields to `settings` (Resolve's camera section), checked, errors
// naming the fields under `field`: for a Frame's own camera, "frame.camera".
absl::Status ApplyCamera(const v1::CameraModel& camera, std::string_view field,
                         FrameSettings* settings);

// Whether `settings` have the camera a frame with `geometry` needs: fx always, and a baseline
// for disparity maps and uncalibrated stereo pairs (a calibration gives both for a pair).
// Otherwise INVALID_ARGUMENT naming `field`.fx or `field`.baseline with the reason REQUIRED.
absl::Status RequireCamera(const FrameSettings& settings, v1::Frame::GeometryCase geometry,
                           std::string_view field = "config.camera");

// Every field of a StreamConfig filled from `settings` (GetInfo's defaults); cx and cy only when
// they are set, since unset they follow each frame's size. max_position_error is the bound these
// settings' leaf gives.
v1::StreamConfig ToProto(const StreamSettings& settings);

// Each fills one section of `config` from a core struct, every field of it set (cx and cy
// included, so the principal point is the struct's), leaving the other sections alone.
void SetCamera(const CameraModel& camera, v1::StreamConfig* config);
void SetPassThrough(const PassThroughParams& params, v1::StreamConfig* config);
void SetVoxelGrid(const VoxelGridParams& params, v1::StreamConfig* config);
// max_position_error 0 (the DracoOptions default) stays unset: the server then uses a quarter of
// the voxel leaf, as the core does.
void SetDraco(const DracoOptions& options, v1::StreamConfig* config);
// Every matcher field, return_disparity, and the calibration when it has one.
void SetStereo(const StereoParams& params, v1::StreamConfig* config);
// A StreamConfig holding preset `name`'s camera (the principal point left to each frame's
// centre) and passthrough (cloudcast/core/settings.h, ApplyPreset); the other sections unset.
// INVALID_ARGUMENT naming `field` for an unknown name.
absl::StatusOr<v1::StreamConfig> PresetConfig(std::string_view name,
                                              std::string_view field = "preset");
// Camera, passthrough and voxel grid of `options` (its limits are the server's business).
// Draco and delivery stay at the server defaults.
v1::StreamConfig MakeStreamConfig(const PipelineOptions& options);

// ---------------------------------------------------------------------------------------------
// Frames.

// Copies a view's rows into `raw`, packed tightly (row_stride 0) whatever the view's stride. The
// view is checked for memory safety only (sizes and limits are the server's to judge); errors
// name it under `field`. `raw`'s pixel buffer keeps its capacity from frame to frame.
absl::Status ToProto(const DisparityView& view, std::string_view field, v1::RawDisparity* raw);
absl::Status ToProto(const DepthView& view, std::string_view field, v1::RawDepth* raw);
absl::Status ToProto(const ColorView& view, std::string_view field, v1::RawColor* raw);
// The same, in two steps, for a sender that writes the pixels itself (the client library, straight
// into a gRPC slice, so that they are copied once): ToProtoWithoutPixels checks the view and fills
// every field of `raw` but `pixels`, which it clears; PackRows writes PackedBytes(view) bytes of
// tightly packed rows to `out`.
absl::Status ToProtoWithoutPixels(const DisparityView& view, std::string_view field,
                                  v1::RawDisparity* raw);
absl::Status ToProtoWithoutPixels(const DepthView& view, std::string_view field, v1::RawDepth* raw);
absl::Status ToProtoWithoutPixels(const ColorView& view, std::string_view field, v1::RawColor* raw);
std::size_t PackedBytes(const DisparityView& view);
std::size_t PackedBytes(const DepthView& view);
std::size_t PackedBytes(const ColorView& view);
void PackRows(const DisparityView& view, void* out);
void PackRows(const DepthView& view, void* out);
void PackRows(const ColorView& view, void* out);
// Four-channel B, G, R, A rows (an OpenCV CV_8UC4 Mat) sent as BGR8, dropping the alpha while the
// rows are copied: the protocol has no BGRA encoding, and the server ignores alpha anyway.
absl::Status BgraToProto(const void* data, std::size_t size_bytes, std::uint32_t width,
                         std::uint32_t height, std::size_t stride_bytes, std::string_view field,
                         v1::RawColor* raw);

// Views of a raw image in place (no copy: the view points into `raw`'s bytes), checked against
// `limits`. Errors name the field under `field` (e.g. "frame.disparity.raw.row_stride is 100,
// less than width x 1 = 640"): INVALID_ARGUMENT when malformed, RESOURCE_EXHAUSTED over a limit.
absl::Status ViewRaw(const v1::RawDisparity& raw, std::string_view field, const Limits& limits,
                     DisparityView* view);
absl::Status ViewRaw(const v1::RawDepth& raw, std::string_view field, const Limits& limits,
                     DepthView* view);
absl::Status ViewRaw(const v1::RawColor& raw, std::string_view field, const Limits& limits,
                     ColorView* view);
// The same for an image whose pixel bytes were kept apart from the message (the server leaves
// them in the buffers gRPC received them in): `pixels` gives where they start and how many there
// are, and is what the checks measure. When the bytes are in pieces, the caller then points
// view->rows at the rows (ImageView::rows); view->data is only the first piece.
absl::Status ViewRaw(const v1::RawDisparity& raw, std::string_view pixels, std::string_view field,
                     const Limits& limits, DisparityView* view);
absl::Status ViewRaw(const v1::RawDepth& raw, std::string_view pixels, std::string_view field,
                     const Limits& limits, DepthView* view);
absl::Status ViewRaw(const v1::RawColor& raw, std::string_view pixels, std::string_view field,
                     const Limits& limits, ColorView* view);

// Compressed raw images (CompressedDisparity / CompressedColor): see the proto for the format.

// How a client compresses a raw view.
struct Compression {
  v1::Compression codec = v1::COMPRESSION_ZSTD_DELTA_ROWS;  // the default, by the uplink table
  int level = kDefaultCompressionLevel;                     // zstd's level
};
// The predictor of a compression; INVALID_ARGUMENT naming `field` for an unknown one.
absl::Status FromProto(v1::Compression compression, std::string_view field, Predictor* out);
// Every compression the server accepts, for GetInfo.
const std::vector<v1::Compression>& AcceptedCompressions();

// Compresses a view into `out` (its payload buffer keeps its capacity). The view is checked for
// memory safety only, naming it under `field`. `compressor` null: one kept per thread.
absl::Status ToProto(const DisparityView& view, const Compression& compression,
                     std::string_view field, v1::CompressedDisparity* out,
                     PlaneCompressor* compressor = nullptr);
absl::Status ToProto(const DepthView& view, const Compression& compression, std::string_view field,
                     v1::CompressedDepth* out, PlaneCompressor* compressor = nullptr);
absl::Status ToProto(const ColorView& view, const Compression& compression, std::string_view field,
                     v1::CompressedColor* out, PlaneCompressor* compressor = nullptr);

// Decompresses into `decompressor`'s buffer and views it (packed rows, valid until its next
// use). Every header field is checked first, then the payload against the size they give, before
// anything is allocated (PlaneDecompressor::Decompress). Errors name the field under `field`
// (e.g. "frame.disparity.compressed.payload ..."): INVALID_ARGUMENT when malformed (unknown
// enums, zero size, a payload that is not exactly the image), RESOURCE_EXHAUSTED over a limit.
absl::Status DecodeCompressed(const v1::CompressedDisparity& compressed, std::string_view field,
                              const Limits& limits, PlaneDecompressor* decompressor,
                              DisparityView* view);
absl::Status DecodeCompressed(const v1::CompressedDepth& compressed, std::string_view field,
                              const Limits& limits, PlaneDecompressor* decompressor,
                              DepthView* view);
absl::Status DecodeCompressed(const v1::CompressedColor& compressed, std::string_view field,
                              const Limits& limits, PlaneDecompressor* decompressor,
                              ColorView* view);

// ---------------------------------------------------------------------------------------------
// Errors.

// `error` from a status: its code and message, its kind, what it answers, and its
// FieldViolation (bad_request; fallback field "frame", "config" or "kind" by `kind`).
// frames_dropped and server_instance are left to the caller.
void FillError(const absl::Status& status, v1::ErrorKind kind, std::uint64_t sequence,
               const std::string& frame_id, v1::FrameError* error);
// The structured form of an error, FieldViolation: its field path and its rule (reason).
// Messages name their field first (core/checks.h), so the path is the message's first word when
// it is a dotted path or one word before a colon ("frame: ..."), unless the status carries one
// (RequiredError); a message that starts otherwise gets `fallback_field`. The reason: REQUIRED (RequiredError), OVER_LIMIT (RESOURCE_EXHAUSTED) or
// INVALID.
v1::FieldViolation FieldViolationOf(const absl::Status& status, std::string_view fallback_field);
// INVALID_ARGUMENT for a field that is needed and not set: its FieldViolation names `field` with
// the reason REQUIRED.
absl::Status RequiredError(std::string_view field, std::string_view message);
// A call status's details (grpc::Status error_details, sent as grpc-status-details-bin): a
// google.rpc.Status holding the status's code and message and a google.rpc.BadRequest with its
// FieldViolation.
std::string StatusDetails(const absl::Status& status, std::string_view fallback_field);
// The BadRequest in a call status's details, for clients and tests; false when there is none.
bool ParseStatusDetails(const std::string& details, v1::BadRequest* out);

// The status a FrameError carries, with its FieldViolation (FieldViolationOf gives it back). An
// out-of-range code becomes UNKNOWN.
absl::Status ToStatus(const v1::FrameError& error);
// Whether a FrameError answers a request other than a frame (a StreamConfig, or a request with
// neither a config nor a frame). A server older than FrameError.kind leaves it unset: a frame.
bool AnswersNoFrame(const v1::FrameError& error);

}  // namespace cloudcast::convert
