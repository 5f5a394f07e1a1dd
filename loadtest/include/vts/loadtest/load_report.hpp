// The results of one load test (`vts loadtest`) as plain data, and the three ways they are shown:
// to_json() for --json, summary_table() for the terminal, write_html_report() for --report DIR.
//
// The load engine fills a LoadReport once the run is over (or at an interrupt, with what it has);
// nothing here measures or aggregates, so the writers are deterministic functions of the struct.
// All latencies are nanoseconds. Every writer accepts any LoadReport, including an empty one (no
// requests, no seconds): plots then say "no data" and percentiles are 0. Strings may hold anything
// (a hostile title or URL): they are escaped in HTML and made valid UTF-8 in JSON.
//
// Thread safety: the functions only read their argument; call them from any thread.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "vts/base/result.hpp"
#include "vts/loadtest/latency_histogram.hpp"

namespace vts::loadtest {

struct GateResult;  // load_gates.hpp

// One second of the run: element i of LoadReport::seconds covers [i, i + 1) s after the start.
// Requests count when they complete (with a tile or an error); the percentiles are those of the
// total latency of the requests completed in that second, 0 when none completed.
struct LoadSecond {
  std::uint64_t requests = 0;
  std::uint64_t bytes = 0;  // payload bytes received in that second
  std::uint64_t errors = 0;
  std::uint64_t p50_ns = 0, p90_ns = 0, p99_ns = 0;
};

// Where completed requests were served from. revalidated: a conditional request answered 304
// (a network round trip, but the bytes came from the disk cache).
struct CacheTierCounts {
  std::uint64_t ram = 0, disk = 0, network = 0, revalidated = 0;
};

enum class LoopMode : std::uint8_t {
  closed,  // each viewer waits for its tiles before it asks for more
  open,    // requests are issued at `rate` whatever the responses (no coordinated omission)
};

struct LoadReport {
  // What ran, against what.
  std::string title;         // shown as the page and table heading; may be empty
  std::string target;        // the URL (or archive path) under test
  std::string command_line;  // as typed, for reproducing the run
  std::chrono::system_clock::time_point start{};
  double duration_s = 0;  // wall time of the measured run

  // The simulated load.
  std::uint32_t viewers = 0;
  std::string path;  // camera path name ("orbit", "zoom-in", ...)
  double fps = 0;    // frames per second each viewer simulates
  LoopMode mode = LoopMode::closed;
  double rate = 0;                  // open loop: the rate held, in rate_unit; ignored when closed
  std::string rate_unit = "req/s";  // unit of `rate`, shown next to it

  // Totals over the whole run (not recomputed from `seconds`, which may be cut short).
  std::uint64_t requests = 0;  // completed requests, with a tile or an error
  std::uint64_t bytes = 0;     // payload bytes received
  std::uint64_t errors = 0;    // requests that ended in an error
  std::uint64_t camera_moves = 0;

  std::vector<LoadSecond> seconds;

  // Merged over every viewer. Per request: time queued before it was sent, time to the first
  // response byte, and total (issue to tile in hand). Per camera move: time until the first
  // tile of the new view was visible, and until every visible tile was at full resolution.
  LatencyHistogram queue_time, ttfb, total, first_visible, full_resolution;

