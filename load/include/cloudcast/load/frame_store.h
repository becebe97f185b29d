// The frames a load run sends, prepared once before it starts so that the generator's own cost
// (loading, encoding, serializing 1.2 MB) stays off the measurement.
//
// Each distinct frame is serialized once, as the tail of a StreamRequest{frame}: the Frame's
// frame_id and images, without its sequence and capture time. A send writes a few header bytes
// (the StreamRequest tag and length, then Frame.sequence and Frame.capture_time_unix_ns, fields 1
// and 2, which the wire format lets stand before the others) and points at the shared tail, so
// nothing large is copied or re-serialized per send.
//
// Video (--encoding h264): a bitstream's pictures reference the ones before them, so they cannot
// be replayed in any order. The store then holds one picture sequence, encoded once before the
// run by the client library's FrameEncoder (the robots' encoder, at the run's settings): it
// starts with an IDR and each stream plays it from its start, in order, returning to the start
// (an IDR) when it loops or when the server asks for a keyframe. Encoding live, per stream, would
// cost the generator an encoder's time for every frame of every stream (docs/load-testing.md
// measures both); the replay costs what a raw frame's does.
//
// Live video (--encoding h264 --rate-control): a replayed sequence cannot follow a rate
// controller's target, so each stream encodes its frames when it sends them, at its controller's
// bitrate (the fleet's driver owns a FrameEncoder per stream, as a robot does). The store then
// holds the raw frames for the encoders and each frame's lossless geometry as its tail; a send
// appends the pictures' fields to the tail (RequestWith). For a few robots: the encoders' time
// is the generator's.
#pragma once

#include <grpcpp/support/byte_buffer.h>
#include <grpcpp/support/slice.h>

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/sources/frame_source.h"
#include "cloudcast/sources/uplink.h"
#include "cloudcast/v1/cloudcast.pb.h"
#include "cloudcast/video/frame_encoder.h"

