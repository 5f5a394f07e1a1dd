// What a CI pipeline asks of a load-test report: named metrics, gates on them (`--slo 'p99<200ms'`,
// `--max-error-rate 1%`) and the change of each metric between two runs (`vts loadtest compare`).
//
// Metric names (metric_names_text() lists them for error messages):
//   request latency (the "total" histogram): p50, p90, p99, p99_9 or p99.9, any pNN[.N], min, max,
//     mean; the same with a prefix for the other distributions: queue_time_, ttfb_, total_,
//     first_visible_, full_res_ (or full_resolution_), e.g. full_res_p95, ttfb_max;
//   error_rate (errors / requests, a fraction), errors, requests, requests_per_s, bytes,
//     bytes_per_s, camera_moves, cancelled.
// Latencies are in nanoseconds, error_rate a fraction.
//
// Thread safety: pure functions of their arguments.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "vts/base/result.hpp"
#include "vts/loadtest/load_report.hpp"

namespace vts::loadtest {

enum class MetricKind : std::uint8_t { latency, ratio, rate, count };

struct MetricValue {
  double value = 0;
  MetricKind kind = MetricKind::count;
};

// not_found for an unknown name (listing the names).
Result<MetricValue> metric_value(const LoadReport& report, std::string_view name);
std::string metric_names_text();
// "312 ms", "1.25%", "5230/s", "17".
std::string format_metric(double value, MetricKind kind);

// A fraction: "0.01" or "1%" (both one in a hundred), in [0, 1]. invalid_argument otherwise.
Result<double> parse_fraction(std::string_view text);

// The error rate above which a run fails when --max-error-rate is not given.
inline constexpr double kDefaultMaxErrorRate = 0.01;

struct Gate {
  std::string text;      // as given ("p99<200ms"), or "error_rate<=1%" for --max-error-rate
  std::string metric;    // a metric_value() name
  std::string op;        // <, <=, > or >=
  double threshold = 0;  // in the metric's unit (ns, fraction, ...)
  MetricKind kind = MetricKind::count;
};

// "METRIC OP NUMBER[UNIT]" with OP one of < <= > >=, spaces allowed; latencies need a unit (ns,
// us, ms, s), error_rate takes a fraction or a percentage, the others a plain number.
// invalid_argument naming the text and listing the metric names.
Result<Gate> parse_slo(std::string_view text);
// error_rate <= fraction.
Gate max_error_rate_gate(double fraction);

struct GateResult {
  Gate gate;
  double measured = 0;
  bool held = false;
};

std::vector<GateResult> evaluate_gates(const LoadReport& report, const std::vector<Gate>& gates);
// [{gate, metric, op, threshold, measured, held}] (threshold and measured in the metric's unit
// as metric_value() gives it), with the display forms threshold_text and measured_text.
nlohmann::json gates_json(const std::vector<GateResult>& results);
// "gate failed: p99<200ms (p99 = 312 ms); error_rate<=1% (error_rate = 5.00%)" — one line, no
// newline; empty when every gate held.
std::string gate_failure_line(const std::vector<GateResult>& results);

// One metric of two runs. relative is (b - a) / a, NaN when a is 0. A regression is a change for
// the worse by more than the threshold: higher latency, error rate or errors, lower requests/s;
// for an error rate that was 0, any error.
struct MetricChange {
  std::string name;
  MetricKind kind = MetricKind::count;
  double a = 0, b = 0, absolute = 0, relative = 0;
  bool regression = false;
};

// The metrics compare shows, in order: requests, requests_per_s, bytes_per_s, error_rate,
// p50, p90, p99, p99_9, ttfb_p50, ttfb_p99, first_visible_p50, first_visible_p99, full_res_p50,
// full_res_p90, full_res_p99. threshold is a fraction (0.1: 10% worse).
std::vector<MetricChange> compare_reports(const LoadReport& a, const LoadReport& b,
                                          double threshold);
// {"threshold", "regressions": n, "metrics": [{name, a, b, absolute, relative (null when a is 0),
// regression}]}
nlohmann::json compare_json(const std::vector<MetricChange>& changes, double threshold);
// An aligned table: metric, A, B, change, relative, and "REGRESSION" in a last column.
std::string compare_table(const std::vector<MetricChange>& changes);

}  // namespace vts::loadtest
