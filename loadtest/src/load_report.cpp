// The load-test report writers. The HTML page is built as one string: a header table, summary
// tables and four SVG plots drawn here (linear or log axes with "nice" ticks), with no scripts and
// no external resources, so the file can be mailed, archived or opened offline as it is.
#include "vts/loadtest/load_report.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <functional>
#include <limits>
#include <optional>
#include <string_view>
#include <utility>

#include "vts/base/file_io.hpp"
#include "vts/loadtest/load_gates.hpp"
#include "vts/plot/svg_plot.hpp"

namespace vts::loadtest {
namespace {

using nlohmann::json;
using plot::Axis;
using plot::AxisSet;
using plot::display_width;
using plot::html_escape;
using plot::kMarginBottom;
using plot::kMarginLeft;
using plot::kMarginTop;
using plot::kPlotHeight;
using plot::kPlotWidth;
using plot::Plot;
using plot::px;
using plot::render_plot;
using plot::Series;
using plot::valid_utf8;
namespace fs = std::filesystem;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// ---------------------------------------------------------------------------------------------
// Text

// Text for the terminal: valid UTF-8 without controls, one line.
std::string terminal_safe(std::string_view s) {
  std::string out = valid_utf8(s, true);
  std::replace(out.begin(), out.end(), '\n', ' ');
  std::replace(out.begin(), out.end(), '\t', ' ');
  return out;
}

std::string printf_string(const char* format, double value) {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, value);
  return buf;
}

// Three significant digits, no exponent, for values >= 0 of everyday magnitude.
std::string three_digits(double v) {
  const double a = std::fabs(v);
  if (a == 0) return "0";
  if (a < 10) return printf_string("%.2f", v);
  if (a < 100) return printf_string("%.1f", v);
  return printf_string("%.0f", v);
}

// "0 ns", "850 ns", "12.3 us", "1.25 ms", "12.0 s", "2.50 min". `micro` is the microsecond
// symbol: "us" on the terminal, U+00B5 in HTML.
std::string format_ns(double ns, std::string_view micro = "us") {
  if (!std::isfinite(ns)) return "-";
  if (ns < 1e3) return printf_string("%.0f", ns) + " ns";
  if (ns < 1e6) return three_digits(ns / 1e3) + " " + std::string(micro);
  if (ns < 1e9) return three_digits(ns / 1e6) + " ms";
  if (ns < 100e9) return three_digits(ns / 1e9) + " s";
  return three_digits(ns / 60e9) + " min";
}

// Axis tick labels: as format_ns, without trailing zeros ("1 s", "20 ms", "2.5 ms").
std::string format_ns_tick(double ns) {
  static constexpr std::string_view kMicro = "\xC2\xB5s";
  const std::pair<double, std::string_view> units[] = {
      {60e9, "min"}, {1e9, "s"}, {1e6, "ms"}, {1e3, kMicro}, {1, "ns"}};
  for (const auto& [scale, unit] : units) {
    if (ns >= scale || scale == 1) {
      if (scale == 60e9 && ns < 100e9) continue;
      return printf_string("%.3g", ns / scale) + " " + std::string(unit);
    }
  }
  return "";
}

std::string format_bytes(double bytes) {
  if (bytes < 1e3) return printf_string("%.0f", bytes) + " B";
  if (bytes < 1e6) return three_digits(bytes / 1e3) + " kB";
  if (bytes < 1e9) return three_digits(bytes / 1e6) + " MB";
  if (bytes < 1e12) return three_digits(bytes / 1e9) + " GB";
  return three_digits(bytes / 1e12) + " TB";
}

std::string format_count(std::uint64_t n) {
  return std::to_string(n);
}

std::string format_rate(double per_s) {
  return three_digits(per_s);
}

std::string format_percent(double fraction) {
  if (!std::isfinite(fraction)) return "-";
  if (fraction > 0 && fraction < 0.001) return printf_string("%.3f", fraction * 100) + "%";
  return printf_string("%.1f", fraction * 100) + "%";
}

std::int64_t unix_ms(std::chrono::system_clock::time_point t) {
  return std::chrono::duration_cast<std::chrono::milliseconds>(t.time_since_epoch()).count();
}

// "2026-11-23T12:00:00.123Z" (iso) or "2026-11-23 12:00:00 UTC".
std::string format_time(std::chrono::system_clock::time_point t, bool iso) {
  const std::int64_t ms = unix_ms(t);
  std::int64_t secs = ms / 1000, frac = ms % 1000;
  if (frac < 0) {
    frac += 1000;
    secs -= 1;
  }
  const std::time_t tt = static_cast<std::time_t>(secs);
  std::tm tm{};
  if (::gmtime_r(&tt, &tm) == nullptr) return "?";
  char buf[64];
  std::strftime(buf, sizeof buf, iso ? "%Y-%m-%dT%H:%M:%S" : "%Y-%m-%d %H:%M:%S", &tm);
  std::string out = buf;
  if (iso) {
    char f[8];
    std::snprintf(f, sizeof f, ".%03dZ", static_cast<int>(frac));
    out += f;
  } else {
    out += " UTC";
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Derived figures shared by the three writers

// A figure the engine may have left NaN or infinite (a division by a zero-length run), as 0.
double finite(double v) {
  return std::isfinite(v) ? v : 0.0;
}

double per_second(double amount, double duration_s) {
  return duration_s > 0 ? amount / duration_s : 0.0;
}

// a + b, or 2^64 - 1 where that would wrap (a report read back never holds such counts; one
// made in memory might).
std::uint64_t saturated_sum(std::uint64_t a, std::uint64_t b) {
  std::uint64_t sum;
  return __builtin_add_overflow(a, b, &sum) ? std::numeric_limits<std::uint64_t>::max() : sum;
}

double ratio(std::uint64_t part, std::uint64_t whole) {
  return whole == 0 ? 0.0 : static_cast<double>(part) / static_cast<double>(whole);
}

const char* mode_name(LoopMode mode) {
  return mode == LoopMode::open ? "open" : "closed";
}

struct Metric {
  const char* key;    // JSON key and plot/table id
  const char* label;  // for people
  const LatencyHistogram* histogram;
};

std::vector<Metric> metrics(const LoadReport& r) {
  return {{"queue_time", "queue time", &r.queue_time},
          {"ttfb", "time to first byte", &r.ttfb},
          {"total", "total (request)", &r.total},
          {"first_visible", "first visible tile", &r.first_visible},
          {"full_resolution", "full resolution", &r.full_resolution}};
}

// The percentiles every view shows, with their labels and JSON keys.
struct Quantile {
  double p;
  const char* label;
  const char* key;
};
constexpr Quantile kQuantiles[] = {
    {50, "p50", "p50"}, {90, "p90", "p90"}, {99, "p99", "p99"}, {99.9, "p99.9", "p99_9"}};

std::string scenario_text(const LoadReport& r, bool for_terminal) {
  auto clean = [&](const std::string& s) { return for_terminal ? terminal_safe(s) : s; };
  std::string s = std::to_string(r.viewers) + (r.viewers == 1 ? " viewer" : " viewers");
  if (!r.path.empty()) s += " on path \"" + clean(r.path) + "\"";
  if (finite(r.fps) > 0) s += " at " + printf_string("%g", r.fps) + " fps";
  s += ", " + std::string(mode_name(r.mode)) + " loop";
  if (r.mode == LoopMode::open)
    s += " at " + printf_string("%g", finite(r.rate)) + " " + clean(r.rate_unit);
  return s;
}

// ---------------------------------------------------------------------------------------------
// JSON

json histogram_json(const LatencyHistogram& h) {
  json buckets = json::array();
  for (const auto& b : h.buckets()) {
    buckets.push_back(json{{"low", b.low}, {"high", b.high}, {"count", b.count}});
  }
  json j = {{"count", h.count()}, {"min", h.min()}, {"mean", h.mean()}};
  for (const auto& q : kQuantiles) j[q.key] = h.percentile(q.p);
  j["max"] = h.max();
  j["relative_error"] = h.relative_error();
  j["sub_bucket_bits"] = h.sub_bucket_bits();
  j["buckets"] = std::move(buckets);
  return j;
}

// ---------------------------------------------------------------------------------------------
// Plain-text tables

class TextTable {
 public:
  // The first column is left-aligned, the others right-aligned unless all_left. An empty header
  // prints no header row and no rule.
  explicit TextTable(std::vector<std::string> header, bool all_left = false)
      : rows_{std::move(header)}, all_left_(all_left) {}
  void add(std::vector<std::string> row) { rows_.push_back(std::move(row)); }

  std::string render(const std::string& indent = "") const {
    std::vector<std::size_t> width;
    for (const auto& row : rows_) {
      if (row.size() > width.size()) width.resize(row.size(), 0);
      for (std::size_t c = 0; c < row.size(); ++c) {
        width[c] = std::max(width[c], display_width(row[c]));
      }
    }
    std::string out;
    const bool header = !rows_.front().empty();
    for (std::size_t r = header ? 0 : 1; r < rows_.size(); ++r) {
      std::string line = indent;
      for (std::size_t c = 0; c < rows_[r].size(); ++c) {
        const std::string& cell = rows_[r][c];
        const std::string pad(width[c] - display_width(cell), ' ');
        if (c > 0) line += "  ";
        line += c == 0 || all_left_ ? cell + pad : pad + cell;
      }
      while (!line.empty() && line.back() == ' ') line.pop_back();
      out += line + "\n";
      if (header && r == 0) {  // underline the header
        std::string rule = indent;
        for (std::size_t c = 0; c < width.size(); ++c) {
          if (c > 0) rule += "  ";
          rule += std::string(width[c], '-');
        }
        out += rule + "\n";
      }
    }
    return out;
  }

 private:
  std::vector<std::vector<std::string>> rows_;
  bool all_left_;
};

// ---------------------------------------------------------------------------------------------
// SVG plots

// x positions of the per-second series: the middle of each second.
double second_x(std::size_t i) {
  return static_cast<double>(i) + 0.5;
}

Axis seconds_axis(const LoadReport& r, double right) {
  return Axis::linear(0, static_cast<double>(r.seconds.size()), kMarginLeft, right);
}

std::string seconds_label(double t) {
  return printf_string("%g", t) + " s";
}

bool any_traffic(const LoadReport& r) {
  return std::any_of(r.seconds.begin(), r.seconds.end(), [](const LoadSecond& s) {
    return s.requests > 0 || s.bytes > 0 || s.errors > 0;
  });
}

// A plot over the run's seconds: x is the time since the start, y values print as %g.
Plot per_second_plot(const char* id, const char* title, const char* y_label) {
  Plot plot;
  plot.id = id;
  plot.title = title;
  plot.x_label = "time since start";
  plot.y_label = y_label;
  plot.x_format = seconds_label;
  plot.y_format = [](double v) { return printf_string("%g", v); };
  return plot;
}

std::string latency_plot(const LoadReport& r) {
  Plot plot = per_second_plot("plot-latency", "Request latency per second (p50, p90, p99)",
                              "request latency");
  plot.y_format = format_ns_tick;
  const std::pair<const char*, std::uint64_t LoadSecond::*> lines[] = {
      {"p50", &LoadSecond::p50_ns}, {"p90", &LoadSecond::p90_ns}, {"p99", &LoadSecond::p99_ns}};
  const char* colors[] = {"#1f77b4", "#ff7f0e", "#d62728"};
  double lo = 0, hi = 0;
  bool any = false;
  for (std::size_t k = 0; k < 3; ++k) {
    Series series{lines[k].first, lines[k].first, colors[k], {}, false, r.seconds.size() <= 60};
    for (std::size_t i = 0; i < r.seconds.size(); ++i) {
      const LoadSecond& sec = r.seconds[i];
      if (sec.requests == 0) {
        series.points.emplace_back(second_x(i), kNaN);
        continue;
      }
      const double v = static_cast<double>(sec.*(lines[k].second));
      series.points.emplace_back(second_x(i), v);
      if (v > 0) lo = any ? std::min(lo, v) : v;
      hi = std::max(hi, v);
      any = true;
    }
    plot.series.push_back(std::move(series));
  }
  if (!any) return render_plot(plot, nullptr);
  const double right = kPlotWidth - 24;
  AxisSet axes{seconds_axis(r, right),
               Axis::automatic(lo, hi, kPlotHeight - kMarginBottom, kMarginTop), std::nullopt};
  return render_plot(plot, &axes);
}

// The CDF of a histogram as points (value, percent of values <= value), linear within a bucket.
std::vector<std::pair<double, double>> cdf_points(const LatencyHistogram& h) {
  std::vector<std::pair<double, double>> points;
  if (h.count() == 0) return points;
  const double n = static_cast<double>(h.count());
  std::uint64_t seen = 0;
  for (const auto& b : h.buckets()) {
    const double low = std::max(static_cast<double>(b.low), static_cast<double>(h.min()));
    const double high = std::min(static_cast<double>(b.high), static_cast<double>(h.max()));
    points.emplace_back(low, 100.0 * static_cast<double>(seen) / n);
    seen += b.count;
    points.emplace_back(high, 100.0 * static_cast<double>(seen) / n);
  }
  return points;
}

// A CDF plot of `hists` (key, label, colour, histogram), log x when the range is wide.
struct CdfLine {
  std::string key, label, color;
  const LatencyHistogram* h;
};
std::string cdf_plot(Plot plot, const std::vector<CdfLine>& lines) {
  plot.x_format = format_ns_tick;
  plot.y_format = [](double v) { return printf_string("%g", v) + "%"; };
  double lo = 0, hi = 0;
  bool any = false;
  for (const CdfLine& l : lines) {
    plot.series.push_back(Series{l.key, l.label, l.color, cdf_points(*l.h)});
    if (l.h->count() == 0) continue;
    const double hmin = static_cast<double>(std::max<std::uint64_t>(l.h->min(), 1));
    lo = any ? std::min(lo, hmin) : hmin;
    hi = std::max(hi, static_cast<double>(l.h->max()));
    any = true;
  }
  if (!any) return render_plot(plot, nullptr);
  const double right = kPlotWidth - 24;
  Axis x = hi / lo > 20 ? Axis::logarithmic(lo, hi, kMarginLeft, right)
                        : Axis::linear(0, hi, kMarginLeft, right);
  AxisSet axes{x, Axis::linear(0, 100, kPlotHeight - kMarginBottom, kMarginTop), std::nullopt};
  return render_plot(plot, &axes);
}

std::string full_resolution_plot(const LoadReport& r, const LoadReport* base) {
  Plot plot;
  plot.id = "plot-full-resolution";
  plot.title = "Camera moves: time to first visible tile and to full resolution (CDF)";
  plot.x_label = "time after the camera move";
  plot.y_label = "camera moves done";
  std::vector<CdfLine> lines = {
      {"full_resolution", "full resolution", "#1f77b4", &r.full_resolution},
      {"first_visible", "first visible tile", "#9467bd", &r.first_visible}};
  if (base) {
    lines.push_back({"baseline_full_resolution", "baseline: full resolution", "#aec7e8",
                     &base->full_resolution});
    lines.push_back({"baseline_first_visible", "baseline: first visible tile", "#c5b0d5",
                     &base->first_visible});
  }
  return cdf_plot(std::move(plot), lines);
}

// Only with a baseline: the request latency distributions of both runs.
std::string latency_cdf_plot(const LoadReport& r, const LoadReport& base) {
  Plot plot;
  plot.id = "plot-latency-cdf";
  plot.title = "Request latency against the baseline (CDF)";
  plot.x_label = "request latency";
  plot.y_label = "requests done";
  return cdf_plot(std::move(plot), {{"total", "this run", "#d62728", &r.total},
                                    {"baseline_total", "baseline", "#ff9896", &base.total}});
}

std::string throughput_plot(const LoadReport& r) {
  Plot plot =
      per_second_plot("plot-throughput", "Throughput per second (requests and MB)", "requests/s");
  plot.y2_label = "MB/s";
  plot.y2_format = plot.y_format;
  const bool markers = r.seconds.size() <= 60;
  Series reqs{"requests_per_s", "requests/s", "#1f77b4", {}, false, markers};
  Series mbs{"megabytes_per_s", "MB/s (right axis)", "#2ca02c", {}, true, markers};
  double max_reqs = 0, max_mb = 0;
  for (std::size_t i = 0; i < r.seconds.size(); ++i) {
    const double q = static_cast<double>(r.seconds[i].requests);
    const double mb = static_cast<double>(r.seconds[i].bytes) / 1e6;
    reqs.points.emplace_back(second_x(i), q);
    mbs.points.emplace_back(second_x(i), mb);
    max_reqs = std::max(max_reqs, q);
    max_mb = std::max(max_mb, mb);
  }
  plot.series = {std::move(reqs), std::move(mbs)};
  if (!any_traffic(r)) return render_plot(plot, nullptr);
  const double right = kPlotWidth - 76;
  AxisSet axes{
      seconds_axis(r, right),
      Axis::linear(0, max_reqs > 0 ? max_reqs : 1, kPlotHeight - kMarginBottom, kMarginTop),
      Axis::linear(0, max_mb > 0 ? max_mb : 1, kPlotHeight - kMarginBottom, kMarginTop)};
  return render_plot(plot, &axes);
}

std::string errors_plot(const LoadReport& r) {
  Plot plot = per_second_plot("plot-errors", "Errors per second", "errors/s");
  Series errors{"errors_per_s", "errors/s", "#d62728", {}, false, r.seconds.size() <= 60};
  double max_errors = 0;
  for (std::size_t i = 0; i < r.seconds.size(); ++i) {
    const double e = static_cast<double>(r.seconds[i].errors);
    errors.points.emplace_back(second_x(i), e);
    max_errors = std::max(max_errors, e);
  }
  plot.series = {std::move(errors)};
  if (!any_traffic(r)) return render_plot(plot, nullptr);
  const double right = kPlotWidth - 24;
  // At least 0..5 so that a run without errors shows a flat line at the bottom, not mid-plot.
  AxisSet axes{seconds_axis(r, right),
               Axis::linear(0, std::max(max_errors, 5.0), kPlotHeight - kMarginBottom, kMarginTop),
               std::nullopt};
  return render_plot(plot, &axes);
}

// ---------------------------------------------------------------------------------------------
// HTML tables

// Rows of cells; the first row is the header. Cells are escaped here.
std::string html_table(const std::vector<std::vector<std::string>>& rows,
                       const std::string& css_class) {
  std::string s = "<table class=\"" + css_class + "\">\n";
  for (std::size_t r = 0; r < rows.size(); ++r) {
    s += "<tr>";
    for (std::size_t c = 0; c < rows[r].size(); ++c) {
      const char* tag = r == 0 ? "th" : "td";
      s += std::string("<") + tag + (c > 0 ? " class=\"num\"" : "") + ">" +
           html_escape(rows[r][c]) + "</" + tag + ">";
    }
    s += "</tr>\n";
  }
  return s + "</table>\n";
}

std::vector<std::vector<std::string>> latency_rows(const LoadReport& r, std::string_view micro) {
  std::vector<std::vector<std::string>> rows;
  std::vector<std::string> header = {"latency", "count", "min"};
  for (const auto& q : kQuantiles) header.emplace_back(q.label);
  header.insert(header.end(), {"max", "mean"});
  rows.push_back(std::move(header));
  for (const Metric& m : metrics(r)) {
    const LatencyHistogram& h = *m.histogram;
    std::vector<std::string> row = {m.label, format_count(h.count())};
    auto cell = [&](double ns) { return h.count() == 0 ? std::string("-") : format_ns(ns, micro); };
    row.push_back(cell(static_cast<double>(h.min())));
    for (const auto& q : kQuantiles) row.push_back(cell(static_cast<double>(h.percentile(q.p))));
    row.push_back(cell(static_cast<double>(h.max())));
    row.push_back(cell(h.mean()));
    rows.push_back(std::move(row));
  }
  return rows;
}

std::vector<std::vector<std::string>> totals_rows(const LoadReport& r) {
  return {
      {"totals", "value", "per second"},
      {"requests", format_count(r.requests),
       format_rate(per_second(static_cast<double>(r.requests), r.duration_s))},
      {"bytes", format_bytes(static_cast<double>(r.bytes)),
       format_bytes(per_second(static_cast<double>(r.bytes), r.duration_s)) + "/s"},
      {"errors", format_count(r.errors) + " (" + format_percent(ratio(r.errors, r.requests)) + ")",
       format_rate(per_second(static_cast<double>(r.errors), r.duration_s))},
      {"camera moves", format_count(r.camera_moves),
       format_rate(per_second(static_cast<double>(r.camera_moves), r.duration_s))},
      {"wasted: cancelled", format_count(r.cancelled),
       format_rate(per_second(static_cast<double>(r.cancelled), r.duration_s))}};
}

std::vector<std::vector<std::string>> tier_rows(const LoadReport& r) {
  const CacheTierCounts& t = r.tiers;
  const std::uint64_t all =
      saturated_sum(saturated_sum(t.ram, t.disk), saturated_sum(t.network, t.revalidated));
  return {{"served from", "requests", "share"},
          {"ram", format_count(t.ram), format_percent(ratio(t.ram, all))},
          {"disk", format_count(t.disk), format_percent(ratio(t.disk, all))},
          {"network", format_count(t.network), format_percent(ratio(t.network, all))},
          {"revalidated (304)", format_count(t.revalidated),
           format_percent(ratio(t.revalidated, all))}};
}

std::vector<std::vector<std::string>> status_rows(const LoadReport& r) {
  std::uint64_t all = 0;
  for (const auto& [code, n] : r.by_status) all = saturated_sum(all, n);
  std::vector<std::vector<std::string>> rows = {{"HTTP status", "responses", "share"}};
  for (const auto& [code, n] : r.by_status) {
    rows.push_back({std::to_string(code), format_count(n), format_percent(ratio(n, all))});
  }
  return rows;
}

std::vector<std::vector<std::string>> error_rows(const LoadReport& r, bool for_terminal) {
  std::vector<std::vector<std::string>> rows = {{"error", "requests", "of all requests"}};
  for (const auto& [kind, n] : r.errors_by_kind) {
    rows.push_back({for_terminal ? terminal_safe(kind) : kind, format_count(n),
                    format_percent(ratio(n, r.requests))});
  }
  return rows;
}

// compare_reports(baseline, r) as an HTML table (class "compare"); regressions say so.
std::string compare_html(const LoadReport& r, const LoadReport& base) {
  std::vector<std::vector<std::string>> rows = {{"metric", "baseline", "this run", "relative", ""}};
  for (const MetricChange& c : compare_reports(base, r, 0.1)) {
    rows.push_back({c.name, format_metric(c.a, c.kind), format_metric(c.b, c.kind),
                    std::isnan(c.relative) ? "-" : printf_string("%+.1f", c.relative * 100) + "%",
                    c.regression ? "regression (> 10% worse)" : ""});
  }
  return html_table(rows, "compare");
}

constexpr std::string_view kCss = R"(
body { font-family: system-ui, -apple-system, "Segoe UI", Helvetica, Arial, sans-serif;
       margin: 2em auto; max-width: 820px; padding: 0 1em; color: #222; background: #fafafa; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; word-break: break-word; }
h2 { font-size: 1.2em; margin-top: 2em; border-bottom: 1px solid #ccc; }
h3 { font-size: 1em; margin: 1.5em 0 0.4em; }
p.sub { color: #666; margin-top: 0; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.92em; }
th, td { padding: 0.25em 0.8em; border-bottom: 1px solid #e0e0e0; text-align: left; }
th { background: #f0f0f0; }
td.num, th.num { text-align: right; font-variant-numeric: tabular-nums; }
table.run td { word-break: break-all; }
table.run th { white-space: nowrap; }
figure { margin: 0; }
svg.plot { display: block; max-width: 100%; height: auto; background: #fff;
           font-family: system-ui, Helvetica, Arial, sans-serif; }
footer { margin-top: 3em; color: #888; font-size: 0.85em; }
section.gates { margin: 1em 0; padding: 0.4em 1em; border-left: 6px solid #2e7d32;
                background: #edf7ee; }
section.gates.failed { border-left-color: #c62828; background: #fdecea; }
section.gates h2 { margin-top: 0.3em; border: none; }
td.pass { color: #2e7d32; font-weight: bold; }
td.fail { color: #c62828; font-weight: bold; }
)";

// The gates of the run (--slo, --max-error-rate) with their measured values: the first thing on
// the page, red when one failed, so a CI artefact says at once which gate stopped the pipeline.
std::string gates_html(const std::vector<GateResult>& gates) {
  const bool failed =
      std::any_of(gates.begin(), gates.end(), [](const GateResult& g) { return !g.held; });
  std::string s = std::string("<section class=\"gates") + (failed ? " failed" : "") +
                  "\" id=\"gates\">\n<h2>" + (failed ? "Gates: FAILED" : "Gates: passed") +
                  "</h2>\n";
  s += "<table class=\"gates\">\n<tr><th>gate</th><th>measured</th><th>result</th></tr>\n";
  for (const GateResult& g : gates) {
    s += "<tr><td>" + html_escape(g.gate.text) + "</td><td class=\"num\">" +
         html_escape(g.gate.metric + " = " + format_metric(g.measured, g.gate.kind)) + "</td>" +
         (g.held ? "<td class=\"pass\">pass</td>" : "<td class=\"fail\">FAIL</td>") + "</tr>\n";
  }
  return s + "</table>\n</section>\n";
}

}  // namespace

// ---------------------------------------------------------------------------------------------

nlohmann::json to_json(const LoadReport& r) {
  auto str = [](const std::string& s) { return valid_utf8(s, false); };
  json j;
  j["format"] = "vts-loadtest-report";
  j["version"] = 1;
  j["title"] = str(r.title);
  j["target"] = str(r.target);
  j["command_line"] = str(r.command_line);
  j["start"] = format_time(r.start, true);
  j["start_unix_ms"] = unix_ms(r.start);
  j["duration_s"] = finite(r.duration_s);
  j["scenario"] = {{"viewers", r.viewers},   {"path", str(r.path)},
                   {"fps", finite(r.fps)},   {"mode", mode_name(r.mode)},
                   {"rate", finite(r.rate)}, {"rate_unit", str(r.rate_unit)}};
  j["totals"] = {
      {"requests", r.requests},
      {"bytes", r.bytes},
      {"errors", r.errors},
      {"camera_moves", r.camera_moves},
      {"requests_per_s", per_second(static_cast<double>(r.requests), r.duration_s)},
      {"bytes_per_s", per_second(static_cast<double>(r.bytes), r.duration_s)},
      {"error_ratio", ratio(r.errors, r.requests)},
  };
  json latency = json::object();
  for (const Metric& m : metrics(r)) latency[m.key] = histogram_json(*m.histogram);
  j["latency_ns"] = std::move(latency);
  j["cache_tiers"] = {{"ram", r.tiers.ram},
                      {"disk", r.tiers.disk},
                      {"network", r.tiers.network},
                      {"revalidated", r.tiers.revalidated}};
  json status = json::object();
  for (const auto& [code, n] : r.by_status) status[std::to_string(code)] = n;
  j["by_status"] = std::move(status);
  json errors = json::object();
  for (const auto& [kind, n] : r.errors_by_kind) {
    // Two kinds that differ only in invalid bytes become one key: add, do not overwrite.
    json& slot = errors[str(kind)];
    slot = saturated_sum(slot.is_number() ? slot.get<std::uint64_t>() : 0, n);
  }
  j["errors_by_kind"] = std::move(errors);
  j["wasted"] = {{"cancelled", r.cancelled}};
  json seconds = json::array();
  for (std::size_t i = 0; i < r.seconds.size(); ++i) {
    const LoadSecond& s = r.seconds[i];
    seconds.push_back({{"t", i},
                       {"requests", s.requests},
                       {"bytes", s.bytes},
                       {"errors", s.errors},
                       {"p50_ns", s.p50_ns},
                       {"p90_ns", s.p90_ns},
                       {"p99_ns", s.p99_ns}});
  }
  j["seconds"] = std::move(seconds);
  return j;
}

std::string duration_text(double ns) {
  return format_ns(ns);
}

std::string summary_table(const LoadReport& r) {
  std::string out;
  out += (r.title.empty() ? std::string("vts loadtest") : terminal_safe(r.title)) + "\n";
  TextTable run({}, true);
  if (!r.target.empty()) run.add({"target", terminal_safe(r.target)});
  if (!r.command_line.empty()) run.add({"command", terminal_safe(r.command_line)});
  run.add({"started", format_time(r.start, false)});
  run.add({"duration", printf_string("%.1f", finite(r.duration_s)) + " s"});
  run.add({"load", scenario_text(r, true)});
  out += run.render("  ") + "\n";

  auto table = [](const std::vector<std::vector<std::string>>& rows) {
    TextTable t(rows.front());
    for (std::size_t i = 1; i < rows.size(); ++i) t.add(rows[i]);
    return t.render();
  };
  out += table(totals_rows(r)) + "\n";
  out += table(latency_rows(r, "us")) + "\n";
  out += table(tier_rows(r));
  if (!r.by_status.empty()) out += "\n" + table(status_rows(r));
  if (!r.errors_by_kind.empty()) out += "\n" + table(error_rows(r, true));
  if (r.requests == 0) out += "\nno requests completed\n";
  return out;
}

std::string html_report(const LoadReport& r, const LoadReport* baseline,
                        const std::vector<GateResult>* gates) {
  const std::string title = r.title.empty() ? "vts loadtest report" : r.title;
  std::string s;
  s += "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n";
  // Nothing on this page may come from elsewhere: no scripts, fonts, images or style sheets.
  s += "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; "
       "style-src 'unsafe-inline'\">\n";
  s += "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n";
  s += "<meta name=\"generator\" content=\"vts loadtest\">\n";
  s += "<title>" + html_escape(title) + "</title>\n<style>" + std::string(kCss) +
       "</style>\n</head>\n<body>\n";
  s += "<h1 id=\"title\">" + html_escape(title) + "</h1>\n";
  s += "<p class=\"sub\">vts loadtest report &middot; " + html_escape(format_time(r.start, false)) +
       "</p>\n";
  if (gates && !gates->empty()) s += gates_html(*gates);

  s += "<table class=\"run\">\n";
  auto run_row = [&](const char* key, const std::string& value) {
    s += std::string("<tr><th>") + key + "</th><td>" + html_escape(value) + "</td></tr>\n";
  };
  run_row("target", r.target);
  run_row("command", r.command_line);
  run_row("started", format_time(r.start, false));
  run_row("duration", printf_string("%.1f", finite(r.duration_s)) + " s");
  run_row("load", scenario_text(r, false));
  s += "</table>\n";

  if (r.requests == 0) s += "<p class=\"empty\">No requests completed in this run.</p>\n";

  s += "<h2>Summary</h2>\n" + html_table(totals_rows(r), "totals");
  if (baseline) s += "<h2>Change against the baseline</h2>\n" + compare_html(r, *baseline);
  s += "<h2>Latency</h2>\n" + html_table(latency_rows(r, "\xC2\xB5s"), "latency");
  s += "<p class=\"note\">Percentiles come from histograms with a relative error of at most " +
       format_percent(r.total.relative_error()) + ".</p>\n";
  s += "<figure>\n<h3>Request latency over time</h3>\n" + latency_plot(r) + "\n</figure>\n";
  s += "<figure>\n<h3>Time to first visible tile and to full resolution</h3>\n" +
       full_resolution_plot(r, baseline) + "\n</figure>\n";
  if (baseline) {
    s += "<figure>\n<h3>Request latency against the baseline</h3>\n" +
         latency_cdf_plot(r, *baseline) + "\n</figure>\n";
  }
  s += "<h2>Throughput and errors</h2>\n";
  s += "<figure>\n<h3>Throughput</h3>\n" + throughput_plot(r) + "\n</figure>\n";
  s += "<figure>\n<h3>Errors</h3>\n" + errors_plot(r) + "\n</figure>\n";
  s += "<h2>Cache tiers</h2>\n" + html_table(tier_rows(r), "tiers");
  s += "<h2>Responses</h2>\n";
  s += r.by_status.empty() ? std::string("<p>No HTTP responses.</p>\n")
                           : html_table(status_rows(r), "status");
  s += "<h2>Errors by kind</h2>\n";
  s += r.errors_by_kind.empty() ? std::string("<p>No errors.</p>\n")
                                : html_table(error_rows(r, false), "errors");
  s += "<footer>Written by vts loadtest. Latencies are wall-clock times measured by the simulated "
       "viewers.</footer>\n</body>\n</html>\n";
  return s;
}

Status write_html_report(const LoadReport& report, const fs::path& dir, const LoadReport* baseline,
                         const std::vector<GateResult>* gates) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) {
    return make_error(ErrorCode::io,
                      "cannot create the report folder " + dir.string() + ": " + ec.message());
  }
  if (!fs::is_directory(dir, ec)) {
    return make_error(ErrorCode::io, "the report folder " + dir.string() + " is not a folder");
  }
  return write_file_atomically(dir / "index.html", html_report(report, baseline, gates));
}

}  // namespace vts::loadtest