namespace cloudcast::load {

struct FrameSourceOptions {
  // The source (sources::OpenSource: one of them, or New Tsukuba when present, else the
  // synthetic scene at 640x480). One pass of a finite source is sent; the synthetic scene's
  // disparity is 16-bit here, as a camera's fixed-point disparity (so png and jpeg carry it).
  sources::SourceSpec source;
  // What the frames hold (--input): disparity + colour, depth + colour, or a stereo pair.
  sources::FrameKind kind = sources::FrameKind::kDisparity;
  // The camera of file sources; New Tsukuba's depth frames are computed with it.
  double focal = sources::SourceOptions{}.focal;
  double baseline = sources::SourceOptions{}.baseline;
  int synthetic_frames = 10;  // distinct synthetic frames (the camera moves from one to the next)
  // How the images travel. uplink.max_point_error (--max-point-error, metres, 0 = lossless)
  // quantizes each frame's disparity or depth (core/near_lossless.h) with the camera the server
  // will process that frame with: the stream's (stream_camera, required then), and for the
  // half-resolution levels their own, halved (client::HalfResolutionCamera over the stream's, as
  // the server applies Frame.camera). uplink.camera is filled from stream_camera here. The bound
  // needs disparity or depth frames and an encoding that compresses them (zstd, png, jpeg,
  // h264, the ladder); anything else is an InvalidArgument error naming --max-point-error.
  sources::UplinkOptions uplink;
  // The stream's camera as its StreamConfig will send it, made from the source's camera (the
  // flags over it). Given, Prepare calls it once the source is open and the store keeps it
  // (stream_camera()): the half-resolution levels get their camera from it at once.
  std::function<absl::StatusOr<v1::CameraModel>(const CameraModel& source)> stream_camera;
  // The adaptive sender's ladder (--rate-control): every frame also at each of these JPEG
  // qualities for its colour images (best first), its disparity or depth lossless (zstd with
  // row deltas). The stream picks a level per frame from its rate controller's target.
  std::vector<int> jpeg_ladder;
  // Below it, the same at half resolution (disparity and depth frames; with jpeg_ladder only):
  // every second pixel of the disparity or depth, its values unchanged, the colour averaged over
  // 2x2 pixels, and the frame's own camera (Frame.camera) halved to match once the stream's is
  // known (FrameStore::SetStreamCamera), so each point keeps its place and depth. A quarter of
  // the pixels, much the same cloud after the voxel grid. The floor when the link cannot carry
  // even the last full-resolution level (whose lossless disparity alone is about 14 KB).
  std::vector<int> half_resolution_ladder;
  // --encoding h264: the colour images (a stereo pair's both views) as H.264 pictures of one
  // sequence encoded before the run (the class comment); disparity and depth go lossless with
  // zstd (row deltas), `uplink`'s other settings apply.
  std::optional<video::FrameEncoderOptions> video;
  // With `video`: encode live, per stream (the class comment; --rate-control --encoding h264).
  bool live_video = false;
};

// A live video store's raw material (FrameSourceOptions::live_video).
struct LiveVideo {
  std::vector<sources::SourceFrame> originals;  // the source's frames, owned
  sources::UplinkOptions raw;                   // how the encoder takes them (raw images)
  video::FrameEncoderOptions encoder;           // each stream's encoder
  std::string settings;  // e.g. "veryfast crf 18 <= 8 Mbit/s, colour 4:2:0, IDR every 60"
};

// The picture sequence of a video store.
struct VideoSequence {
  // Its length in frames: the source's frames, cycled, up to a whole number of keyframe
  // intervals (60 frames with --h264-keyframe-interval 0), at most kMaxVideoSequence unless the
  // source has more frames.
  std::size_t length = 0;
  std::size_t source_frames = 0;  // distinct frames of the source in it
  std::vector<bool> keyframe;     // per frame: its pictures are IDRs (frame 0 always)
  std::string settings;           // e.g. "veryfast crf 18 <= 8 Mbit/s, colour 4:2:0, IDR every 60"
  // The encoder's cost when the sequence was made: thread CPU ms per frame (both views of a
  // pair), median and mean over the sequence; and the access unit bytes per frame, mean.
  double encode_ms_median = 0, encode_ms_mean = 0;
  double video_bytes_mean = 0;
};
inline constexpr std::size_t kMaxVideoSequence = 300;

// What --max-point-error saved, measured when the store was prepared: each frame's disparity or
// depth was also encoded without the bound. Bytes are means per distinct frame.
struct NearLosslessSummary {
  double max_point_error = 0;  // metres
  std::string geometry;        // "disparity" or "depth"
  // The geometry's bytes in a full-resolution frame (the field as serialized), with the bound
  // and without; and the whole request's (level 0 of a ladder), with and without.
  double geometry_bytes = 0, geometry_bytes_lossless = 0;
  double request_bytes = 0, request_bytes_lossless = 0;
  // The half-resolution levels' geometry, with and without (0: no such levels).
  double half_geometry_bytes = 0, half_geometry_bytes_lossless = 0;
  // Over every quantized map (each resolution): pixels that give a point, and of those, the
  // values the quantizer replaced.
  std::uint64_t values = 0, changed = 0;
};

class FrameStore {
 public:
  // Loads, encodes and serializes every frame. Errors name the flag or the file.
  static absl::StatusOr<FrameStore> Prepare(const FrameSourceOptions& options);

  // Frames made by the caller (tests): each serialized as it is, sequence and time ignored.
  static FrameStore FromFrames(const std::vector<v1::Frame>& frames, const CameraModel& camera,
                               const std::string& description);
  // A video store of frames made by the caller (tests): their pictures in the order given, the
  // first an IDR (else an error), sent as the sequence of a video store.
  static absl::StatusOr<FrameStore> FromVideoFrames(const std::vector<v1::Frame>& frames,
                                                    const CameraModel& camera,
                                                    const std::string& description);

  std::size_t size() const { return levels_.front().size(); }
  // The bytes of frame `index % size()` on the wire, sequence and time patched in, at `level`
  // of the ladder (0: the best, and the only one without a ladder). Only a small header slice is
  // new; the image bytes are shared with every other send of that frame.
  grpc::ByteBuffer Request(std::size_t index, std::uint64_t sequence,
                           std::int64_t capture_time_unix_ns, std::size_t level = 0) const;
  // The same with `fields` after the tail: more of the Frame's fields, serialized (a live video
  // frame's pictures), which the wire format merges into the one Frame.
  grpc::ByteBuffer RequestWith(std::size_t index, std::uint64_t sequence,
                               std::int64_t capture_time_unix_ns, const std::string& fields) const;
  // The ladder: its levels (1 without one), and the best level whose frames average at most
  // `budget_bytes` (the last, smallest, when none does).
  std::size_t levels() const { return levels_.size(); }
  std::size_t LevelFor(double budget_bytes) const;
  double MeanRequestBytes(std::size_t level) const;
  // The request's size in bytes (about the same for every send of that frame).
  std::size_t RequestBytes(std::size_t index) const;
  double MeanRequestBytes() const;

