// cloudcast-uplink-bench: what a frame costs on the uplink, per encoding. Bytes per frame, the
// client's encode time and the server's decode time, over the New Tsukuba frames (or synthetic
// frames without them), interleaved, medians. Two tables:
//   uplink      the encodings the protocol offers, through the code each side runs (the client
//               library's frame building, the server's frame input);
//   candidates  (--candidates) the codecs measured to choose the compressed uplink: zstd at
//               several levels with and without row predictors, lz4, PNG through OpenCV and
//               libspng, JPEG colour.
#include <lz4.h>
#include <spng.h>
#define ZSTD_STATIC_LINKING_ONLY  // ZSTD_c_literalCompressionMode, for the tuned candidates
#include <time.h>
#include <zstd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "cloudcast/core/frame_codec.h"
#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/datasets/tsukuba.h"
#include "cloudcast/io/image_io.h"
#include "cloudcast/proto/convert.h"
#include "stats.h"

namespace cloudcast::bench {
namespace {

struct Frame {
  OwnedDisparity disparity;
  OwnedColor colour;
};

double ThreadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

// This thread's CPU milliseconds in one call: on 2 cores shared with other work, wall time
// mostly measures the scheduler; CPU time is what the encoding costs a server core.
template <typename F>
double TimeMs(F&& f) {
  const double t0 = ThreadCpuMs();
  f();
  return ThreadCpuMs() - t0;
}

// The bytes an encoding puts on the wire for one frame.
struct Encoded {
  std::string disparity;
  std::string colour;
};

// One row of a table: how to encode a frame (client) and decode it back (server). `decode`
// returns false when the result differs from the input where it must not (checked once).
struct Candidate {
  std::string name;
  std::string note;
  std::function<void(const Frame&, Encoded*)> encode;
  std::function<bool(const Frame&, const Encoded&, bool check)> decode;
  // Per frame: medians over the repeats.
  std::vector<double> encode_ms, decode_ms, disparity_bytes, colour_bytes;
  bool exact = true;
};

Candidate Row(std::string name, std::string note,
              std::function<void(const Frame&, Encoded*)> encode,
              std::function<bool(const Frame&, const Encoded&, bool)> decode) {
  Candidate c;
  c.name = std::move(name);
  c.note = std::move(note);
  c.encode = std::move(encode);
  c.decode = std::move(decode);
  return c;
}

cv::Mat MatOf(const OwnedDisparity& d) {
  return cv::Mat(static_cast<int>(d.height), static_cast<int>(d.width), CV_8UC1,
                 const_cast<std::uint8_t*>(d.pixels.data()));
}
cv::Mat MatOf(const OwnedColor& c) {
  return cv::Mat(static_cast<int>(c.height), static_cast<int>(c.width), CV_8UC3,
                 const_cast<std::uint8_t*>(c.pixels.data()));
}

std::string Png(const cv::Mat& m, int level) {
  std::vector<std::uint8_t> buf;
  cv::imencode(".png", m, buf, {cv::IMWRITE_PNG_COMPRESSION, level});
  return std::string(buf.begin(), buf.end());
}
std::string Jpeg(const cv::Mat& m, int quality) {
  std::vector<std::uint8_t> buf;
  cv::imencode(".jpg", m, buf, {cv::IMWRITE_JPEG_QUALITY, quality});
  return std::string(buf.begin(), buf.end());
}

bool Same(const std::uint8_t* a, const std::vector<std::uint8_t>& b) {
  return std::memcmp(a, b.data(), b.size()) == 0;
}

// libspng decode into a reused buffer; colour as RGB8 (what the server would take), disparity
// as G8.
struct SpngDecoder {
  std::vector<std::uint8_t> out;
  bool Decode(const std::string& png, int fmt) {
    spng_ctx* ctx = spng_ctx_new(0);
    spng_set_png_buffer(ctx, png.data(), png.size());
    spng_set_crc_action(ctx, SPNG_CRC_USE, SPNG_CRC_USE);  // as OpenCV: no CRC check cost
    std::size_t size = 0;
    bool ok = spng_decoded_image_size(ctx, fmt, &size) == 0;
    if (ok) {
      if (out.size() < size) out.resize(size);
      ok = spng_decode_image(ctx, out.data(), size, fmt, 0) == 0;
    }
    spng_ctx_free(ctx);
    return ok;
  }
};

// --- candidates -------------------------------------------------------------------------------

std::vector<Candidate> Candidates() {
  std::vector<Candidate> c;
  auto compressor = std::make_shared<PlaneCompressor>();
  auto dd = std::make_shared<PlaneDecompressor>();
  auto dc = std::make_shared<PlaneDecompressor>();
  auto spng = std::make_shared<SpngDecoder>();
  auto copy = std::make_shared<Encoded>();

  c.push_back(Row(
      "raw", "rows copied into the request",
      [copy](const Frame& f, Encoded* e) {
        e->disparity.assign(reinterpret_cast<const char*>(f.disparity.pixels.data()),
                            f.disparity.pixels.size());
        e->colour.assign(reinterpret_cast<const char*>(f.colour.pixels.data()),
                         f.colour.pixels.size());
      },
      [](const Frame&, const Encoded&, bool) { return true; }));

  for (int level : {1, 3}) {
    c.push_back(Row(
        "png-opencv-" + std::to_string(level), "OpenCV (libpng) both ways",
        [level](const Frame& f, Encoded* e) {
          e->disparity = Png(MatOf(f.disparity), level);
          e->colour = Png(MatOf(f.colour), level);
        },
        [](const Frame& f, const Encoded& e, bool check) {
          auto d = DecodeDisparity(e.disparity);
          auto col = DecodeColor(e.colour);
          if (!check) return d.ok() && col.ok();
          return d.ok() && col.ok() && d->pixels == f.disparity.pixels &&
                 col->pixels == f.colour.pixels;
        }));
  }
  c.push_back(Row(
      "png-spng-1", "OpenCV encode, libspng decode",
      [](const Frame& f, Encoded* e) {
        e->disparity = Png(MatOf(f.disparity), 1);
        e->colour = Png(MatOf(f.colour), 1);
      },
      [spng](const Frame& f, const Encoded& e, bool check) {
        bool ok = spng->Decode(e.disparity, SPNG_FMT_G8);
        if (ok && check) ok = Same(spng->out.data(), f.disparity.pixels);
        // RGB8 from a BGR PNG written by OpenCV: the bytes come back in the file's
        // order (OpenCV swapped them), so compare against the swap.
        ok = ok && spng->Decode(e.colour, SPNG_FMT_RGB8);
        if (ok && check) {
          for (std::size_t i = 0; i < f.colour.pixels.size(); i += 3) {
            if (spng->out[i] != f.colour.pixels[i + 2] || spng->out[i + 2] != f.colour.pixels[i]) {
              return false;
            }
          }
        }
        return ok;
      }));

  for (int level : {-3, -1, 1, 3}) {
    for (Predictor dp : {Predictor::kNone, Predictor::kUp, Predictor::kLeft}) {
      for (Predictor cp : {Predictor::kNone, Predictor::kUp, Predictor::kLeft}) {
        if (level != 1 && dp != cp) continue;  // the mixed predictors at level 1 only
        const std::string name = "zstd" + std::to_string(level) + "-d" + std::string(Name(dp)) +
                                 "-c" + std::string(Name(cp));
        c.push_back(Row(
            name, "",
            [=](const Frame& f, Encoded* e) {
              (void)compressor->Compress(f.disparity.view(), dp, level, "d", &e->disparity);
              (void)compressor->Compress(f.colour.view(), cp, level, "c", &e->colour);
            },
            [=](const Frame& f, const Encoded& e, bool check) {
              const std::uint8_t* d = nullptr;
              const std::uint8_t* col = nullptr;
              bool ok =
                  dd->Decompress(e.disparity, LayoutOf(f.disparity.view()), dp, "d", "", &d).ok() &&
                  dc->Decompress(e.colour, LayoutOf(f.colour.view()), cp, "c", "", &col).ok();
              if (ok && check) {
                ok = Same(d, f.disparity.pixels) && Same(col, f.colour.pixels);
              }
              return ok;
            }));
      }
    }
  }

  // zstd with parameters beyond the level, on up-predicted planes: stored literals (no Huffman
  // stage: faster to decode, larger; negative levels store them anyway, so level 1 only), other
  // minimum matches and the double-fast matcher.
  struct Tuned {
    std::string name, note;
    int level;
    std::function<void(ZSTD_CCtx*)> set;
  };
  const std::vector<Tuned> tuned = {
      {"zstd1-up-rawlit", "literals stored, not Huffman-coded", 1,
       [](ZSTD_CCtx* z) {
         ZSTD_CCtx_setParameter(z, ZSTD_c_literalCompressionMode, ZSTD_ps_disable);
       }},
      {"zstd1-up-mm5", "minimum match 5", 1,
       [](ZSTD_CCtx* z) { ZSTD_CCtx_setParameter(z, ZSTD_c_minMatch, 5); }},
      {"zstd1-up-mm6", "minimum match 6", 1,
       [](ZSTD_CCtx* z) { ZSTD_CCtx_setParameter(z, ZSTD_c_minMatch, 6); }},
      {"zstd1-up-mm7", "minimum match 7", 1,
       [](ZSTD_CCtx* z) { ZSTD_CCtx_setParameter(z, ZSTD_c_minMatch, 7); }},
      {"zstd1-up-dfast", "double-fast matcher", 1,
       [](ZSTD_CCtx* z) { ZSTD_CCtx_setParameter(z, ZSTD_c_strategy, ZSTD_dfast); }},
      {"zstd1-up-dfast-mm6", "double-fast matcher, minimum match 6", 1,
       [](ZSTD_CCtx* z) {
         ZSTD_CCtx_setParameter(z, ZSTD_c_strategy, ZSTD_dfast);
         ZSTD_CCtx_setParameter(z, ZSTD_c_minMatch, 6);
       }},
  };
  for (const Tuned& t : tuned) {
    auto cctx = std::shared_ptr<ZSTD_CCtx>(ZSTD_createCCtx(), ZSTD_freeCCtx);
    auto dctx = std::shared_ptr<ZSTD_DCtx>(ZSTD_createDCtx(), ZSTD_freeDCtx);
    auto buf = std::make_shared<std::vector<std::uint8_t>>();
    c.push_back(Row(
        t.name, t.note,
        [=](const Frame& f, Encoded* e) {
          auto one = [&](const void* data, const PlaneLayout& l, std::string* out) {
            buf->resize(l.bytes());
            ApplyPredictor(Predictor::kUp, l, data, l.width * l.bpp, buf->data());
            ZSTD_CCtx_reset(cctx.get(), ZSTD_reset_session_and_parameters);
            ZSTD_CCtx_setParameter(cctx.get(), ZSTD_c_compressionLevel, t.level);
            ZSTD_CCtx_setParameter(cctx.get(), ZSTD_c_checksumFlag, 1);  // as the uplink's
            t.set(cctx.get());
            out->resize(ZSTD_compressBound(l.bytes()));
            out->resize(
                ZSTD_compress2(cctx.get(), out->data(), out->size(), buf->data(), l.bytes()));
          };
          one(f.disparity.pixels.data(), LayoutOf(f.disparity.view()), &e->disparity);
          one(f.colour.pixels.data(), LayoutOf(f.colour.view()), &e->colour);
        },
        [=](const Frame& f, const Encoded& e, bool check) {
          auto one = [&](const std::string& in, const PlaneLayout& l,
                         const std::vector<std::uint8_t>& want) {
            buf->resize(l.bytes());
            const std::size_t n =
                ZSTD_decompressDCtx(dctx.get(), buf->data(), l.bytes(), in.data(), in.size());
            if (n != l.bytes()) return false;
            UndoPredictor(Predictor::kUp, l, buf->data());
            return !check || *buf == want;
          };
          return one(e.disparity, LayoutOf(f.disparity.view()), f.disparity.pixels) &&
                 one(e.colour, LayoutOf(f.colour.view()), f.colour.pixels);
        }));
  }

  // lz4 (fast mode) on the up-predicted planes.
  auto lz4_buf = std::make_shared<std::vector<std::uint8_t>>();
  for (Predictor p : {Predictor::kNone, Predictor::kUp}) {
    c.push_back(Row(
        "lz4-" + std::string(Name(p)), "LZ4_compress_default",
        [=](const Frame& f, Encoded* e) {
          auto one = [&](const void* data, const PlaneLayout& l, std::string* out) {
            lz4_buf->resize(l.bytes());
            ApplyPredictor(p, l, data, l.width * l.bpp, lz4_buf->data());
            out->resize(LZ4_compressBound(static_cast<int>(l.bytes())));
            const int n =
                LZ4_compress_default(reinterpret_cast<const char*>(lz4_buf->data()), out->data(),
                                     static_cast<int>(l.bytes()), static_cast<int>(out->size()));
            out->resize(n);
          };
          one(f.disparity.pixels.data(), LayoutOf(f.disparity.view()), &e->disparity);
          one(f.colour.pixels.data(), LayoutOf(f.colour.view()), &e->colour);
        },
        [=](const Frame& f, const Encoded& e, bool check) {
          auto one = [&](const std::string& in, const PlaneLayout& l,
                         const std::vector<std::uint8_t>& want) {
            lz4_buf->resize(l.bytes());
            const int n =
                LZ4_decompress_safe(in.data(), reinterpret_cast<char*>(lz4_buf->data()),
                                    static_cast<int>(in.size()), static_cast<int>(l.bytes()));
            if (n != static_cast<int>(l.bytes())) return false;
            UndoPredictor(p, l, lz4_buf->data());
            return !check || *lz4_buf == want;
          };
          return one(e.disparity, LayoutOf(f.disparity.view()), f.disparity.pixels) &&
                 one(e.colour, LayoutOf(f.colour.view()), f.colour.pixels);
        }));
  }

  for (int quality : {90, 80}) {
    c.push_back(Row(
        "jpeg" + std::to_string(quality) + "+zstd1-dup", "colour lossy (OpenCV)",
        [=](const Frame& f, Encoded* e) {
          (void)compressor->Compress(f.disparity.view(), Predictor::kUp, 1, "d", &e->disparity);
          e->colour = Jpeg(MatOf(f.colour), quality);
        },
        [=](const Frame& f, const Encoded& e, bool check) {
          const std::uint8_t* d = nullptr;
          bool ok =
              dd->Decompress(e.disparity, LayoutOf(f.disparity.view()), Predictor::kUp, "d", "", &d)
                  .ok();
          auto col = DecodeColor(e.colour);
          if (ok && check) ok = Same(d, f.disparity.pixels);
          return ok && col.ok();
        }));
  }
  c.back().exact = false;
  c[c.size() - 2].exact = false;
  return c;
}

// --- the uplink as the protocol offers it ------------------------------------------------------

std::vector<Candidate> UplinkRows() {
  std::vector<Candidate> c;
  auto frame = std::make_shared<v1::Frame>();
  auto compressor = std::make_shared<PlaneCompressor>();
  auto dd = std::make_shared<PlaneDecompressor>();
  auto dc = std::make_shared<PlaneDecompressor>();
  const Limits limits;

  // Encode: what the client library writes into the request. Decode: what the server does before
  // the pipeline sees views (raw: views in place).
  c.push_back(Row(
      "raw", "views in place on the server",
      [frame](const Frame& f, Encoded* e) {
        (void)convert::ToProto(f.disparity.view(), "disparity",
                               frame->mutable_disparity()->mutable_raw());
        (void)convert::ToProto(f.colour.view(), "colour", frame->mutable_color()->mutable_raw());
        e->disparity = frame->disparity().raw().pixels();
        e->colour = frame->color().raw().pixels();
      },
      [frame, limits](const Frame&, const Encoded&, bool) {
        DisparityView d;
        ColorView c;
        return convert::ViewRaw(frame->disparity().raw(), "d", limits, &d).ok() &&
               convert::ViewRaw(frame->color().raw(), "c", limits, &c).ok();
      }));
  c.push_back(Row(
      "png", "OpenCV, compression 1 (the client's EncodePng default)",
      [](const Frame& f, Encoded* e) {
        e->disparity = Png(MatOf(f.disparity), 1);
        e->colour = Png(MatOf(f.colour), 1);
      },
      [limits](const Frame& f, const Encoded& e, bool check) {
        if (!CheckEncodedImage(e.disparity, "d", limits).ok() ||
            !CheckEncodedImage(e.colour, "c", limits).ok()) {
          return false;
        }
        auto d = DecodeDisparity(e.disparity);
        auto col = DecodeColor(e.colour);
        if (!check) return d.ok() && col.ok();
        return d.ok() && col.ok() && d->pixels == f.disparity.pixels &&
               col->pixels == f.colour.pixels;
      }));
  const auto zstd_encode = [frame](const Frame& f, Encoded* e, bool jpeg_colour) {
    const convert::Compression z;
    (void)convert::ToProto(f.disparity.view(), z, "disparity",
                           frame->mutable_disparity()->mutable_compressed());
    e->disparity = frame->disparity().compressed().payload();
    if (jpeg_colour) {
      e->colour = Jpeg(MatOf(f.colour), 90);
    } else {
      (void)convert::ToProto(f.colour.view(), z, "colour",
                             frame->mutable_color()->mutable_compressed());
      e->colour = frame->color().compressed().payload();
    }
  };
  c.push_back(Row(
      "zstd", "the compressed uplink: row deltas + zstd, both images",
      [=](const Frame& f, Encoded* e) { zstd_encode(f, e, false); },
      [=](const Frame& f, const Encoded&, bool check) {
        DisparityView d;
        ColorView col;
        bool ok =
            convert::DecodeCompressed(frame->disparity().compressed(), "d", limits, dd.get(), &d)
                .ok() &&
            convert::DecodeCompressed(frame->color().compressed(), "c", limits, dc.get(), &col)
                .ok();
        if (ok && check) {
          ok = Same(static_cast<const std::uint8_t*>(d.data), f.disparity.pixels) &&
               Same(static_cast<const std::uint8_t*>(col.data), f.colour.pixels);
        }
        return ok;
      }));
  c.push_back(Row(
      "jpeg", "colour JPEG q90 (lossy), disparity as zstd",
      [=](const Frame& f, Encoded* e) { zstd_encode(f, e, true); },
      [=](const Frame& f, const Encoded& e, bool check) {
        DisparityView d;
        bool ok =
            convert::DecodeCompressed(frame->disparity().compressed(), "d", limits, dd.get(), &d)
                .ok() &&
            CheckEncodedImage(e.colour, "c", limits).ok();
        auto col = DecodeColor(e.colour);
        if (ok && check) {
          ok = Same(static_cast<const std::uint8_t*>(d.data), f.disparity.pixels);
        }
        return ok && col.ok();
      }));
  c.back().exact = false;
  return c;
}

std::vector<Frame> LoadFrames(const std::string& dir) {
  std::vector<Frame> frames;
  if (auto loaded = tsukuba::LoadAll(dir); loaded.ok()) {
    for (tsukuba::Frame& t : *loaded) {
      frames.push_back(Frame{std::move(t.disparity), std::move(t.colour)});
    }
    return frames;
  }
  std::fprintf(stderr, "no New Tsukuba frames under %s: synthetic 640x480 frames\n", dir.c_str());
  for (std::uint64_t i = 0; i < 10; ++i) {
    SyntheticOptions o;
    o.frame = i * 36;
    o.disparity_encoding = DisparityEncoding::kU8;
    auto r = SyntheticScene::Default().Render(o);
    frames.push_back(
        Frame{OwnedDisparity{std::move(r->disparity), o.width, o.height, DisparityEncoding::kU8},
              OwnedColor{std::move(r->colour), o.width, o.height, ColorEncoding::kBGR8}});
  }
  return frames;
}

void Run(std::vector<Candidate>& rows, const std::vector<Frame>& frames, int repeats) {
  for (std::size_t fi = 0; fi < frames.size(); ++fi) {
    const Frame& f = frames[fi];
    std::vector<std::vector<double>> enc(rows.size()), dec(rows.size());
    std::vector<Encoded> encoded(rows.size());
    for (std::size_t r = 0; r < rows.size(); ++r) {
      rows[r].encode(f, &encoded[r]);
      if (!rows[r].decode(f, encoded[r], /*check=*/rows[r].exact)) {
        std::fprintf(stderr, "%s: frame %zu does not round-trip\n", rows[r].name.c_str(), fi);
        std::exit(1);
      }
    }
    for (int i = 0; i < repeats; ++i) {
      // Interleaved: every row once per repeat, so drift in the machine's load hits all alike.
      for (std::size_t r = 0; r < rows.size(); ++r) {
        enc[r].push_back(TimeMs([&] { rows[r].encode(f, &encoded[r]); }));
        dec[r].push_back(TimeMs([&] { rows[r].decode(f, encoded[r], false); }));
      }
    }
    for (std::size_t r = 0; r < rows.size(); ++r) {
      rows[r].encode_ms.push_back(Median(enc[r]));
      rows[r].decode_ms.push_back(Median(dec[r]));
      rows[r].disparity_bytes.push_back(static_cast<double>(encoded[r].disparity.size()));
      rows[r].colour_bytes.push_back(static_cast<double>(encoded[r].colour.size()));
    }
  }
}

double Mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? 0 : s / static_cast<double>(v.size());
}

nlohmann::json Print(const char* title, const std::vector<Candidate>& rows, double raw_bytes) {
  std::printf("\n%s (%s)\n", title,
              "bytes: mean per frame; ms: thread CPU, median over frames of each frame's median");
  std::printf("%-22s %9s %9s %10s %7s %10s %10s  %s\n", "encoding", "disp KB", "colour KB",
              "frame KB", "% raw", "client ms", "server ms", "note");
  nlohmann::json j = nlohmann::json::array();
  for (const Candidate& c : rows) {
    const double d = Mean(c.disparity_bytes), col = Mean(c.colour_bytes);
    const double pct = 100.0 * (d + col) / raw_bytes;
    const double e = Median(c.encode_ms), dm = Median(c.decode_ms);
    std::printf("%-22s %9.1f %9.1f %10.1f %6.1f%% %10.3f %10.3f  %s%s\n", c.name.c_str(), d / 1024,
                col / 1024, (d + col) / 1024, pct, e, dm, c.exact ? "" : "lossy; ", c.note.c_str());
    j.push_back({{"encoding", c.name},
                 {"disparity_bytes", d},
                 {"colour_bytes", col},
                 {"frame_bytes", d + col},
                 {"percent_of_raw", pct},
                 {"client_encode_ms", e},
                 {"server_decode_ms", dm},
                 {"lossless", c.exact},
                 {"encode_ms_per_frame", c.encode_ms},
                 {"decode_ms_per_frame", c.decode_ms}});
  }
  return j;
}

int Main(int argc, char** argv) {
  CLI::App app{
      "cloudcast-uplink-bench: bytes per frame, client encode ms and server decode ms for each\n"
      "uplink encoding, over the New Tsukuba frames (synthetic frames without them)."};
  std::string data_dir = tsukuba::DefaultDir(), json_path;
  int repeats = 15;
  bool candidates = false;
  app.add_option("--data", data_dir, "New Tsukuba folder");
  app.add_option("--repeats", repeats, "timed runs per frame and encoding")
      ->check(CLI::Range(1, 1000));
  app.add_flag("--candidates", candidates,
               "also the codec candidates the compressed uplink was chosen from");
  app.add_option("--json", json_path, "write the tables as JSON");
  CLI11_PARSE(app, argc, argv);

  const std::vector<Frame> frames = LoadFrames(data_dir);
  const double raw_bytes =
      static_cast<double>(frames[0].disparity.pixels.size() + frames[0].colour.pixels.size());
  std::printf("%zu frames of %ux%u, raw %.1f KB per frame (8-bit disparity + BGR8), %d repeats\n",
              frames.size(), frames[0].disparity.width, frames[0].disparity.height,
              raw_bytes / 1024, repeats);
  nlohmann::json out;
  std::vector<Candidate> uplink = UplinkRows();
  Run(uplink, frames, repeats);
  out["uplink"] = Print("uplink encodings", uplink, raw_bytes);
  if (candidates) {
    std::vector<Candidate> c = Candidates();
    Run(c, frames, repeats);
    out["candidates"] = Print("candidates", c, raw_bytes);
  }
  if (!json_path.empty()) std::ofstream(json_path) << out.dump(2) << "\n";
  return 0;
}

}  // namespace
}  // namespace cloudcast::bench

int main(int argc, char** argv) { return cloudcast::bench::Main(argc, argv); }
