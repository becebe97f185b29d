// The HTML report: one file, inline CSS and SVG, system fonts only, nothing loaded from anywhere.
#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <cmath>

#include "cloudcast/load/report.h"

namespace cloudcast::load {
namespace {

std::string Escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

// A "nice" axis maximum and tick step for values up to `max`.
void NiceAxis(double max, double* top, double* step) {
  if (!(max > 0)) max = 1;
  const double raw = max / 5;
  const double mag = std::pow(10, std::floor(std::log10(raw)));
  const double f = raw / mag;
  *step = (f <= 1 ? 1 : f <= 2 ? 2 : f <= 5 ? 5 : 10) * mag;
  *top = std::ceil(max / *step) * *step;
}

struct Line {
  std::string name, colour;
  std::vector<double> y;
  bool dashed = false;
};

constexpr int kW = 900, kH = 300, kLeft = 70, kRight = 20, kTop = 30, kBottom = 45;

std::string Frame(const std::string& id, const std::string& title) {
  return fmt::format(
      "<svg id=\"{}\" class=\"chart\" xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" "
      "height=\"{}\" viewBox=\"0 0 {} {}\" role=\"img\" aria-label=\"{}\">\n"
      "<rect x=\"0\" y=\"0\" width=\"{}\" height=\"{}\" fill=\"#ffffff\"/>\n"
      "<text x=\"{}\" y=\"18\" class=\"title\">{}</text>\n",
      id, kW, kH, kW, kH, Escape(title), kW, kH, kLeft, Escape(title));
}

// A line chart of `lines` over x (seconds), with a y axis labelled `unit`.
std::string LineChart(const std::string& id, const std::string& title, const std::string& unit,
                      const std::vector<double>& x, const std::vector<Line>& lines) {
  std::string svg = Frame(id, title);
  const double pw = kW - kLeft - kRight, ph = kH - kTop - kBottom;
  double xmax = x.empty() ? 1 : std::max(1.0, x.back()), ymax = 0;
  for (const Line& l : lines) {
    for (double v : l.y) ymax = std::max(ymax, v);
  }
  double ytop, ystep, xtop, xstep;
  NiceAxis(ymax, &ytop, &ystep);
  NiceAxis(xmax, &xtop, &xstep);
  auto X = [&](double v) { return kLeft + pw * v / xtop; };
  auto Y = [&](double v) { return kTop + ph * (1 - v / ytop); };
  for (double v = 0; v <= ytop + ystep / 2; v += ystep) {
    svg += fmt::format(
        "<line x1=\"{}\" y1=\"{:.1f}\" x2=\"{}\" y2=\"{:.1f}\" class=\"grid\"/>"
        "<text x=\"{}\" y=\"{:.1f}\" class=\"tick\" text-anchor=\"end\">{:g}</text>\n",
        kLeft, Y(v), kW - kRight, Y(v), kLeft - 6, Y(v) + 4, v);
  }
  for (double v = 0; v <= xtop + xstep / 2; v += xstep) {
    svg += fmt::format(
        "<line x1=\"{:.1f}\" y1=\"{}\" x2=\"{:.1f}\" y2=\"{}\" class=\"axis\"/>"
        "<text x=\"{:.1f}\" y=\"{}\" class=\"tick\" text-anchor=\"middle\">{:g}</text>\n",
        X(v), kTop + ph, X(v), kTop + ph + 5, X(v), kTop + ph + 18, v);
  }
  svg += fmt::format(
      "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" class=\"axis\"/>"
      "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" class=\"axis\"/>\n",
      kLeft, kTop, kLeft, kTop + ph, kLeft, kTop + ph, kW - kRight, kTop + ph);
  svg +=
      fmt::format("<text x=\"{}\" y=\"{}\" class=\"tick\" text-anchor=\"middle\">seconds</text>\n",
                  kLeft + pw / 2, kH - 8);
  svg += fmt::format(
      "<text x=\"16\" y=\"{}\" class=\"tick\" text-anchor=\"middle\" transform=\"rotate(-90 16 "
      "{})\">{}</text>\n",
      kTop + ph / 2, kTop + ph / 2, Escape(unit));
  double legend_x = kW - kRight - 10;
  for (auto it = lines.rbegin(); it != lines.rend(); ++it) {
    const Line& l = *it;
    const double w = 14 + 7.0 * l.name.size() + 16;
    legend_x -= w;
    svg += fmt::format(
        "<line x1=\"{:.0f}\" y1=\"14\" x2=\"{:.0f}\" y2=\"14\" stroke=\"{}\" stroke-width=\"3\"{}/>"
        "<text x=\"{:.0f}\" y=\"18\" class=\"tick\">{}</text>\n",
        legend_x, legend_x + 12, l.colour, l.dashed ? " stroke-dasharray=\"5 3\"" : "",
        legend_x + 16, Escape(l.name));
  }
  for (const Line& l : lines) {
    std::string points;
    for (std::size_t i = 0; i < l.y.size() && i < x.size(); ++i) {
      points += fmt::format("{:.1f},{:.1f} ", X(x[i]), Y(l.y[i]));
    }
    svg +=
        fmt::format("<polyline points=\"{}\" fill=\"none\" stroke=\"{}\" stroke-width=\"2\"{}/>\n",
                    points, l.colour, l.dashed ? " stroke-dasharray=\"5 3\"" : "");
    if (l.y.size() == 1) {
      svg += fmt::format("<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"3\" fill=\"{}\"/>\n", X(x[0]),
                         Y(l.y[0]), l.colour);
    }
  }
  return svg + "</svg>\n";
}

// The latency histogram on a logarithmic axis: 8 bins per doubling from the fastest frame to
// the slowest.
std::string HistogramChart(const Histogram& h) {
  std::string svg = Frame("histogram", "Latency from the intended send time: frames per bin");
  const double pw = kW - kLeft - kRight, ph = kH - kTop - kBottom;
  if (h.count() == 0) {
    return svg + fmt::format(
                     "<text x=\"{}\" y=\"{}\" class=\"tick\">no frames answered</text>"
                     "</svg>\n",
                     kLeft + 10, kTop + 40);
  }
  const double lo = std::max<double>(1000, static_cast<double>(h.min()));  // >= 1 us
  const double hi = std::max(lo * 1.01, static_cast<double>(h.max()) + 1);
  const double decades_lo = std::floor(std::log10(lo)), decades_hi = std::ceil(std::log10(hi));
  const int per_doubling = 8;
  std::vector<std::int64_t> bounds;
  for (double v = std::pow(10, decades_lo); v <= std::pow(10, decades_hi) * 1.0001;
       v *= std::pow(2.0, 1.0 / per_doubling)) {
    bounds.push_back(static_cast<std::int64_t>(v));
  }
  std::vector<std::uint64_t> counts = h.CountBetween(bounds);
  std::uint64_t cmax = 1;
  for (auto c : counts) cmax = std::max(cmax, c);
  double ytop, ystep;
  NiceAxis(static_cast<double>(cmax), &ytop, &ystep);
  const double l0 = decades_lo, l1 = decades_hi;
  auto X = [&](double v) { return kLeft + pw * (std::log10(v) - l0) / (l1 - l0); };
  auto Y = [&](double v) { return kTop + ph * (1 - v / ytop); };
  for (double v = 0; v <= ytop + ystep / 2; v += ystep) {
    svg += fmt::format(
        "<line x1=\"{}\" y1=\"{:.1f}\" x2=\"{}\" y2=\"{:.1f}\" class=\"grid\"/>"
        "<text x=\"{}\" y=\"{:.1f}\" class=\"tick\" text-anchor=\"end\">{:g}</text>\n",
        kLeft, Y(v), kW - kRight, Y(v), kLeft - 6, Y(v) + 4, v);
  }
  for (std::size_t i = 0; i < counts.size(); ++i) {
    if (counts[i] == 0) continue;
    const double x0 = X(static_cast<double>(bounds[i])), x1 = X(static_cast<double>(bounds[i + 1]));
    svg += fmt::format(
        "<rect x=\"{:.1f}\" y=\"{:.1f}\" width=\"{:.1f}\" height=\"{:.1f}\" class=\"bar\"/>\n", x0,
        Y(static_cast<double>(counts[i])), std::max(1.0, x1 - x0 - 1),
        ph - (Y(static_cast<double>(counts[i])) - kTop));
  }
  for (double d = l0; d <= l1 + 1e-9; d += 1) {
    for (int m : {1, 2, 5}) {
      const double v = m * std::pow(10, d);
      if (std::log10(v) > l1 + 1e-9) break;
      const double ms = v / 1e6;
      svg += fmt::format(
          "<line x1=\"{:.1f}\" y1=\"{}\" x2=\"{:.1f}\" y2=\"{}\" class=\"axis\"/>"
          "<text x=\"{:.1f}\" y=\"{}\" class=\"tick\" text-anchor=\"middle\">{:g}</text>\n",
          X(v), kTop + ph, X(v), kTop + ph + 5, X(v), kTop + ph + 18, ms);
    }
  }
  for (double p : {50.0, 99.0, 99.9}) {
    const double v = static_cast<double>(std::max<std::int64_t>(h.Percentile(p), 1000));
    svg += fmt::format(
        "<line x1=\"{:.1f}\" y1=\"{}\" x2=\"{:.1f}\" y2=\"{}\" class=\"marker\"/>"
        "<text x=\"{:.1f}\" y=\"{}\" class=\"tick\">p{:g}</text>\n",
        X(v), kTop, X(v), kTop + ph, X(v) + 3, kTop + 12, p);
  }
  svg += fmt::format(
      "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" class=\"axis\"/>"
      "<text x=\"{}\" y=\"{}\" class=\"tick\" text-anchor=\"middle\">milliseconds (log scale)"
      "</text>\n",
      kLeft, kTop + ph, kW - kRight, kTop + ph, kLeft + pw / 2, kH - 8);
  return svg + "</svg>\n";
}

std::string Row(const std::string& name, const std::string& value) {
  return fmt::format("<tr><th>{}</th><td>{}</td></tr>\n", Escape(name), Escape(value));
}

}  // namespace

std::string Html(const Report& r) {
  const Totals& t = r.totals;
  std::string page =
      "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n"
      "<title>cloudcast-load report</title>\n<style>\n"
      "body{font-family:sans-serif;margin:24px;color:#222;background:#fafafa}"
      "h1{font-size:22px;margin:0 0 4px}h2{font-size:17px;margin:24px 0 8px}"
      "p.sub{color:#555;margin:0 0 16px}"
      "table{border-collapse:collapse;background:#fff;margin:0 16px 12px 0}"
      "th,td{border:1px solid #ddd;padding:4px 10px;text-align:right;font-size:14px}"
      "th{background:#f0f0f0;text-align:left}.chart{display:block;margin:8px 0;"
      "border:1px solid #ddd}.tables{display:flex;flex-wrap:wrap;align-items:flex-start}"
      ".title{font-size:15px;font-weight:bold;fill:#222}.tick{font-size:12px;fill:#444}"
      ".grid{stroke:#e6e6e6}.axis{stroke:#888}.bar{fill:#4c78a8}"
      ".marker{stroke:#e45756;stroke-dasharray:4 3}\n"
      "</style></head><body>\n";
  page += "<h1>cloudcast-load</h1>\n";
  page += fmt::format(
      "<p class=\"sub\">{} streams over {} connections to {} &middot; {} "
      "&middot; {}</p>\n",
      r.streams, r.connections, Escape(r.target), Escape(r.schedule), Escape(r.delivery));
  page += "<div class=\"tables\">\n<table id=\"summary\">\n";
  page += Row("frames", r.frames);
  page +=
      Row("ended", fmt::format("{} after {:.2f} s", Name(r.result.end_reason), r.result.elapsed_s));
  page += Row("sent / answered", fmt::format("{} / {}", t.sent, t.answered));
  page += Row("throughput", fmt::format("{:.1f} frames/s", r.answered_fps()));
  page += Row("encoding",
              fmt::format("{}, {:.1f} KB sent a frame", r.encoding.empty() ? "?" : r.encoding,
                          r.bytes_per_frame() / 1024));
  if (r.near_lossless) {
    page += Row("near-lossless",
                fmt::format("{}; {:.1f} KB a request (lossless {:.1f} KB)",
                            Describe(*r.near_lossless), r.near_lossless->request_bytes / 1024,
                            r.near_lossless->request_bytes_lossless / 1024));
  }
  if (r.video) {
    page += Row("video", fmt::format("{}; a sequence of {} frames, {:.1f} KB of pictures a frame, "
                                     "encoded once in {:.2f} ms a frame",
                                     r.video->settings, r.video->length,
                                     r.video->video_bytes_mean / 1024, r.video->encode_ms_median));
    page += Row("IDRs sent (asked for) / replies asking / skipped",
                fmt::format("{} ({}) / {} / {}", t.keyframes_sent, t.keyframe_restarts,
                            t.keyframe_needed, t.skipped));
  }
  if (r.live_video) {
    page += Row(
        "video",
        fmt::format("{}; encoded live by each stream at its rate controller's bitrate: "
                    "{} frames, {:.1f} KB of pictures a frame, encoder CPU {:.2f} ms a "
                    "frame median ({:.2f} p99)",
                    *r.live_video, r.totals.live_encoded, r.live_picture_bytes_per_frame() / 1024,
                    r.live_encode_us.Percentile(50) / 1e3, r.live_encode_us.Percentile(99) / 1e3));
    page +=
        Row("IDRs sent (asked for) / replies asking",
            fmt::format("{} ({}) / {}", t.keyframes_sent, t.keyframe_restarts, t.keyframe_needed));
  }
  page += Row("generator CPU", fmt::format("{:.2f} s, {:.3f} ms a frame sent", r.result.cpu_s,
                                           r.generator_ms_per_frame()));
  page += Row("frame errors / lost / unsent",
              fmt::format("{} / {} / {}", t.frame_errors, t.lost, t.unsent));
  page += Row("dropped (DELIVERY_LATEST)", std::to_string(t.drops));
  page += Row("late sends", fmt::format("{} (previous write not done {}, generator behind {})",
                                        t.late(), t.late_flow_control, t.late_scheduler));
  page += Row("balancing", r.lb_policy);
  if (r.resilient) {
    page += Row("resent / duplicates", fmt::format("{} / {}", t.resent, t.duplicates));
    page += Row("reconnects (of attempts)",
                fmt::format("{} ({}), p50 {:.1f} ms, max {:.1f} ms", t.reconnects,
                            t.reconnect_attempts, PercentileOf(r.reconnect_ns, 50) / 1e6,
                            (r.reconnect_ns.empty() ? 0 : r.reconnect_ns.back()) / 1e6));
    page += Row("streams given up", std::to_string(t.streams_given_up));
  }
  page += "</table>\n<table id=\"latency\">\n<tr><th>ms</th>";
  for (double p : ReportPercentiles()) page += fmt::format("<th>p{:g}</th>", p);
  page += "<th>max</th><th>mean</th></tr>\n";
  for (const auto* row : {&r.latency, &r.service}) {
    page += fmt::format("<tr><th>{}</th>",
                        row == &r.latency ? "latency from intended time" : "service time");
    for (double p : ReportPercentiles()) {
      page += fmt::format("<td>{:.2f}</td>", row->Percentile(p) / 1e6);
    }
    page +=
        fmt::format("<td>{:.2f}</td><td>{:.2f}</td></tr>\n", row->max() / 1e6, row->mean() / 1e6);
  }
  page += "</table>\n";
  if (!r.replicas.empty()) {
    page +=
        "<table id=\"replicas\">\n<tr><th>replica</th><th>streams</th><th>at start</th>"
        "<th>frames</th><th>share</th></tr>\n";
    std::uint64_t sum = 0;
    for (const auto& [name, rep] : r.replicas) sum += rep.frames;
    for (const auto& [name, rep] : r.replicas) {
      page += fmt::format("<tr><th>{}</th><td>{}</td><td>{}</td><td>{}</td><td>{:.1f}%</td></tr>\n",
                          Escape(name), rep.streams, rep.streams_at_start, rep.frames,
                          sum ? 100.0 * rep.frames / sum : 0.0);
    }
    page += "</table>\n";
  }
  page += "</div>\n";

  std::vector<double> x;
  Line p50{"p50", "#4c78a8", {}}, p90{"p90", "#f58518", {}}, p99{"p99", "#e45756", {}};
  Line fps{"answered frames/s", "#54a24b", {}}, sent{"sent frames/s", "#9d755d", {}, true};
  for (const SecondStats& s : r.series) {
    if (s.duration_s < 0.05) continue;  // the sliver after the last full second
    x.push_back(s.t_end_s);
    p50.y.push_back(s.p50 / 1e6);
    p90.y.push_back(s.p90 / 1e6);
    p99.y.push_back(s.p99 / 1e6);
    fps.y.push_back(s.fps());
    sent.y.push_back(s.duration_s > 0 ? s.sent / s.duration_s : 0);
  }
  page += "<h2>Over time (per second)</h2>\n";
  page += LineChart("latency-chart", "Latency from the intended send time, per second", "ms", x,
                    {p50, p90, p99});
  page += LineChart("throughput-chart", "Throughput", "frames/s", x, {fps, sent});
  if (r.rate.samples > 0) {
    // --rate-control: what the senders' controllers decided, beside what they measured.
    std::vector<double> rx;
    Line target{"target (Mbit/s, all streams)", "#4c78a8", {}};
    Line queue{"queueing delay (ms / 10)", "#e45756", {}, true};
    Line kb{"KB per frame / 10", "#54a24b", {}, true};
    for (const SecondStats& s : r.series) {
      if (s.duration_s < 0.05 || s.rate.samples == 0) continue;
      rx.push_back(s.t_end_s);
      target.y.push_back(s.rate.target_bps / 1e6);
      queue.y.push_back(s.rate.queue_delay_ms / 10);
      kb.y.push_back(s.rate.frame_bytes / 1e4);
    }
    page += LineChart("rate-chart", "Rate control: target bitrate, queueing delay, frame size", "",
                      rx, {target, queue, kb});
  }
  {
    // The way back: what the replies took, and (--rate-control) the bitrate the senders let them
    // take and the cap that asked the server for it.
    std::vector<double> dx;
    Line reply_kb{"KB per reply", "#54a24b", {}};
    Line reply_mbps{"replies (Mbit/s, all streams)", "#4c78a8", {}};
    Line allowed{"replies' bitrate allowed (Mbit/s, all streams)", "#f58518", {}, true};
    Line cap{"cap (KB per reply)", "#e45756", {}, true};
    bool capped = false;
    for (const SecondStats& s : r.series) {
      if (s.duration_s < 0.05) continue;
      dx.push_back(s.t_end_s);
      reply_kb.y.push_back(s.answered > 0 ? static_cast<double>(s.bytes_received) /
                                                static_cast<double>(s.answered) / 1e3
                                          : 0);
      reply_mbps.y.push_back(static_cast<double>(s.bytes_received) * 8 / s.duration_s / 1e6);
      allowed.y.push_back(s.rate.reply_target_bps / 1e6);
      cap.y.push_back(s.rate.reply_cap_bytes / 1e3);
      capped = capped || s.rate.reply_target_bps > 0;
    }
    std::vector<Line> lines = {reply_kb, reply_mbps};
    if (capped) {
      lines.push_back(allowed);
      lines.push_back(cap);
    }
    page += LineChart("downlink-chart", "Downlink: the replies", "", dx, lines);
  }
  if (!r.memory.empty()) {
    std::vector<double> mx;
    Line rss{"RSS", "#b279a2", {}};
    for (const MemorySample& m : r.memory) {
      if (m.rss_bytes == 0) continue;
      mx.push_back(m.t_s);
      rss.y.push_back(m.rss_bytes / 1e6);
    }
    page += LineChart("memory-chart", "Server memory (resident, " + Escape(r.memory_url) + ")",
                      "MB", mx, {rss});
  }
  if (r.soak) {
    const SoakVerdict& v = r.soak_verdict;
    page += fmt::format(
        "<p id=\"soak\">Soak <b>{}</b>: after the {:g} s warm-up memory {:.1f} "
        "&rarr; peak {:.1f} MB (bound +{:.1f} MB).</p>\n",
        v.passed ? "passed" : "FAILED", r.soak_bounds.warmup_s, v.baseline_bytes / 1e6,
        v.peak_bytes / 1e6, r.soak_bounds.max_growth_bytes / 1e6);
    if (!v.failures.empty()) {
      page += "<ul>\n";
      for (const std::string& f : v.failures) page += "<li>" + Escape(f) + "</li>\n";
      page += "</ul>\n";
    }
  }
  page += "<h2>Distribution</h2>\n";
  page += HistogramChart(r.latency);
  // Per stream, bounded: a page stays readable with thousands of streams (the JSON has them all).
  constexpr std::size_t kMaxRows = 200;
  if (!r.streams_detail.empty()) {
    page += fmt::format("<h2>Streams{}</h2>\n<table id=\"streams\">\n",
                        r.streams_detail.size() > kMaxRows
                            ? fmt::format(" (first {} of {})", kMaxRows, r.streams_detail.size())
                            : "");
    page +=
        "<tr><th>stream</th><th>sent</th><th>answered</th><th>resent</th><th>lost</th>"
        "<th>errors</th><th>dropped</th><th>reconnects</th><th>reconnect ms</th>"
        "<th>replicas</th></tr>\n";
    for (std::size_t i = 0; i < r.streams_detail.size() && i < kMaxRows; ++i) {
      const StreamStats& s = r.streams_detail[i];
      std::string ms, path;
      for (std::int64_t v : s.reconnect_ns)
        ms += fmt::format("{}{:.0f}", ms.empty() ? "" : " ", v / 1e6);
      for (const std::string& name : s.replicas) path += (path.empty() ? "" : " > ") + name;
      page += fmt::format(
          "<tr><th>{}</th><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>"
          "<td>{}/{}</td><td>{}</td><td>{}{}</td></tr>\n",
          s.index, s.sent, s.answered, s.resent, s.lost, s.frame_errors, s.dropped,
          s.reconnect_ns.size(), s.reconnect_attempts, ms.empty() ? "-" : ms, Escape(path),
          s.gave_up ? " (gave up)" : "");
    }
    page += "</table>\n";
  }
  if (!r.errors.empty()) {
    page += "<h2>Errors</h2>\n<table id=\"errors\">\n";
    for (const auto& [message, n] : r.errors) page += Row(message, std::to_string(n));
    page += "</table>\n";
  }
  page += "</body></html>\n";
  return page;
}

}  // namespace cloudcast::load
