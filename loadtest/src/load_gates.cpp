// Metrics by name, gates and run-to-run comparison of load-test reports (load_gates.hpp).
#include "vts/loadtest/load_gates.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <limits>

#include "vts/base/file_io.hpp"

namespace vts::loadtest {
namespace {

using nlohmann::json;

bool starts_with(std::string_view s, std::string_view p) {
  return s.substr(0, p.size()) == p;
}

// A finite number >= 0 at the start of s; the rest is left in s.
bool take_number(std::string_view& s, double& out) {
  const char* end = s.data() + s.size();
  auto [ptr, ec] = std::from_chars(s.data(), end, out);
  if (ec != std::errc{} || !std::isfinite(out) || out < 0) return false;
  s.remove_prefix(static_cast<std::size_t>(ptr - s.data()));
  return true;
}

// "p99", "p99_9", "p99.9", "p95" -> the percentile; false for anything else.
bool percentile_of(std::string_view stat, double& p) {
  if (stat.size() < 2 || stat[0] != 'p') return false;
  std::string digits(stat.substr(1));
  std::replace(digits.begin(), digits.end(), '_', '.');
  std::string_view rest = digits;
  if (!std::isdigit(static_cast<unsigned char>(rest.front()))) return false;
  return take_number(rest, p) && rest.empty() && p <= 100;
}

// An empty histogram measured nothing: NaN, which holds no gate (a server that never reached
// full resolution does not pass full_res_p95<1.5s).
Result<MetricValue> histogram_metric(const LatencyHistogram& h, std::string_view stat) {
  double p = 0;
  double v = 0;
  const bool empty = h.count() == 0;
  if (stat == "min")
    v = static_cast<double>(h.min());
  else if (stat == "max")
    v = static_cast<double>(h.max());
  else if (stat == "mean")
    v = h.mean();
  else if (percentile_of(stat, p))
    v = static_cast<double>(h.percentile(p));
  else
    return make_error(ErrorCode::not_found, "");
  return MetricValue{empty ? std::numeric_limits<double>::quiet_NaN() : v, MetricKind::latency};
}

double per_s(double n, double seconds) {
  return seconds > 0 ? n / seconds : 0.0;
}

std::string number_text(const char* format, double v) {
  char b[64];
  std::snprintf(b, sizeof b, format, v);
  return b;
}

}  // namespace

std::string metric_names_text() {
  return "p50, p90, p99, p99_9, any pNN, min, max, mean (request latency), the same prefixed "
         "with queue_time_, ttfb_, total_, first_visible_ or full_res_ (e.g. full_res_p95), "
         "error_rate, errors, requests, requests_per_s, bytes, bytes_per_s, camera_moves, "
         "cancelled";
}

Result<MetricValue> metric_value(const LoadReport& r, std::string_view name) {
  const double d = r.duration_s;
  const std::pair<std::string_view, MetricValue> plain[] = {
      {"error_rate",
       {r.requests ? static_cast<double>(r.errors) / static_cast<double>(r.requests) : 0.0,
        MetricKind::ratio}},
      {"errors", {static_cast<double>(r.errors), MetricKind::count}},
      {"requests", {static_cast<double>(r.requests), MetricKind::count}},
      {"requests_per_s", {per_s(static_cast<double>(r.requests), d), MetricKind::rate}},
      {"bytes", {static_cast<double>(r.bytes), MetricKind::count}},
      {"bytes_per_s", {per_s(static_cast<double>(r.bytes), d), MetricKind::rate}},
      {"camera_moves", {static_cast<double>(r.camera_moves), MetricKind::count}},
      {"cancelled", {static_cast<double>(r.cancelled), MetricKind::count}}};
  for (const auto& [key, value] : plain)
    if (name == key) return value;
  const std::pair<std::string_view, const LatencyHistogram*> prefixed[] = {
      {"queue_time_", &r.queue_time},
      {"ttfb_", &r.ttfb},
      {"total_", &r.total},
      {"first_visible_", &r.first_visible},
      {"full_resolution_", &r.full_resolution},
      {"full_res_", &r.full_resolution}};
  const LatencyHistogram* h = &r.total;
  std::string_view stat = name;
  for (const auto& [prefix, hist] : prefixed) {
    if (starts_with(name, prefix)) {
      h = hist;
      stat = name.substr(prefix.size());
      break;
    }
  }
  auto v = histogram_metric(*h, stat);
  if (!v)
    return make_error(ErrorCode::not_found, "unknown metric '" + std::string(name) +
                                                "'; metrics: " + metric_names_text());
  return v;
}

std::string format_metric(double v, MetricKind kind) {
  switch (kind) {
    case MetricKind::latency:
      if (v < 1e3) return number_text("%.0f ns", v);
      if (v < 1e6) return number_text("%.3g us", v / 1e3);
      if (v < 1e9) return number_text("%.3g ms", v / 1e6);
      return number_text("%.3g s", v / 1e9);
    case MetricKind::ratio:
      return number_text("%.3g%%", v * 100);
    case MetricKind::rate:
      return number_text("%.1f/s", v);
    case MetricKind::count:
      return number_text("%.0f", v);
  }
  return "";
}

Result<double> parse_fraction(std::string_view text) {
  std::string_view s = trim(text);
  double v = 0;
  const bool ok = take_number(s, v);
  const bool percent = trim(s) == "%";
  if (!ok || (!percent && !trim(s).empty()) || (percent ? v > 100 : v > 1))
    return make_error(ErrorCode::invalid_argument,
                      "'" + std::string(text) +
                          "' is not an error rate: a fraction in [0, 1] (0.01) or a percentage "
                          "(1%)");
  return percent ? v / 100 : v;
}

Result<Gate> parse_slo(std::string_view text) {
  auto malformed = [&](const std::string& why) -> Result<Gate> {
    return make_error(ErrorCode::invalid_argument,
                      "--slo '" + std::string(text) + "': " + why +
                          " (expected METRIC<VALUE such as p99<200ms or full_res_p95<1.5s, with "
                          "< <= > >=; metrics: " +
                          metric_names_text() + ")");
  };
  const std::size_t at = text.find_first_of("<>");
  if (at == std::string_view::npos) return malformed("no comparison");
  Gate g;
  g.text = std::string(text);
  g.metric = std::string(trim(text.substr(0, at)));
  std::string_view rest = text.substr(at + 1);
  g.op = std::string(1, text[at]);
  if (!rest.empty() && rest.front() == '=') {
    g.op += '=';
    rest.remove_prefix(1);
  }
  const LoadReport empty;
  auto kind = metric_value(empty, g.metric);
  if (!kind) return malformed("unknown metric '" + g.metric + "'");
  g.kind = kind->kind;
  rest = trim(rest);
  if (!take_number(rest, g.threshold)) return malformed("no number after " + g.op);
  const std::string unit(trim(rest));
  if (g.kind == MetricKind::latency) {
    const std::pair<const char*, double> units[] = {
        {"ns", 1}, {"us", 1e3}, {"ms", 1e6}, {"s", 1e9}};
    auto u = std::find_if(std::begin(units), std::end(units),
                          [&](const auto& p) { return unit == p.first; });
    if (u == std::end(units)) return malformed("a latency needs a unit: ns, us, ms or s");
    g.threshold *= u->second;
  } else if (g.kind == MetricKind::ratio && unit == "%") {
    g.threshold /= 100;
  } else if (!unit.empty()) {
    return malformed("unit '" + unit + "' does not fit " + g.metric);
  }
  if (g.kind == MetricKind::ratio && g.threshold > 1)
    return malformed(g.metric + " is a fraction in [0, 1] or a percentage (5%)");
  return g;
}

Gate max_error_rate_gate(double fraction) {
  return Gate{"error_rate<=" + format_metric(fraction, MetricKind::ratio), "error_rate",
              "<=", fraction, MetricKind::ratio};
}

std::vector<GateResult> evaluate_gates(const LoadReport& report, const std::vector<Gate>& gates) {
  std::vector<GateResult> out;
  for (const Gate& g : gates) {
    auto v = metric_value(report, g.metric);
    const double m = v ? v->value : std::numeric_limits<double>::quiet_NaN();
    bool held = false;
    if (g.op == "<") held = m < g.threshold;
    if (g.op == "<=") held = m <= g.threshold;
    if (g.op == ">") held = m > g.threshold;
    if (g.op == ">=") held = m >= g.threshold;
    out.push_back({g, m, held});
  }
  return out;
}

json gates_json(const std::vector<GateResult>& results) {
  json a = json::array();
  for (const GateResult& r : results) {
    a.push_back({{"gate", r.gate.text},
                 {"metric", r.gate.metric},
                 {"op", r.gate.op},
                 {"threshold", r.gate.threshold},
                 {"threshold_text", format_metric(r.gate.threshold, r.gate.kind)},
                 {"measured", r.measured},
                 {"measured_text", format_metric(r.measured, r.gate.kind)},
                 {"held", r.held}});
  }
  return a;
}

std::string gate_failure_line(const std::vector<GateResult>& results) {
  std::string line;
  for (const GateResult& r : results) {
    if (r.held) continue;
    line += line.empty() ? "gate failed: " : "; ";
    line +=
        r.gate.text + " (" + r.gate.metric + " = " + format_metric(r.measured, r.gate.kind) + ")";
  }
  return line;
}

std::vector<MetricChange> compare_reports(const LoadReport& a, const LoadReport& b,
                                          double threshold) {
  static constexpr std::string_view kNames[] = {"requests",
                                                "requests_per_s",
                                                "bytes_per_s",
                                                "error_rate",
                                                "p50",
                                                "p90",
                                                "p99",
                                                "p99_9",
                                                "ttfb_p50",
                                                "ttfb_p99",
                                                "first_visible_p50",
                                                "first_visible_p99",
                                                "full_res_p50",
                                                "full_res_p90",
                                                "full_res_p99"};
  std::vector<MetricChange> out;
  for (std::string_view name : kNames) {
    const MetricValue va = *metric_value(a, name), vb = *metric_value(b, name);
    MetricChange c{std::string(name), va.kind, va.value, vb.value, vb.value - va.value, 0, false};
    c.relative = va.value != 0 ? c.absolute / va.value : std::numeric_limits<double>::quiet_NaN();
    if (va.kind == MetricKind::latency)
      c.regression = va.value > 0 && c.relative > threshold;
    else if (va.kind == MetricKind::ratio)
      c.regression = va.value == 0 ? vb.value > 0 : c.relative > threshold;
    else if (name == "requests_per_s")
      c.regression = va.value > 0 && -c.relative > threshold;
    out.push_back(c);
  }
  return out;
}

json compare_json(const std::vector<MetricChange>& changes, double threshold) {
  json metrics = json::array();
  int regressions = 0;
  for (const MetricChange& c : changes) {
    regressions += c.regression ? 1 : 0;
    metrics.push_back({{"name", c.name},
                       {"a", c.a},
                       {"b", c.b},
                       {"absolute", c.absolute},
                       {"relative", std::isnan(c.relative) ? json(nullptr) : json(c.relative)},
                       {"regression", c.regression}});
  }
  return {{"threshold", threshold}, {"regressions", regressions}, {"metrics", metrics}};
}

std::string compare_table(const std::vector<MetricChange>& changes) {
  std::vector<std::vector<std::string>> rows = {{"metric", "A", "B", "change", "relative", ""}};
  for (const MetricChange& c : changes) {
    const std::string sign = c.absolute > 0 ? "+" : c.absolute < 0 ? "-" : "";
    rows.push_back({c.name, format_metric(c.a, c.kind), format_metric(c.b, c.kind),
                    sign + format_metric(std::fabs(c.absolute), c.kind),
                    std::isnan(c.relative) ? "-" : number_text("%+.1f%%", c.relative * 100),
                    c.regression ? "REGRESSION" : ""});
  }
  std::vector<std::size_t> width(6, 0);
  for (const auto& row : rows)
    for (std::size_t i = 0; i < row.size(); ++i) width[i] = std::max(width[i], row[i].size());
  std::string out;
  for (const auto& row : rows) {
    std::string line = row[0] + std::string(width[0] - row[0].size(), ' ');
    for (std::size_t i = 1; i < 5; ++i)
      line += "  " + std::string(width[i] - row[i].size(), ' ') + row[i];
    if (!row[5].empty()) line += "  " + row[5];
    out += line + "\n";
  }
  return out;
}

}  // namespace vts::loadtest
