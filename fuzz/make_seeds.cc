// Writes the fuzzers' seed corpora (fuzz/corpus/<harness>/): tiny valid inputs of every kind each
// harness reads, a few KB each, made with the project's own writers (convert, frame_codec,
// EncodeDraco, SaveCloud) and OpenCV's encoders. Deterministic: run again, same bytes.
//   make_seeds <fuzz/corpus folder>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "cloudcast/core/draco_codec.h"
#include "cloudcast/core/frame_codec.h"
#include "cloudcast/io/cloud_io.h"
#include "cloudcast/proto/convert.h"
#include "cloudcast/video/encoder.h"
#include "cloudcast/video/rvl.h"
#include "cloudcast/v1/cloudcast.pb.h"

using namespace cloudcast;
namespace fs = std::filesystem;

namespace {

fs::path g_root;

void Write(const std::string& harness, const std::string& name, const std::string& bytes) {
  const fs::path dir = g_root / harness;
  fs::create_directories(dir);
  std::ofstream(dir / name, std::ios::binary) << bytes;
}

void Check(const absl::Status& s) {
  if (!s.ok()) {
    std::cerr << "make_seeds: " << s << "\n";
    std::exit(1);
  }
}

// A 16 x 12 scene: disparities 51..205 (z = 615 / d in [3, 12], inside the paper's passthrough),
// a few invalid (0) pixels, colour a gradient.
constexpr std::uint32_t kW = 16, kH = 12;

cv::Mat DisparityU8() {
  cv::Mat m(kH, kW, CV_8UC1);
  for (std::uint32_t v = 0; v < kH; ++v)
    for (std::uint32_t u = 0; u < kW; ++u)
      m.at<std::uint8_t>(v, u) = (u + v) % 7 == 0 ? 0 : 51 + (u * 9 + v * 3) % 150;
  return m;
}
cv::Mat DisparityU16() {
  cv::Mat m;
  DisparityU8().convertTo(m, CV_16U, 16.0);  // 1/16 fixed point, as stereo matchers write it
  return m;
}
cv::Mat DisparityF32() {
  cv::Mat m;
  DisparityU8().convertTo(m, CV_32F, 1.0);
  m.at<float>(0, 1) = NAN;
  return m;
}
cv::Mat ColourBgr() {
  cv::Mat m(kH, kW, CV_8UC3);
  for (std::uint32_t v = 0; v < kH; ++v)
    for (std::uint32_t u = 0; u < kW; ++u) m.at<cv::Vec3b>(v, u) = cv::Vec3b(u * 16, v * 20, 200);
  return m;
}
cv::Mat ColourBgra() {
  cv::Mat m(kH, kW, CV_8UC4);
  for (std::uint32_t v = 0; v < kH; ++v)
    for (std::uint32_t u = 0; u < kW; ++u)
      m.at<cv::Vec4b>(v, u) = cv::Vec4b(u * 16, v * 20, 200, u * 10);
  return m;
}
cv::Mat Grey() {
  cv::Mat m(kH, kW, CV_8UC1);
  for (std::uint32_t v = 0; v < kH; ++v)
    for (std::uint32_t u = 0; u < kW; ++u) m.at<std::uint8_t>(v, u) = u * 8 + v;
  return m;
}

// A depth image of the scene in millimetres (ROS 16UC1): 3 to 12 m, the same invalid pixels.
cv::Mat DepthU16() {
  const cv::Mat d = DisparityU8();
  cv::Mat m(kH, kW, CV_16UC1);
  for (std::uint32_t v = 0; v < kH; ++v)
    for (std::uint32_t u = 0; u < kW; ++u) {
      const int disparity = d.at<std::uint8_t>(v, u);
      m.at<std::uint16_t>(v, u) = disparity == 0 ? 0 : 615000 / disparity;
    }
  return m;
}
// A stereo pair: a textured view `shift` pixels along (the right view is the left one's texture
// 4 pixels on: disparity 4 everywhere), wide enough for the smallest search (16 disparities).
constexpr std::uint32_t kStereoW = 40;
cv::Mat StereoView(std::uint32_t shift, int type) {
  cv::Mat grey(kH, kStereoW, CV_8UC1);
  for (std::uint32_t v = 0; v < kH; ++v)
    for (std::uint32_t u = 0; u < kStereoW; ++u)
      grey.at<std::uint8_t>(v, u) = (((u + shift) * 73 + v * 151) * 2654435761u) >> 24;
  if (type == CV_8UC1) return grey;
  cv::Mat bgr(kH, kStereoW, CV_8UC3);
  for (std::uint32_t v = 0; v < kH; ++v)
    for (std::uint32_t u = 0; u < kStereoW; ++u) {
      const std::uint8_t g = grey.at<std::uint8_t>(v, u);
      bgr.at<cv::Vec3b>(v, u) = cv::Vec3b(g, 255 - g, g / 2);
    }
  return bgr;
}

std::string Encode(const std::string& ext, const cv::Mat& m, std::vector<int> params = {}) {
  std::vector<std::uint8_t> out;
  if (!cv::imencode(ext, m, out, params)) {
    std::cerr << "make_seeds: imencode " << ext << " failed\n";
    std::exit(1);
  }
  return std::string(out.begin(), out.end());
}

template <typename Encoding>
ImageView<Encoding> View(const cv::Mat& m, Encoding e) {
  ImageView<Encoding> v;
  v.data = m.data;
  v.size_bytes = m.step[0] * m.rows;
  v.width = m.cols;
  v.height = m.rows;
  v.stride_bytes = m.step[0];
  v.encoding = e;
  return v;
}

// Frames, each image as raw / encoded / compressed.
enum class As { kRaw, kEncoded, kCompressed };

// An empty frame named after its sequence number.
v1::Frame NumberedFrame(std::uint64_t sequence) {
  v1::Frame f;
  f.set_sequence(sequence);
  f.set_frame_id("seed-" + std::to_string(sequence));
  return f;
}

v1::Frame MakeFrame(As disparity_as, const cv::Mat& disparity, DisparityEncoding de, As colour_as,
                    const cv::Mat& colour, ColorEncoding ce, v1::Compression codec,
                    std::uint64_t sequence) {
  v1::Frame f = NumberedFrame(sequence);
  f.set_capture_time_unix_ns(1'700'000'000'000'000'000 + sequence);
  const convert::Compression compression{codec, 1};
  switch (disparity_as) {
    case As::kRaw:
      Check(convert::ToProto(View(disparity, de), "d", f.mutable_disparity()->mutable_raw()));
      break;
    case As::kEncoded:
      f.mutable_disparity()->set_encoded(Encode(".png", disparity));
      break;
    case As::kCompressed:
      Check(convert::ToProto(View(disparity, de), compression, "d",
                             f.mutable_disparity()->mutable_compressed()));
      break;
  }
  switch (colour_as) {
    case As::kRaw:
      Check(convert::ToProto(View(colour, ce), "c", f.mutable_color()->mutable_raw()));
      break;
    case As::kEncoded:
      f.mutable_color()->set_encoded(Encode(".png", colour));
      break;
    case As::kCompressed:
      Check(convert::ToProto(View(colour, ce), compression, "c",
                             f.mutable_color()->mutable_compressed()));
      break;
  }
  return f;
}

// A frame whose depth comes from a depth image (raw or zstd) or a stereo pair (raw, or zstd
// with the colour of the left view), with a colour image of the same size.
v1::Frame DepthFrame(As depth_as, const cv::Mat& depth, DepthEncoding encoding,
                     std::uint64_t sequence) {
  v1::Frame f = NumberedFrame(sequence);
  const DepthView view = View(depth, encoding);
  if (depth_as == As::kRaw) {
    Check(convert::ToProto(view, "depth", f.mutable_depth()->mutable_raw()));
  } else {
    Check(convert::ToProto(view, convert::Compression{v1::COMPRESSION_ZSTD_DELTA_LEFT, 1}, "depth",
                           f.mutable_depth()->mutable_compressed()));
  }
  Check(convert::ToProto(View(ColourBgr(), ColorEncoding::kBGR8), "c",
                         f.mutable_color()->mutable_raw()));
  return f;
}
v1::Frame StereoFrame(As as, int type, std::uint64_t sequence) {
  v1::Frame f = NumberedFrame(sequence);
  const ColorEncoding e = type == CV_8UC1 ? ColorEncoding::kMono8 : ColorEncoding::kBGR8;
  const cv::Mat left = StereoView(0, type), right = StereoView(4, type);
  const convert::Compression zstd{v1::COMPRESSION_ZSTD_DELTA_ROWS, 1};
  if (as == As::kRaw) {
    Check(convert::ToProto(View(left, e), "c", f.mutable_color()->mutable_raw()));
    Check(convert::ToProto(View(right, e), "r", f.mutable_right()->mutable_raw()));
  } else {
    Check(convert::ToProto(View(left, e), zstd, "c", f.mutable_color()->mutable_compressed()));
    Check(convert::ToProto(View(right, e), zstd, "r", f.mutable_right()->mutable_compressed()));
  }
  return f;
}

// The smallest search, so that the seeds' pairs are wide enough for it, and a camera that puts
// their disparity of 4 at z = 30 * 0.4 / 4 = 3, inside the default passthrough.
v1::StreamConfig StereoConfig(v1::StereoMatcher matcher) {
  v1::StreamConfig c;
  c.mutable_stereo()->set_matcher(matcher);
  c.mutable_stereo()->set_num_disparities(16);
  v1::CameraModel* m = c.mutable_camera();
  m->set_fx(30);
  m->set_fy(30);
  m->set_cx(20);
  m->set_cy(6);
  m->set_baseline(0.4);
  return c;
}

std::vector<std::pair<std::string, v1::Frame>> Frames() {
  const cv::Mat d8 = DisparityU8(), d16 = DisparityU16(), df = DisparityF32();
  const cv::Mat bgr = ColourBgr(), bgra = ColourBgra(), grey = Grey();
  return {
      {"raw_u8_bgr", MakeFrame(As::kRaw, d8, DisparityEncoding::kU8, As::kRaw, bgr,
                               ColorEncoding::kBGR8, v1::COMPRESSION_ZSTD, 1)},
      {"raw_u16_rgba", MakeFrame(As::kRaw, d16, DisparityEncoding::kU16, As::kRaw, bgra,
                                 ColorEncoding::kRGBA8, v1::COMPRESSION_ZSTD, 2)},
      {"raw_f32_mono", MakeFrame(As::kRaw, df, DisparityEncoding::kF32, As::kRaw, grey,
                                 ColorEncoding::kMono8, v1::COMPRESSION_ZSTD, 3)},
      {"png_png", MakeFrame(As::kEncoded, d8, DisparityEncoding::kU8, As::kEncoded, bgr,
                            ColorEncoding::kBGR8, v1::COMPRESSION_ZSTD, 4)},
      {"zstd_rows", MakeFrame(As::kCompressed, d8, DisparityEncoding::kU8, As::kCompressed, bgr,
                              ColorEncoding::kRGB8, v1::COMPRESSION_ZSTD_DELTA_ROWS, 5)},
      {"zstd_left_u16", MakeFrame(As::kCompressed, d16, DisparityEncoding::kU16, As::kCompressed,
                                  bgra, ColorEncoding::kBGR8, v1::COMPRESSION_ZSTD_DELTA_LEFT, 6)},
  };
}

v1::StreamConfig FullConfig() {
  PipelineOptions options;
  v1::StreamConfig c = convert::MakeStreamConfig(options);
  DracoOptions draco;
  convert::SetDraco(draco, &c);
  c.set_delivery(v1::DELIVERY_ALL);
  c.mutable_camera()->mutable_invalid_disparities()->add_values(0);
  return c;
}

// A short real H.264 stream (x264, 64x48) in fuzz-video-decode's framing: a flag byte, then each
// access unit after its 2-byte big-endian length.
std::string SeedStream(video::PictureKind kind, int frames, int idr_at, int skip_first,
                       std::uint8_t flags) {
  video::EncoderOptions o;
  o.kind = kind;
  o.width = 64;
  o.height = 48;
  o.crf = 30;
  o.bitrate_bps = 0;
  auto enc = video::Encoder::Make(o);
  Check(enc.status());
  std::string out(1, static_cast<char>(flags));
  for (int f = 0; f < frames; ++f) {
    cv::Mat img =
        kind == video::PictureKind::kGrey ? cv::Mat(48, 64, CV_8UC1) : cv::Mat(48, 64, CV_8UC3);
    for (int v = 0; v < 48; ++v) {
      for (int u = 0; u < 64 * img.channels(); ++u) {
        img.ptr<std::uint8_t>(v)[u] = static_cast<std::uint8_t>((u * 7 + v * 5 + f * 3) ^ (u * v));
      }
    }
    ColorView view;
    view.data = img.data;
    view.size_bytes = img.total() * img.elemSize();
    view.width = 64;
    view.height = 48;
    view.stride_bytes = img.step;
    view.encoding = img.channels() == 1 ? ColorEncoding::kMono8 : ColorEncoding::kBGR8;
    video::FrameControl control;
    control.keyframe = f == idr_at;
    video::EncodedPicture pic;
    Check((*enc)->Encode(view, control, "seed", &pic));
    if (f < skip_first) continue;
    out.push_back(static_cast<char>(pic.bytes.size() >> 8));
    out.push_back(static_cast<char>(pic.bytes.size() & 0xFF));
    out += pic.bytes;
  }
  return out;
}

void StreamSeeds() {
  const std::string h = "stream_request";
  v1::StreamRequest r;
  r.mutable_config();
  Write(h, "config_empty", r.SerializeAsString());
  *r.mutable_config() = FullConfig();
  Write(h, "config_full", r.SerializeAsString());
  r.Clear();
  Write(h, "neither", r.SerializeAsString());
  for (const auto& [name, frame] : Frames()) {
    r.Clear();
    *r.mutable_frame() = frame;
    Write(h, "frame_" + name, r.SerializeAsString());
  }
  r.Clear();
  *r.mutable_frame() = DepthFrame(As::kRaw, DepthU16(), DepthEncoding::kU16, 7);
  Write(h, "frame_depth_u16", r.SerializeAsString());
  *r.mutable_frame() = StereoFrame(As::kRaw, CV_8UC1, 8);  // the defaults' search: too narrow
  Write(h, "frame_stereo_mono", r.SerializeAsString());
  r.Clear();
  *r.mutable_config() = StereoConfig(v1::STEREO_MATCHER_SGM);
  Write(h, "config_stereo", r.SerializeAsString());
  // A disparity map with its colour as a video IDR (64x48, 4:2:0): the reading path's decoder.
  r.Clear();
  v1::Frame* f = r.mutable_frame();
  f->set_sequence(1);
  cv::Mat d(48, 64, CV_8UC1);
  for (int v = 0; v < 48; ++v) {
    for (int u = 0; u < 64; ++u)
      d.at<std::uint8_t>(v, u) = static_cast<std::uint8_t>(20 + (v * 64 + u) % 40);
  }
  Check(convert::ToProto(View(d, DisparityEncoding::kU8), "d",
                         f->mutable_disparity()->mutable_raw()));
  const std::string idr_stream = SeedStream(video::PictureKind::kColour, 1, -1, 0, 1);
  const std::size_t length =
      static_cast<std::uint8_t>(idr_stream[1]) << 8 | static_cast<std::uint8_t>(idr_stream[2]);
  v1::VideoPicture* picture = f->mutable_color()->mutable_video();
  picture->set_codec(v1::VIDEO_CODEC_H264);
  picture->set_width(64);
  picture->set_height(48);
  picture->set_access_unit(idr_stream.substr(3, length));
  picture->set_keyframe(true);
  Write(h, "frame_video_colour_idr", r.SerializeAsString());
}

void ProcessSeeds() {
  const std::string h = "process_request";
  const auto frames = Frames();
  v1::ProcessRequest r;
  *r.mutable_frame() = frames[0].second;
  Write(h, "defaults_raw", r.SerializeAsString());
  *r.mutable_config() = FullConfig();
  Write(h, "full_config_raw", r.SerializeAsString());
  // Every stage off but the conversion: every valid pixel becomes a point.
  v1::StreamConfig off;
  off.mutable_passthrough()->set_enabled(false);
  off.mutable_voxel_grid()->set_enabled(false);
  *r.mutable_config() = off;
  *r.mutable_frame() = frames[2].second;
  Write(h, "stages_off_f32", r.SerializeAsString());
  // The kd-tree coder (speed 7) and libdraco's path, many position bits.
  v1::StreamConfig kd;
  kd.mutable_draco()->set_encode_speed(7);
  kd.mutable_draco()->set_decode_speed(7);
  kd.mutable_draco()->set_position_bits(14);
  kd.mutable_draco()->set_color_bits(5);
  kd.mutable_voxel_grid()->set_leaf(0.01f);
  *r.mutable_config() = kd;
  *r.mutable_frame() = frames[1].second;
  Write(h, "draco_kdtree_u16", r.SerializeAsString());
  // A camera of its own, passthrough on x, negative, a per-axis leaf and a minimum per voxel.
  v1::StreamConfig cam;
  v1::CameraModel* m = cam.mutable_camera();
  m->set_fx(500);
  m->set_fy(510);
  m->set_cx(7.5);
  m->set_cy(6);
  m->set_baseline(0.12);
  m->set_disparity_scale(1.0 / 16);
  m->set_disparity_offset(0.5);
  cam.mutable_passthrough()->set_axis(v1::AXIS_X);
  cam.mutable_passthrough()->set_min(-1);
  cam.mutable_passthrough()->set_max(1);
  cam.mutable_passthrough()->set_negative(true);
  cam.mutable_voxel_grid()->set_leaf_x(0.05f);
  cam.mutable_voxel_grid()->set_leaf_y(0.02f);
  cam.mutable_voxel_grid()->set_leaf_z(0.1f);
  cam.mutable_voxel_grid()->set_min_points_per_voxel(2);
  cam.mutable_draco()->set_max_position_error(0.001f);
  *r.mutable_config() = cam;
  *r.mutable_frame() = frames[5].second;
  Write(h, "camera_axis_x_zstd", r.SerializeAsString());
  r.clear_config();
  *r.mutable_frame() = frames[3].second;
  Write(h, "defaults_png", r.SerializeAsString());
  *r.mutable_frame() = frames[4].second;
  Write(h, "defaults_zstd", r.SerializeAsString());
  // Depth images: millimetres, and float metres through zstd.
  *r.mutable_frame() = DepthFrame(As::kRaw, DepthU16(), DepthEncoding::kU16, 7);
  Write(h, "depth_u16_raw", r.SerializeAsString());
  cv::Mat metres;
  DepthU16().convertTo(metres, CV_32F, 0.001);
  metres.at<float>(2, 3) = NAN;
  *r.mutable_frame() = DepthFrame(As::kCompressed, metres, DepthEncoding::kF32, 8);
  Write(h, "depth_f32_zstd", r.SerializeAsString());
  // Stereo pairs through every matcher: ours (4 and 8 paths, the disparity sent back), OpenCV's
  // SGBM and BM, and a pair rectified with a calibration first.
  *r.mutable_config() = StereoConfig(v1::STEREO_MATCHER_SGM);
  *r.mutable_frame() = StereoFrame(As::kRaw, CV_8UC1, 9);
  Write(h, "stereo_sgm_mono", r.SerializeAsString());
  r.mutable_config()->mutable_stereo()->set_paths(8);
  r.mutable_config()->mutable_stereo()->set_return_disparity(true);
  *r.mutable_frame() = StereoFrame(As::kCompressed, CV_8UC3, 10);
  Write(h, "stereo_sgm8_bgr_zstd", r.SerializeAsString());
  *r.mutable_config() = StereoConfig(v1::STEREO_MATCHER_OPENCV_SGBM);
  *r.mutable_frame() = StereoFrame(As::kRaw, CV_8UC3, 11);
  Write(h, "stereo_sgbm_bgr", r.SerializeAsString());
  *r.mutable_config() = StereoConfig(v1::STEREO_MATCHER_OPENCV_BM);
  r.mutable_config()->mutable_stereo()->set_block_size(5);
  *r.mutable_frame() = StereoFrame(As::kRaw, CV_8UC1, 12);
  Write(h, "stereo_bm_mono", r.SerializeAsString());
  *r.mutable_config() = StereoConfig(v1::STEREO_MATCHER_SGM);
  v1::StereoCalibration* cal = r.mutable_config()->mutable_stereo()->mutable_calibration();
  cal->set_width(kStereoW);
  cal->set_height(kH);
  for (auto* k : {cal->mutable_left_k(), cal->mutable_right_k()})
    for (double x : {30.0, 0.0, 20.0, 0.0, 30.0, 6.0, 0.0, 0.0, 1.0}) k->Add(x);
  for (double x : {0.01, -0.002, 0.0, 0.0}) cal->add_left_d(x);
  for (double x : {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0}) cal->add_r(x);
  for (double x : {-0.4, 0.0, 0.0}) cal->add_t(x);
  *r.mutable_frame() = StereoFrame(As::kRaw, CV_8UC1, 13);
  Write(h, "stereo_calibrated", r.SerializeAsString());
  // Pairs at the edge of their disparity range, for each of OpenCV's modes (issue 30: a 64x16
  // pair with 128 disparities aborted the server inside OpenCV's SGBM_3WAY): 32 disparities
  // leave the 40-pixel pair 3 columns past a 5-pixel block, 48 none (refused before matching).
  struct Edge {
    v1::StereoMatcher matcher;
    const char* name;
  };
  for (const Edge& e : {Edge{v1::STEREO_MATCHER_OPENCV_SGBM_3WAY, "sgbm3way"},
                        Edge{v1::STEREO_MATCHER_OPENCV_SGBM, "sgbm"},
                        Edge{v1::STEREO_MATCHER_OPENCV_HH, "hh"},
                        Edge{v1::STEREO_MATCHER_OPENCV_BM, "bm"}}) {
    for (int disparities : {32, 48}) {
      *r.mutable_config() = StereoConfig(e.matcher);
      r.mutable_config()->mutable_stereo()->set_num_disparities(disparities);
      r.mutable_config()->mutable_stereo()->set_block_size(5);
      *r.mutable_frame() = StereoFrame(As::kRaw, CV_8UC1, 14);
      Write(h, std::string("stereo_") + e.name + "_edge_" + std::to_string(disparities),
            r.SerializeAsString());
    }
  }
}

std::string Le16(std::uint32_t v) {
  return {static_cast<char>(v & 0xFF), static_cast<char>(v >> 8)};
}

void ImageSeeds() {
  const std::string h = "frame_images";
  const cv::Mat d8 = DisparityU8(), d16 = DisparityU16(), df = DisparityF32();
  const cv::Mat bgr = ColourBgr(), bgra = ColourBgra(), grey = Grey();
  // Mode 0: disparity bytes.
  Write(h, "d_png_u8", std::string(1, '\0') + Encode(".png", d8));
  Write(h, "d_png_u16", std::string(1, '\0') + Encode(".png", d16));
  Write(h, "d_tiff_f32", std::string(1, '\0') + Encode(".tiff", df));
  Write(h, "d_pfm", std::string(1, '\0') + Encode(".pfm", df));
  Write(h, "d_pgm", std::string(1, '\0') + Encode(".pgm", d8));
  Write(h, "d_jpeg_refused", std::string(1, '\0') + Encode(".jpg", d8));
  // Mode 1: colour bytes.
  Write(h, "c_png_bgr", "\x01" + Encode(".png", bgr));
  Write(h, "c_png_bgra", "\x01" + Encode(".png", bgra));
  Write(h, "c_jpeg", "\x01" + Encode(".jpg", bgr, {cv::IMWRITE_JPEG_QUALITY, 50}));
  Write(h, "c_ppm", "\x01" + Encode(".ppm", bgr));
  Write(h, "c_tiff_grey", "\x01" + Encode(".tiff", grey));
  // Modes 2 and 3: the zstd uplink, every encoding and predictor.
  PlaneCompressor compressor;
  struct D {
    const char* name;
    const cv::Mat* m;
    DisparityEncoding e;
    v1::DisparityEncoding pe;
  };
  const D ds[] = {{"u8", &d8, DisparityEncoding::kU8, v1::DISPARITY_U8},
                  {"u16", &d16, DisparityEncoding::kU16, v1::DISPARITY_U16},
                  {"f32", &df, DisparityEncoding::kF32, v1::DISPARITY_F32}};
  const v1::Compression codecs[] = {v1::COMPRESSION_ZSTD, v1::COMPRESSION_ZSTD_DELTA_ROWS,
                                    v1::COMPRESSION_ZSTD_DELTA_LEFT};
  for (const D& d : ds) {
    for (v1::Compression codec : codecs) {
      v1::CompressedDisparity c;
      Check(convert::ToProto(View(*d.m, d.e), convert::Compression{codec, 1}, "d", &c));
      Write(h, std::string("d_zstd_") + d.name + "_" + std::to_string(codec),
            std::string{'\x02', static_cast<char>(d.pe), static_cast<char>(codec)} + Le16(kW) +
                Le16(kH) + c.payload());
    }
  }
  struct C {
    const char* name;
    const cv::Mat* m;
    ColorEncoding e;
    v1::ColorEncoding pe;
  };
  const C cs[] = {{"bgr", &bgr, ColorEncoding::kBGR8, v1::COLOR_BGR8},
                  {"rgba", &bgra, ColorEncoding::kRGBA8, v1::COLOR_RGBA8},
                  {"mono", &grey, ColorEncoding::kMono8, v1::COLOR_MONO8}};
  for (const C& c : cs) {
    for (v1::Compression codec : codecs) {
      v1::CompressedColor cc;
      Check(convert::ToProto(View(*c.m, c.e), convert::Compression{codec, 1}, "c", &cc));
      Write(h, std::string("c_zstd_") + c.name + "_" + std::to_string(codec),
            std::string{'\x03', static_cast<char>(c.pe), static_cast<char>(codec)} + Le16(kW) +
                Le16(kH) + cc.payload());
    }
  }
}

PointCloud SmallCloud(std::uint32_t width, std::uint32_t height, bool with_nan) {
  PointCloud cloud;
  cloud.width = width;
  cloud.height = height;
  for (std::uint32_t v = 0; v < height; ++v) {
    for (std::uint32_t u = 0; u < width; ++u) {
      Point p{0.1f * u - 0.8f, 0.07f * v - 0.4f, 3.0f + 0.05f * ((u * 7 + v) % 11),
              PackRgba(u * 16, v * 20, 200)};
      if (with_nan && (u + v) % 5 == 0) p = Point{NAN, NAN, NAN, 0};
      cloud.points.push_back(p);
    }
  }
  return cloud;
}

std::string ReadFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

void DracoSeeds() {
  const std::string h = "draco_decode";
  const PointCloud cloud = SmallCloud(64, 1, false);
  struct Case {
    const char* name;
    int bits, color_bits, speed;
    bool libdraco;
  };
  const Case cases[] = {{"seq10_ours", 10, 8, 10, false},
                        {"seq10_libdraco", 10, 8, 10, true},
                        {"seq10_24bits", 24, 8, 10, false},
                        {"kd7_12bits", 12, 8, 7, false},
                        {"kd0_colour5", 11, 5, 0, false}};
  for (const Case& c : cases) {
    DracoOptions o;
    o.position_bits = c.bits;
    o.color_bits = c.color_bits;
    o.encode_speed = o.decode_speed = c.speed;
    o.force_libdraco = c.libdraco;
    std::string bytes;
    Check(EncodeDraco(cloud, o, &bytes));
    Write(h, c.name, bytes);
  }
  std::string empty;
  Check(EncodeDraco(PointCloud{}, DracoOptions{}, &empty));
  Write(h, "empty", empty);
}

void CloudFileSeeds() {
  const std::string h = "cloud_readers";
  const fs::path tmp = fs::temp_directory_path() / ("cloudcast-seeds-" + std::to_string(getpid()));
  fs::create_directories(tmp);
  const PointCloud organized = SmallCloud(6, 4, true);
  const PointCloud flat = SmallCloud(20, 1, false);
  const char* const exts[] = {".pcd", ".ply", ".drc"};
  for (int i = 0; i < 3; ++i) {
    const std::string prefix(1, static_cast<char>(i));
    const std::string ext = exts[i];
    for (const auto& [name, cloud] :
         {std::pair{"organized", &organized}, std::pair{"flat", &flat}}) {
      const fs::path p = tmp / (std::string(name) + ext);
      Check(SaveCloud(p.string(), *cloud));
      Write(h, ext.substr(1) + "_" + name, prefix + ReadFile(p));
    }
    const fs::path p = tmp / ("empty" + ext);
    Check(SaveCloud(p.string(), PointCloud{}));
    Write(h, ext.substr(1) + "_empty", prefix + ReadFile(p));
  }
  fs::remove_all(tmp);
  // Other tools' flavours: ASCII PCD with rgba as an integer, ASCII PLY with doubles and no
  // colour, a binary-compressed PCD header.
  Write(h, "pcd_ascii_rgba",
        std::string(1, '\0') +
            "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z rgba\n"
            "SIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 3\nHEIGHT 1\n"
            "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA ascii\n"
            "0.1 0.2 3.0 4278190335\n0.2 0.3 3.5 4278255360\nnan nan nan 0\n");
  Write(h, "ply_ascii_double",
        std::string(1, '\1') +
            "ply\nformat ascii 1.0\ncomment other tool\nelement vertex 3\nproperty double x\n"
            "property double y\nproperty double z\nend_header\n0 0 3\n1 0 3\n0 1 4\n");
  Write(h, "ply_binary_uchar_colour",
        std::string(1, '\1') +
            "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n"
            "property float y\nproperty float z\nproperty uchar red\nproperty uchar green\n"
            "property uchar blue\nend_header\n" +
            std::string("\x00\x00\x80\x3f\x00\x00\x00\x40\x00\x00\x40\x40\x10\x20\x30", 15));
}

}  // namespace

