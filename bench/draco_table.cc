#include "draco_table.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <ostream>
#include <string>
#include <vector>

#include "cloudcast/core/draco_codec.h"
#include "stats.h"

namespace cloudcast::bench {
namespace {

using Clock = std::chrono::steady_clock;

constexpr int kSpeeds[] = {0, 3, 5, 7, 10};
constexpr int kPositionBits[] = {10, 11, 12, 14, 16};
constexpr int kFirstCloudRuns = 41;

double Ms(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

bool Finite(const Point& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
}

// The finite points of `cloud`, each carrying its own index as its colour.
PointCloud NumberedCopy(const PointCloud& cloud) {
  PointCloud numbered;
  numbered.points.reserve(cloud.size());
  for (const Point& p : cloud.points) {
    if (!Finite(p)) continue;
    const auto index = static_cast<std::uint32_t>(numbered.points.size());
    numbered.points.push_back({p.x, p.y, p.z, 0xFF000000u | index});
  }
  numbered.width = static_cast<std::uint32_t>(numbered.points.size());
  numbered.height = 1;
  return numbered;
}

// The largest per-coordinate distance between a point and its decoded self, exactly: the
// kd-tree coder reorders points, so a copy numbered through its (exact, 8-bit) colour is encoded
// with the same options. Quantization treats every point on its own, so the positions come back
// exactly as in the timed encode. NaN when the cloud is too big to number or a step fails.
double MeasureMaxError(const PointCloud& cloud, const DracoOptions& options) {
  const PointCloud numbered = NumberedCopy(cloud);
  if (numbered.size() > (std::size_t{1} << 24)) return std::nan("");
  std::string bytes;
  PointCloud decoded;
  if (!EncodeDraco(numbered, options, &bytes).ok() || !DecodeDraco(bytes, &decoded).ok() ||
      decoded.size() != numbered.size()) {
    return std::nan("");
  }
  double worst = 0.0;
  for (const Point& d : decoded.points) {
    const std::uint32_t index = d.rgba & 0xFFFFFFu;
    if (index >= numbered.size()) return std::nan("");
    const Point& o = numbered.points[index];
    worst = std::max({worst, std::fabs(double{d.x} - o.x), std::fabs(double{d.y} - o.y),
                      std::fabs(double{d.z} - o.z)});
  }
  return worst;
}

struct Row {
  int speed = 0;
  int bits = 0;
  double bytes_per_point = 0;
  double kb_per_cloud = 0;
  double encode_ms = 0;           // EncodeDraco as the service calls it
  double libdraco_encode_ms = 0;  // the same with force_libdraco (speed 10 only; NaN otherwise)
  // Speed 10: libdraco's total over the clouds / ours, each cloud's median (NaN otherwise). The
  // medians above mix clouds of 0 to 27,000 points; this is what a frame costs on average.
  double speedup = 0;
  bool bytes_identical = true;  // speed 10: both encoders wrote the same bytes for every cloud
  double decode_ms = 0;
  double max_error = 0;    // NaN if not measured
  double error_bound = 0;  // the loosest bound over the clouds
  bool within_bound = true;
  std::string failure;
};

// Times `fn` once, in ms.
template <typename Fn>
double TimeMs(Fn&& fn) {
  const auto t0 = Clock::now();
  fn();
  return Ms(t0, Clock::now());
}

Row RunOne(const std::vector<PointCloud>& clouds, int speed, int bits, int iterations) {
  Row row;
  row.speed = speed;
  row.bits = bits;
  DracoOptions options;
  options.encode_speed = options.decode_speed = speed;
  options.position_bits = bits;
  options.color_bits = 8;
  DracoOptions libdraco = options;
  libdraco.force_libdraco = true;
  // At speed 10 EncodeDraco runs cloudcast's encoder; libdraco runs on the same clouds in the
  // same passes, each first every other pass (whoever runs second finds warm caches).
  const bool compare = speed == 10;
  row.libdraco_encode_ms = std::nan("");

  // Buffers reused across calls, as on the service's per-frame path.
  std::string bytes, libdraco_bytes;
  PointCloud decoded;
  std::vector<double> encode_ms, libdraco_ms, decode_ms, kb;
  // Per cloud: its timed passes, for the total of medians.
  std::vector<std::vector<double>> cloud_ours(clouds.size()), cloud_libdraco(clouds.size());
  std::uint64_t total_bytes = 0, total_points = 0;
  for (int pass = 0; pass <= iterations; ++pass) {  // pass 0 is the warm-up
    for (std::size_t c = 0; c < clouds.size(); ++c) {
      const PointCloud& cloud = clouds[c];
      DracoEncodeInfo info;
      absl::Status encoded, libdraco_encoded;
      double ours_t = 0, libdraco_t = 0;
      auto ours_run = [&] {
        ours_t = TimeMs([&] { encoded = EncodeDraco(cloud, options, &bytes, &info); });
      };
      auto libdraco_run = [&] {
        libdraco_t =
            TimeMs([&] { libdraco_encoded = EncodeDraco(cloud, libdraco, &libdraco_bytes); });
      };
      if (compare && pass % 2 == 1) libdraco_run();
      ours_run();
      if (compare && pass % 2 == 0) libdraco_run();
      const auto t1 = Clock::now();
      const absl::Status decoded_ok = DecodeDraco(bytes, &decoded);
      const auto t2 = Clock::now();
      if (!encoded.ok() || !decoded_ok.ok() || (compare && !libdraco_encoded.ok())) {
        row.failure = std::string(!encoded.ok()            ? encoded.message()
                                  : !libdraco_encoded.ok() ? libdraco_encoded.message()
                                                           : decoded_ok.message());
        return row;
      }
      if (pass == 0) {
        // Sizes, bounds and bytes are deterministic: taken once.
        total_bytes += info.bytes;
        total_points += decoded.size();
        kb.push_back(info.bytes / 1024.0);
        if (compare) row.bytes_identical = row.bytes_identical && bytes == libdraco_bytes;
        row.error_bound = std::max(row.error_bound, double{info.position_error_bound});
        const double error = MeasureMaxError(cloud, options);
        if (std::isnan(error) || std::isnan(row.max_error)) {
          row.max_error = std::nan("");
        } else {
          row.max_error = std::max(row.max_error, error);
          row.within_bound = row.within_bound && error <= info.position_error_bound;
        }
        continue;
      }
      encode_ms.push_back(ours_t);
      if (compare) {
        libdraco_ms.push_back(libdraco_t);
        cloud_ours[c].push_back(ours_t);
        cloud_libdraco[c].push_back(libdraco_t);
      }
      decode_ms.push_back(Ms(t1, t2));
    }
  }
  row.bytes_per_point = total_points > 0 ? double(total_bytes) / double(total_points) : 0.0;
  row.kb_per_cloud = Median(kb);
  row.encode_ms = Median(encode_ms);
  row.speedup = std::nan("");
  if (compare) {
    row.libdraco_encode_ms = Median(libdraco_ms);
    double ours_total = 0, libdraco_total = 0;
    for (std::size_t c = 0; c < clouds.size(); ++c) {
      ours_total += Median(cloud_ours[c]);
      libdraco_total += Median(cloud_libdraco[c]);
    }
    row.speedup = libdraco_total / ours_total;
  }
  row.decode_ms = Median(decode_ms);
  return row;
}

// The first cloud alone at the service's settings (speed 10, 10 bits raised to keep a quarter
// of the 3 cm leaf), ours and libdraco interleaved: the figure the encoder's target is set on.
struct FirstCloud {
  std::size_t points = 0;
  std::size_t bytes = 0;
  int runs = 0;
  double ours_ms = 0, libdraco_ms = 0;
  double ours_min_ms = 0, libdraco_min_ms = 0;
  double pair_ratio = 0;  // median of libdraco / ours over runs side by side: robust to load
  bool bytes_identical = false;
  bool ours_ran = false;
  std::string failure;
};

FirstCloud RunFirstCloud(const PointCloud& cloud, int runs) {
  FirstCloud r;
  r.runs = runs;
  DracoOptions ours;
  ours.max_position_error = 0.0075f;  // what the server sets for a 0.03 leaf
  DracoOptions libdraco = ours;
  libdraco.force_libdraco = true;
  std::string a, b;
  DracoEncodeInfo info;
  std::vector<double> ta, tb;
  for (int i = -3; i < runs; ++i) {  // 3 warm-up runs
    absl::Status sa, sb;
    double da = 0, db = 0;
    auto run_ours = [&] { da = TimeMs([&] { sa = EncodeDraco(cloud, ours, &a, &info); }); };
    auto run_libdraco = [&] { db = TimeMs([&] { sb = EncodeDraco(cloud, libdraco, &b); }); };
    if (i % 2 == 0) {
      run_ours();
      run_libdraco();
    } else {
      run_libdraco();
      run_ours();
    }
    if (!sa.ok() || !sb.ok()) {
      r.failure = std::string(!sa.ok() ? sa.message() : sb.message());
      return r;
    }
    if (i < 0) continue;
    ta.push_back(da);
    tb.push_back(db);
  }
  r.points = cloud.size();
  r.bytes = a.size();
  r.bytes_identical = a == b;
  r.ours_ran = info.encoder == DracoEncoder::kCloudcast;
  r.ours_ms = Median(ta);
  r.libdraco_ms = Median(tb);
  std::vector<double> ratios;
  for (std::size_t i = 0; i < ta.size(); ++i) ratios.push_back(tb[i] / ta[i]);
  r.pair_ratio = Median(ratios);
  r.ours_min_ms = *std::min_element(ta.begin(), ta.end());
  r.libdraco_min_ms = *std::min_element(tb.begin(), tb.end());
  return r;
}

// JSON has no NaN: an unmeasured value is null.
nlohmann::json OrNull(double v) {
  return std::isnan(v) ? nlohmann::json(nullptr) : nlohmann::json(v);
}

}  // namespace

nlohmann::json RunDracoTable(const std::vector<PointCloud>& clouds, int iterations,
                             std::ostream& out) {
  iterations = std::max(iterations, 1);
  char line[512];
  out << "enc ms: EncodeDraco (at speed 10 cloudcast's encoder, else libdraco); libdraco: the "
         "same\n"
         "clouds through libdraco 1.5.5 (force_libdraco), interleaved; x: libdraco's time / ours\n"
         "summed over the clouds (each cloud's median): the speed-up per frame.\n";
  std::snprintf(line, sizeof line, "%5s %4s %8s %9s %9s %9s %7s %9s %9s %11s %11s\n", "speed",
                "bits", "B/point", "KB/cloud", "enc ms", "libdraco", "x", "dec ms", "enc+dec",
                "max error", "bound");
  out << line;
  nlohmann::json rows = nlohmann::json::array();
  for (int speed : kSpeeds) {
    for (int bits : kPositionBits) {
      const Row r = RunOne(clouds, speed, bits, iterations);
      if (!r.failure.empty()) {
        out << "speed " << speed << " bits " << bits << ": " << r.failure << "\n";
        rows.push_back({{"speed", speed}, {"position_bits", bits}, {"error", r.failure}});
        continue;
      }
      const bool compared = !std::isnan(r.libdraco_encode_ms);
      const double speedup = r.speedup;
      char libdraco_col[32] = "-", speedup_col[32] = "-";
      if (compared) {
        std::snprintf(libdraco_col, sizeof libdraco_col, "%.3f", r.libdraco_encode_ms);
        std::snprintf(speedup_col, sizeof speedup_col, "%.1fx", speedup);
      }
      std::snprintf(line, sizeof line,
                    "%5d %4d %8.3f %9.1f %9.3f %9s %7s %9.3f %9.3f %11.6f %11.6f%s%s\n", r.speed,
                    r.bits, r.bytes_per_point, r.kb_per_cloud, r.encode_ms, libdraco_col,
                    speedup_col, r.decode_ms, r.encode_ms + r.decode_ms, r.max_error, r.error_bound,
                    r.within_bound ? "" : "  ABOVE BOUND",
                    r.bytes_identical ? "" : "  BYTES DIFFER FROM LIBDRACO");
      out << line;
      nlohmann::json row = {{"speed", r.speed},
                            {"position_bits", r.bits},
                            {"bytes_per_point", r.bytes_per_point},
                            {"kb_per_cloud", r.kb_per_cloud},
                            {"encode_ms", r.encode_ms},
                            {"libdraco_encode_ms", OrNull(r.libdraco_encode_ms)},
                            {"encode_speedup", OrNull(speedup)},
                            {"decode_ms", r.decode_ms},
                            {"error_bound", r.error_bound},
                            {"within_bound", r.within_bound}};
      if (compared) row["bytes_identical"] = r.bytes_identical;
      row["max_error"] = OrNull(r.max_error);
      rows.push_back(std::move(row));
    }
  }

  if (!clouds.empty()) {
    const FirstCloud f = RunFirstCloud(clouds.front(), kFirstCloudRuns);
    if (!f.failure.empty()) {
      out << "first cloud: " << f.failure << "\n";
      rows.push_back({{"first_cloud", {{"error", f.failure}}}});
    } else {
      std::snprintf(line, sizeof line,
                    "first cloud (New Tsukuba 00001 when the data is there; %zu points), speed 10, "
                    "10 bits, max error 0.0075:\n  ours %.3f ms, libdraco %.3f ms (medians of %d "
                    "interleaved runs): %.1fx; median of the runs' ratios %.1fx; minima %.3f / "
                    "%.3f ms: %.1fx; %zu bytes, %s\n",
                    f.points, f.ours_ms, f.libdraco_ms, f.runs, f.libdraco_ms / f.ours_ms,
                    f.pair_ratio, f.ours_min_ms, f.libdraco_min_ms,
                    f.libdraco_min_ms / f.ours_min_ms, f.bytes,
                    !f.ours_ran         ? "OUR ENCODER DID NOT RUN"
                    : f.bytes_identical ? "identical to libdraco's"
                                        : "BYTES DIFFER FROM LIBDRACO");
      out << line;
      rows.push_back({{"first_cloud",
                       {{"points", f.points},
                        {"bytes", f.bytes},
                        {"runs", f.runs},
                        {"encode_ms", f.ours_ms},
                        {"libdraco_encode_ms", f.libdraco_ms},
                        {"encode_speedup", f.libdraco_ms / f.ours_ms},
                        {"encode_speedup_median_of_pairs", f.pair_ratio},
                        {"encode_min_ms", f.ours_min_ms},
                        {"libdraco_encode_min_ms", f.libdraco_min_ms},
                        {"bytes_identical", f.bytes_identical},
                        {"cloudcast_encoder_ran", f.ours_ran}}}});
    }
  }
  return rows;
}

}  // namespace cloudcast::bench
