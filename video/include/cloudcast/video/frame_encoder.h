// The client's side of the video uplink: a stream's frames in, the same frames out with their
// colour image (and a stereo pair's right image) as H.264 pictures (client::PrecodedVideo, the
// proto's VideoPicture). One encoder per bitstream, kept from frame to frame, so it must see every
// frame the stream sends, in order; the server's replies come back through OnResult, which turns
// its keyframe requests into an IDR on the next frame. Disparity and depth maps pass through
// untouched (they stay lossless).
//
//   video::FrameEncoder encoder(options);
//   for (...) {
//     auto frame = encoder.Encode(raw_frame, sequence);  // views this encoder's pictures
//     stream->Send(*frame, meta_with_that_sequence);
//   }
//   // on each Result: encoder.OnResult(result);
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/client/frame.h"
#include "cloudcast/client/frame_coder.h"
#include "cloudcast/client/result.h"
#include "cloudcast/io/image_io.h"
#include "cloudcast/v1/cloudcast.pb.h"
#include "cloudcast/video/encoder.h"

namespace cloudcast::video {

struct FrameEncoderOptions {
  // The encoder's settings (preset, crf, bitrate_bps, fps, keyframe_interval, intra_refresh,
  // threads, x264_params, limits). kind, width, height and refs are set per bitstream: a grey
  // image (kMono8) is coded grey (4:0:0); a colour one as `colour_kind` (kColour: 4:2:0, or
  // kColour444, which docs/video.md found a 38 dB colour target needs).
  EncoderOptions encoder;
  PictureKind colour_kind = PictureKind::kColour;
  // Stereo pairs: the right view as the picture after its left view in one bitstream
  // (VIDEO_LAYOUT_INTERLEAVED, with two reference frames), the layout docs/video.md measured
  // best; false: a bitstream per view.
  bool interleave_stereo = true;
  // Every image coded grey (4:0:0, luma as the server's matchers compute it): what a stereo
  // pair's matching reads, in fewer bits than colour (docs/video.md measures pairs so); the
  // points' colours are then grey.
  bool grey = false;
};

// "h264" (the --encoding flags' name for this).
inline constexpr std::string_view kH264 = "h264";

// Encode on one thread; OnResult, RequestKeyframe and SetBitrate from any (a receiving thread):
// they wait for an Encode in progress.
class FrameEncoder : public client::FrameCoder {
 public:
  explicit FrameEncoder(FrameEncoderOptions options);
  ~FrameEncoder() override;
  FrameEncoder(const FrameEncoder&) = delete;
  FrameEncoder& operator=(const FrameEncoder&) = delete;

  // Encodes `input`'s colour image (a stereo pair's left and right) into pictures this encoder
  // holds until the next call; the frame returned views them (client::PrecodedVideo) and `input`'s
  // other images. `sequence`: the sequence the frame is sent with (Result::sequence), so that
  // keyframe requests about frames sent before an IDR do not ask for another. The images must be
  // raw (ColorView, or BgraView); a size change starts new bitstreams at an IDR. Errors name the
  // image ("colour", "left", "right").
  absl::StatusOr<client::FrameInput> Encode(const client::FrameInput& input,
                                            std::uint64_t sequence) override;

  // A reply (cloud or FrameError): its keyframe_needed (Result::keyframe_needed) makes the next
  // picture of each bitstream named an IDR, unless one was sent since the frame it answers; a
  // reply that names none asks for nothing (the server decodes every picture as it reads it,
  // whatever becomes of the frame). A frame encoded but never decoded by the server (replaced
  // after encoding, when the application sends the pictures itself to a DELIVERY_LATEST stream;
  // lost or unsent when its stream ended) gets an IDR on every bitstream, under the same rule. A
  // frame the server skipped (kDropped) asks for nothing: it decoded its pictures all the same.
  // As a stream's coder (StreamOptions::coder) the stream calls it.
  void OnResult(const client::Result& result) override;
  // The next frame's pictures are IDRs (a late joiner, a new stream after a reconnect).
  void RequestKeyframe();
  // The bitrate from the next frame on, for both views together (a rate controller's).
  void SetBitrate(std::int64_t bits_per_second);
  // As a stream's coder with rate control: the pictures get the stream's target less the other
  // images' bytes at the encoder's frame rate (a lossless disparity map is sent whatever the
  // link), at least a tenth of the target and 2 kbit per frame, at most the encoder's own
  // bitrate_bps (the cap it was opened with).
  void SetStreamBitrate(std::int64_t stream_bps, std::size_t other_bytes_per_frame) override;

  std::uint64_t keyframes_sent() const;
  std::uint64_t keyframes_requested() const;  // honoured ones
  // The access unit bytes of the last frame (both views).
  std::uint64_t last_bytes() const;

 private:
  struct Bitstream;
  absl::Status EncodePicture(const ColorView& view, const char* field, bool stereo, Bitstream* b,
                             v1::VideoPicture* out);

  const FrameEncoderOptions options_;
  mutable std::mutex mu_;  // everything below
  std::unique_ptr<Bitstream> colour_, right_;
  v1::VideoPicture colour_picture_, right_picture_;
  OwnedColor grey_colour_, grey_right_;  // options.grey: the images converted
  std::int64_t bitrate_bps_ = 0;         // a pending SetBitrate, 0: none
  std::uint64_t keyframes_sent_ = 0;
  std::uint64_t keyframes_requested_ = 0;
  std::uint64_t last_bytes_ = 0;
};

}  // namespace cloudcast::video