  CacheTierCounts tiers;
  std::map<int, std::uint64_t> by_status;               // HTTP status -> responses
  std::map<std::string, std::uint64_t> errors_by_kind;  // "timeout", "http_503", "checksum", ...
  std::uint64_t cancelled = 0;  // wasted: requests cancelled because the view moved on
};

// The --json document. Top-level keys: format ("vts-loadtest-report"), version (1), title,
// target, command_line, start (ISO 8601 UTC), start_unix_ms, duration_s, scenario {viewers, path,
// fps, mode ("open"/"closed"), rate, rate_unit}, totals {requests, bytes, errors, camera_moves,
// requests_per_s, bytes_per_s, error_ratio}, latency_ns {queue_time, ttfb, total, first_visible,
// full_resolution: each {count, min, mean, p50, p90, p99, p99_9, max, relative_error,
// sub_bucket_bits, buckets: [{low, high, count}]}}, cache_tiers {ram, disk, network,
// revalidated}, by_status {"200": n, ...}, errors_by_kind {kind: n}, wasted {cancelled},
// seconds [{t, requests, bytes, errors, p50_ns, p90_ns, p99_ns}]. Rates are 0 when duration_s is
// not positive; strings are valid UTF-8 (invalid bytes become U+FFFD), so dump() never throws.
nlohmann::json to_json(const LoadReport& report);

// The terminal summary: a few aligned plain-text tables (ASCII only, so any terminal aligns them),
// ending in a newline. Durations carry their own unit (ns, us, ms, s).
std::string summary_table(const LoadReport& report);

// A duration as the summary writes it: "850 ns", "12.3 us", "1.25 ms", "12.0 s", "2.50 min" (three
// significant digits; "-" when not finite).
std::string duration_text(double ns);

// Writes dir/index.html: one self-contained page (inline CSS and SVG, no scripts, no external
// resources) with the run's description, the summary tables and four plots, each an
// <svg class="plot"> with axes, tick labels and a legend, and with these ids:
//   plot-latency          p50 / p90 / p99 request latency per second
//   plot-full-resolution  distribution (CDF) of time to first visible tile and to full resolution
//   plot-throughput       requests/s and MB/s per second
//   plot-errors           errors per second
// Creates dir (and its parents) when missing. The page is written to a temporary file in dir,
// flushed to disk and renamed to index.html, so a failure never leaves a half-written report;
// an existing index.html is replaced. io on any file-system failure.
//
// With a baseline (an earlier run, `--baseline A.json`), plot-full-resolution and a request latency
// CDF (plot-latency-cdf, drawn only then) overlay the baseline's distributions in lighter colours
// as series whose data-series keys start with "baseline_", and a "Change against the baseline"
// table (class "compare", compare_reports() of load_gates.hpp) follows the summary.
//
// With gates (evaluate_gates() of the run's --slo and --max-error-rate), the page opens with a
// <section id="gates" class="gates"> (class "gates failed" when any failed): a table of each gate
// as given, the metric's measured value, and "pass" or "FAIL".
Status write_html_report(const LoadReport& report, const std::filesystem::path& dir,
                         const LoadReport* baseline = nullptr,
                         const std::vector<GateResult>* gates = nullptr);

// The page write_html_report() writes, as a string.
std::string html_report(const LoadReport& report, const LoadReport* baseline = nullptr,
                        const std::vector<GateResult>* gates = nullptr);

// The most per-second rows a report read back may have: `vts loadtest --duration` runs at most a
// week; a day more leaves room for requests still completing. No array or object of a report
// file may hold more entries either (read_report_file), so reading one costs bounded memory.
inline constexpr std::size_t kMaxReportSeconds = 8 * 24 * 3600;

// The LoadReport a to_json() document describes (the inverse of to_json for every field it
// writes; the histograms are rebuilt from their buckets, so counts and percentiles are exact).
// invalid_argument naming the first missing or malformed field (more than kMaxReportSeconds
// seconds, counts that sum past 2^64 - 1, a start_unix_ms beyond the year 2200), or a document
// that is not a "vts-loadtest-report" of version 1.
Result<LoadReport> report_from_json(const nlohmann::json& j);
// report_from_json of a file; errors name the file (not_found, io, invalid_argument for bad JSON,
// objects or arrays nested deeper than 64 levels, or one holding more than kMaxReportSeconds
// entries, refused as they are read).
Result<LoadReport> read_report_file(const std::filesystem::path& file);

// One report of N load generators that ran at the same time against one target: every count,
// histogram, status, error kind and tier summed, so the counts and percentiles are those of the
// union of the runs' samples (histograms must have the same sub_bucket_bits). start is the
// earliest start, duration_s the longest run (rates are totals over it), viewers and rate the
// sums; title, target, path, fps and mode are the first report's. Per-second rows add up by
// index (second i after each run's own start); their p50/p90/p99 are the highest of the runs'
// (an upper bound of the union's, which the per-second figures cannot give exactly).
// invalid_argument for no reports, different sub_bucket_bits, or counts (totals, tiers, statuses,
// error kinds, a second's requests, bytes or errors, a histogram's) that sum past 2^64 - 1, or
// viewers past 2^32 - 1: the error names the field and the report (1-based, in the given order).
Result<LoadReport> merge_reports(const std::vector<LoadReport>& reports);

}  // namespace vts::loadtest
