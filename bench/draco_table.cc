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

namespace cloudcast::bench {
namespace {

using Clock = std::chrono::steady_clock;

constexpr int kSpeeds[] = {0, 3, 5, 7, 10};
constexpr int kPositionBits[] = {10, 11, 12, 14, 16};

double Ms(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const std::size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + mid, v.end());
  if (v.size() % 2 == 1) return v[mid];
  const double upper = v[mid];
  return 0.5 * (upper + *std::max_element(v.begin(), v.begin() + mid));
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
  double encode_ms = 0;
  double decode_ms = 0;
  double max_error = 0;    // NaN if not measured
  double error_bound = 0;  // the loosest bound over the clouds
  bool within_bound = true;
  std::string failure;
};

Row RunOne(const std::vector<PointCloud>& clouds, int speed, int bits, int iterations) {
  Row row;
  row.speed = speed;
  row.bits = bits;
  DracoOptions options;
  options.encode_speed = options.decode_speed = speed;
  options.position_bits = bits;
  options.color_bits = 8;

  // Buffers reused across calls, as on the service's per-frame path.
  std::string bytes;
  PointCloud decoded;
  std::vector<double> encode_ms, decode_ms, kb;
  std::uint64_t total_bytes = 0, total_points = 0;
  for (int pass = 0; pass <= iterations; ++pass) {  // pass 0 is the warm-up
    for (const PointCloud& cloud : clouds) {
      DracoEncodeInfo info;
      const auto t0 = Clock::now();
      const absl::Status encoded = EncodeDraco(cloud, options, &bytes, &info);
      const auto t1 = Clock::now();
      const absl::Status decoded_ok = DecodeDraco(bytes, &decoded);
      const auto t2 = Clock::now();
      if (!encoded.ok() || !decoded_ok.ok()) {
        row.failure = std::string(encoded.ok() ? decoded_ok.message() : encoded.message());
        return row;
      }
      if (pass == 0) {
        // Sizes and bounds are deterministic: taken once.
        total_bytes += info.bytes;
        total_points += decoded.size();
        kb.push_back(info.bytes / 1024.0);
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
      encode_ms.push_back(Ms(t0, t1));
      decode_ms.push_back(Ms(t1, t2));
    }
  }
  row.bytes_per_point = total_points > 0 ? double(total_bytes) / double(total_points) : 0.0;
  row.kb_per_cloud = Median(kb);
  row.encode_ms = Median(encode_ms);
  row.decode_ms = Median(decode_ms);
  return row;
}

}  // namespace

nlohmann::json RunDracoTable(const std::vector<PointCloud>& clouds, int iterations,
                             std::ostream& out) {
  iterations = std::max(iterations, 1);
  char line[200];
  std::snprintf(line, sizeof line, "%5s %4s %8s %9s %9s %9s %9s %11s %11s\n", "speed", "bits",
                "B/point", "KB/cloud", "enc ms", "dec ms", "enc+dec", "max error", "bound");
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
      std::snprintf(line, sizeof line, "%5d %4d %8.3f %9.1f %9.3f %9.3f %9.3f %11.6f %11.6f%s\n",
                    r.speed, r.bits, r.bytes_per_point, r.kb_per_cloud, r.encode_ms, r.decode_ms,
                    r.encode_ms + r.decode_ms, r.max_error, r.error_bound,
                    r.within_bound ? "" : "  ABOVE BOUND");
      out << line;
      nlohmann::json row = {{"speed", r.speed},
                            {"position_bits", r.bits},
                            {"bytes_per_point", r.bytes_per_point},
                            {"kb_per_cloud", r.kb_per_cloud},
                            {"encode_ms", r.encode_ms},
                            {"decode_ms", r.decode_ms},
                            {"error_bound", r.error_bound},
                            {"within_bound", r.within_bound}};
      // JSON has no NaN: an unmeasured error is null.
      row["max_error"] =
          std::isnan(r.max_error) ? nlohmann::json(nullptr) : nlohmann::json(r.max_error);
      rows.push_back(std::move(row));
    }
  }
  return rows;
}

}  // namespace cloudcast::bench