  // The camera the frames were made with (the StreamConfig's camera section).
  const CameraModel& camera() const { return camera_; }
  // The stream's camera as the config sends it: the half-resolution levels (if any) get it
  // halved as their frames' own camera. Call before the first Request, or give
  // FrameSourceOptions::stream_camera instead. A store prepared with a stream camera takes only
  // that one again (its near-lossless frames were quantized for it): FailedPrecondition.
  absl::Status SetStreamCamera(const v1::CameraModel& stream);
  // The stream camera given (FrameSourceOptions::stream_camera or SetStreamCamera), if any.
  const std::optional<v1::CameraModel>& stream_camera() const { return stream_camera_; }
  // With uplink.max_point_error > 0: what the bound saved.
  const std::optional<NearLosslessSummary>& near_lossless() const { return near_lossless_; }
  // What the frames hold.
  sources::FrameKind kind() const { return kind_; }
  // A video store (FrameSourceOptions::video): frame i is picture i of the sequence, to be sent
  // in order from 0 (an IDR) on each stream. None: any frame may go at any time.
  const std::optional<VideoSequence>& video() const { return video_; }
  // A live video store (FrameSourceOptions::live_video): frame i's raw images are
  // live_video()->originals[i], its tail (RequestBytes) the geometry sent beside the pictures.
  const std::optional<LiveVideo>& live_video() const { return live_video_; }
  // The encoding's name: "raw", "zstd", "png", "jpeg", "h264", "adaptive" (the JPEG ladder).
  const std::string& encoding() const { return encoding_; }
  // e.g. "New Tsukuba (10 stereo frames, 640x480), raw, 1200 KB per frame".
  const std::string& description() const { return description_; }

 private:
  struct Savings;  // what the bound saved, added up while preparing

  FrameStore() = default;
  void AddTail(const v1::Frame& frame, std::size_t level = 0);
  absl::Status PrepareVideo(const FrameSourceOptions& options,
                            const sources::UplinkOptions& uplink, sources::FrameSource& source,
                            std::uint64_t frames, Savings* savings);
  // A video frame's geometry (zstd, lossless or within the bound: `zstd`'s), its frame id set,
  // what the bound saved added to `savings`; the pictures go beside it.
  static absl::Status VideoGeometry(const sources::SourceFrame& original,
                                    const sources::UplinkOptions& zstd, Savings* savings,
                                    sources::UplinkFrame* scratch, v1::Frame* frame);
  absl::Status PrepareLiveVideo(const FrameSourceOptions& options,
                                const sources::UplinkOptions& uplink, sources::FrameSource& source,
                                std::uint64_t frames, Savings* savings);
  // The half-resolution levels' own camera: the stream camera's, halved (needs stream_camera_).
  v1::CameraModel HalfCamera() const;

  // Per level, owned strings, so their slices can be static (no refcount, no copy) for the
  // store's life.
  std::vector<std::vector<std::shared_ptr<const std::string>>> levels_{1};
  std::size_t first_half_level_ = 0;  // 0: no half-resolution levels
  CameraModel camera_;
  sources::FrameKind kind_ = sources::FrameKind::kDisparity;
  std::string description_;
  std::string encoding_;
  std::optional<VideoSequence> video_;
  std::optional<LiveVideo> live_video_;
  std::optional<v1::CameraModel> stream_camera_;
  std::optional<NearLosslessSummary> near_lossless_;
};

// e.g. "near-lossless <= 0.03 m a point: disparity 9.1 KB a frame (lossless 14.0 KB), 61% of
// its values changed".
std::string Describe(const NearLosslessSummary& summary);

// The Frame fields, serialized, that hold the pictures video::FrameEncoder made of a frame
// (its colour image's, and a stereo pair's right view's): what a live video send appends to the
// frame's tail (FrameStore::RequestWith).
absl::StatusOr<std::string> PictureFields(const client::FrameInput& coded);

// The wire bytes of a StreamRequest holding `config` (the first message of every stream).
grpc::ByteBuffer SerializeConfig(const v1::StreamConfig& config);

}  // namespace cloudcast::load