// fuzz-video-decode: short real H.264 streams (x264, 64x48) in the harness's framing: a flag byte,
// then each access unit after its 2-byte big-endian length. Grey, colour 4:2:0 and 4:4:4, an IDR
// asked for mid-stream, one starting without its IDR, and one with a gap.
void VideoSeeds() {
  Write("video_decode", "grey_4_frames", SeedStream(video::PictureKind::kGrey, 4, -1, 0, 0));
  Write("video_decode", "colour420_bgr_idr_at_2",
        SeedStream(video::PictureKind::kColour, 4, 2, 0, 1));
  Write("video_decode", "colour444_bgr", SeedStream(video::PictureKind::kColour444, 3, -1, 0, 1));
  Write("video_decode", "grey_starts_without_idr",
        SeedStream(video::PictureKind::kGrey, 4, 2, 1, 0));
  Write("video_decode", "grey_gap_then_idr", SeedStream(video::PictureKind::kGrey, 5, 3, 0, 2));
  // RVL images (flag 4; 12: 8-bit): the 16 x 12 disparity maps the other seeds use.
  std::string rvl;
  const cv::Mat u8 = DisparityU8(), u16 = DisparityU16();
  video::EncodeRvl(u8.ptr<std::uint8_t>(), kW, kH, &rvl);
  Write("video_decode", "rvl_u8", std::string(1, '\x0c') + rvl);
  video::EncodeRvl(u16.ptr<std::uint16_t>(), kW, kH, &rvl);
  Write("video_decode", "rvl_u16", std::string(1, '\x04') + rvl);
}

int main(int argc, char** argv) {
  if (argc != 2) {
    std::cerr << "usage: make_seeds <corpus folder, e.g. fuzz/corpus>\n";
    return 2;
  }
  g_root = argv[1];
  StreamSeeds();
  ProcessSeeds();
  ImageSeeds();
  DracoSeeds();
  CloudFileSeeds();
  VideoSeeds();
  std::cout << "make_seeds: wrote the seed corpora under " << g_root << "\n";
  return 0;
}
