// Reading a --json load-test report back (report_from_json) and merging the reports of several
// load generators into one (merge_reports): the histograms travel as their buckets, so the merge
// is exact.
#include <algorithm>
#include <cstdlib>
#include <limits>
#include <tuple>
#include <type_traits>

#include "vts/base/file_io.hpp"
#include "vts/loadtest/load_report.hpp"
#include "vts/protocol/json_input.hpp"

namespace vts::loadtest {
namespace {

using nlohmann::json;

Error bad(const std::string& why) {
  return make_error(ErrorCode::invalid_argument, why);
}

// j[key] as T, or an error naming `where.key`.
template <class T>
Result<T> field(const json& j, const char* key, const std::string& where) {
  const std::string name = where.empty() ? std::string(key) : where + "." + key;
  if (!j.is_object() || !j.contains(key)) return bad("no field " + name);
  const json& v = j.at(key);
  if constexpr (std::is_same_v<T, std::string>) {
    if (!v.is_string()) return bad(name + " is not a string");
  } else if constexpr (std::is_floating_point_v<T>) {
    if (!v.is_number()) return bad(name + " is not a number");
  } else {
    if (!v.is_number_unsigned() && !(v.is_number_integer() && v.get<std::int64_t>() >= 0))
      return bad(name + " is not a non-negative integer");
  }
  return v.get<T>();
}

#define VTS_FIELD(var, T, j, key, where)  \
  auto var##_r = field<T>(j, key, where); \
  if (!var##_r) return var##_r.error();   \
  const T var = *var##_r

// into += n, or an error naming `name` when the sum would pass 2^64 - 1 (into is then unchanged).
Status add_count(std::uint64_t& into, std::uint64_t n, const std::string& name) {
  std::uint64_t sum;
  if (__builtin_add_overflow(into, n, &sum))
    return bad(name + ": the counts sum past 2^64 - 1 (" + std::to_string(into) + " + " +
               std::to_string(n) + ")");
  into = sum;
  return {};
}

#define VTS_ADD(into, n, name) \
  if (auto st = add_count(into, n, name); !st) return st.error()

// 2200-01-01T00:00:00Z: a start further from 1970 (either way) is no run's, and would overflow
// the clock's nanoseconds.
constexpr std::int64_t kMaxStartUnixMs = 7'258'118'400'000;

Result<LatencyHistogram> histogram_from_json(const json& h, const std::string& where) {
  VTS_FIELD(bits, std::uint64_t, h, "sub_bucket_bits", where);
  VTS_FIELD(min, std::uint64_t, h, "min", where);
  VTS_FIELD(max, std::uint64_t, h, "max", where);
  VTS_FIELD(mean, double, h, "mean", where);
  VTS_FIELD(count, std::uint64_t, h, "count", where);
  if (!h.contains("buckets") || !h["buckets"].is_array()) return bad(where + ".buckets: no array");
  std::vector<LatencyHistogram::Bucket> buckets;
  for (const json& b : h["buckets"]) {
    VTS_FIELD(low, std::uint64_t, b, "low", where + ".buckets[]");
    VTS_FIELD(high, std::uint64_t, b, "high", where + ".buckets[]");
    VTS_FIELD(n, std::uint64_t, b, "count", where + ".buckets[]");
    buckets.push_back({low, high, n});
  }
  auto out = LatencyHistogram::from_buckets(static_cast<int>(std::min<std::uint64_t>(bits, 99)),
                                            buckets, min, max, mean);
  if (!out) return bad(where + ": " + out.error().message);
  if (out->count() != count)
    return bad(where + ": the buckets hold " + std::to_string(out->count()) + " values, count is " +
               std::to_string(count));
  return out;
}

Status totals_from_json(const json& j, LoadReport& r) {
  if (!j.contains("totals")) return bad("no field totals");
  const json& t = j["totals"];
  VTS_FIELD(requests, std::uint64_t, t, "requests", "totals");
  VTS_FIELD(bytes, std::uint64_t, t, "bytes", "totals");
  VTS_FIELD(errors, std::uint64_t, t, "errors", "totals");
  VTS_FIELD(moves, std::uint64_t, t, "camera_moves", "totals");
  r.requests = requests;
  r.bytes = bytes;
  r.errors = errors;
  r.camera_moves = moves;
  return {};
}

Status scenario_from_json(const json& j, LoadReport& r) {
  VTS_FIELD(title, std::string, j, "title", "");
  VTS_FIELD(target, std::string, j, "target", "");
  VTS_FIELD(command_line, std::string, j, "command_line", "");
  VTS_FIELD(duration, double, j, "duration_s", "");
  if (!j.contains("start_unix_ms") || !j["start_unix_ms"].is_number_integer())
    return bad("start_unix_ms is not an integer");
  const json& start = j["start_unix_ms"];
  const bool start_in_range = start.is_number_unsigned()
                                  ? start.get<std::uint64_t>() <= std::uint64_t(kMaxStartUnixMs)
                                  : start.get<std::int64_t>() >= -kMaxStartUnixMs &&
                                        start.get<std::int64_t>() <= kMaxStartUnixMs;
  if (!start_in_range) return bad("start_unix_ms is beyond the year 2200");
  r.title = title;
  r.target = target;
  r.command_line = command_line;
  r.duration_s = duration;
  r.start = std::chrono::system_clock::time_point(
      std::chrono::milliseconds(j["start_unix_ms"].get<std::int64_t>()));
  if (!j.contains("scenario")) return bad("no field scenario");
  const json& s = j["scenario"];
  VTS_FIELD(viewers, std::uint64_t, s, "viewers", "scenario");
  VTS_FIELD(path, std::string, s, "path", "scenario");
  VTS_FIELD(fps, double, s, "fps", "scenario");
  VTS_FIELD(mode, std::string, s, "mode", "scenario");
  VTS_FIELD(rate, double, s, "rate", "scenario");
  VTS_FIELD(unit, std::string, s, "rate_unit", "scenario");
  r.viewers = static_cast<std::uint32_t>(std::min<std::uint64_t>(viewers, UINT32_MAX));
  r.path = path;
  r.fps = fps;
  r.mode = mode == "open" ? LoopMode::open : LoopMode::closed;
  r.rate = rate;
  r.rate_unit = unit;
  return {};
}

Status counts_from_json(const json& j, LoadReport& r) {
  for (const char* key : {"cache_tiers", "by_status", "errors_by_kind", "wasted"})
    if (!j.contains(key) || !j[key].is_object()) return bad(std::string("no object ") + key);
  const json& t = j["cache_tiers"];
  VTS_FIELD(ram, std::uint64_t, t, "ram", "cache_tiers");
  VTS_FIELD(disk, std::uint64_t, t, "disk", "cache_tiers");
  VTS_FIELD(network, std::uint64_t, t, "network", "cache_tiers");
  VTS_FIELD(revalidated, std::uint64_t, t, "revalidated", "cache_tiers");
  r.tiers = {ram, disk, network, revalidated};
  for (const auto& [code, n] : j["by_status"].items()) {
    VTS_FIELD(v, std::uint64_t, j["by_status"], code.c_str(), "by_status");
    // Keys that read as the same status ("200", "0200") add up.
    VTS_ADD(r.by_status[std::atoi(code.c_str())], v, "by_status." + code);
  }
  for (const auto& [kind, n] : j["errors_by_kind"].items()) {
    VTS_FIELD(v, std::uint64_t, j["errors_by_kind"], kind.c_str(), "errors_by_kind");
    r.errors_by_kind[kind] += v;
  }
  VTS_FIELD(cancelled, std::uint64_t, j["wasted"], "cancelled", "wasted");
  r.cancelled = cancelled;
  if (!j.contains("seconds") || !j["seconds"].is_array()) return bad("no array seconds");
  if (j["seconds"].size() > kMaxReportSeconds)
    return bad("seconds holds " + std::to_string(j["seconds"].size()) + " entries, more than " +
               std::to_string(kMaxReportSeconds) + " (8 days)");
  r.seconds.reserve(j["seconds"].size());
  for (const json& s : j["seconds"]) {
    LoadSecond sec;
    std::uint64_t LoadSecond::*members[] = {&LoadSecond::requests, &LoadSecond::bytes,
                                            &LoadSecond::errors,   &LoadSecond::p50_ns,
                                            &LoadSecond::p90_ns,   &LoadSecond::p99_ns};
    const char* keys[] = {"requests", "bytes", "errors", "p50_ns", "p90_ns", "p99_ns"};
    for (int k = 0; k < 6; ++k) {
      VTS_FIELD(v, std::uint64_t, s, keys[k], "seconds[]");
      sec.*members[k] = v;
    }
    r.seconds.push_back(sec);
  }
  return {};
}

// into += r, count by count; an error names the first count whose sum would pass 2^64 - 1.
Status add_counts(LoadReport& into, const LoadReport& r) {
  VTS_ADD(into.requests, r.requests, "totals.requests");
  VTS_ADD(into.bytes, r.bytes, "totals.bytes");
  VTS_ADD(into.errors, r.errors, "totals.errors");
  VTS_ADD(into.camera_moves, r.camera_moves, "totals.camera_moves");
  VTS_ADD(into.cancelled, r.cancelled, "wasted.cancelled");
  VTS_ADD(into.tiers.ram, r.tiers.ram, "cache_tiers.ram");
  VTS_ADD(into.tiers.disk, r.tiers.disk, "cache_tiers.disk");
  VTS_ADD(into.tiers.network, r.tiers.network, "cache_tiers.network");
  VTS_ADD(into.tiers.revalidated, r.tiers.revalidated, "cache_tiers.revalidated");
  for (const auto& [code, n] : r.by_status)
    VTS_ADD(into.by_status[code], n, "by_status." + std::to_string(code));
  for (const auto& [kind, n] : r.errors_by_kind)
    VTS_ADD(into.errors_by_kind[kind], n, "errors_by_kind." + kind);
  if (r.seconds.size() > into.seconds.size()) into.seconds.resize(r.seconds.size());
  for (std::size_t i = 0; i < r.seconds.size(); ++i) {
    LoadSecond& s = into.seconds[i];
    const LoadSecond& o = r.seconds[i];
    const std::string at = "seconds[" + std::to_string(i) + "].";
    VTS_ADD(s.requests, o.requests, at + "requests");
    VTS_ADD(s.bytes, o.bytes, at + "bytes");
    VTS_ADD(s.errors, o.errors, at + "errors");
    s.p50_ns = std::max(s.p50_ns, o.p50_ns);
    s.p90_ns = std::max(s.p90_ns, o.p90_ns);
    s.p99_ns = std::max(s.p99_ns, o.p99_ns);
  }
  if (r.viewers > std::numeric_limits<std::uint32_t>::max() - into.viewers)
    return bad("scenario.viewers: the counts sum past 2^32 - 1");
  into.viewers += r.viewers;
  return {};
}

}  // namespace

Result<LoadReport> report_from_json(const json& j) {
  // Checked by type first: json::value() throws on a field of another type.
  if (!j.is_object() || !j.contains("format") || j["format"] != "vts-loadtest-report")
    return bad("not a vts loadtest report (no \"format\": \"vts-loadtest-report\")");
  if (!j.contains("version") || j["version"] != 1)
    return bad("report version " + (j.contains("version") ? j["version"].dump() : "missing") +
               " (this vts reads 1)");
  LoadReport r;
  if (auto st = scenario_from_json(j, r); !st) return st.error();
  if (auto st = totals_from_json(j, r); !st) return st.error();
  if (auto st = counts_from_json(j, r); !st) return st.error();
  if (!j.contains("latency_ns")) return bad("no field latency_ns");
  std::pair<const char*, LatencyHistogram*> hs[] = {{"queue_time", &r.queue_time},
                                                    {"ttfb", &r.ttfb},
                                                    {"total", &r.total},
                                                    {"first_visible", &r.first_visible},
                                                    {"full_resolution", &r.full_resolution}};
  for (auto& [key, h] : hs) {
    if (!j["latency_ns"].contains(key)) return bad(std::string("no field latency_ns.") + key);
    auto parsed = histogram_from_json(j["latency_ns"][key], std::string("latency_ns.") + key);
    if (!parsed) return parsed.error();
    *h = std::move(*parsed);
  }
  return r;
}

Result<LoadReport> read_report_file(const std::filesystem::path& file) {
  auto text = read_file(file);  // not_found, io, or a folder, naming the file
  if (!text) return text.error();
  // Depth-limited, and no array or object past kMaxReportSeconds entries: refused while parsing,
  // before a hostile file's millions of rows take gigabytes.
  auto j = parse_json(*text, file.string(), kMaxJsonDepth, kMaxReportSeconds);
  if (!j) return bad(j.error().message);
  auto r = report_from_json(*j);
  if (!r) return bad(file.string() + ": " + r.error().message);
  return r;
}

Result<LoadReport> merge_reports(const std::vector<LoadReport>& reports) {
  if (reports.empty()) return bad("no reports to merge");
  LoadReport out = reports.front();
  for (std::size_t i = 1; i < reports.size(); ++i) {
    const LoadReport& r = reports[i];
    auto refused = [&](const Error& e) {
      return bad("cannot merge report " + std::to_string(i + 1) + " of " +
                 std::to_string(reports.size()) + ": " + e.message);
    };
    if (auto st = add_counts(out, r); !st) return refused(st.error());
    std::tuple<const char*, LatencyHistogram*, const LatencyHistogram*> hs[] = {
        {"latency_ns.queue_time", &out.queue_time, &r.queue_time},
        {"latency_ns.ttfb", &out.ttfb, &r.ttfb},
        {"latency_ns.total", &out.total, &r.total},
        {"latency_ns.first_visible", &out.first_visible, &r.first_visible},
        {"latency_ns.full_resolution", &out.full_resolution, &r.full_resolution}};
    for (auto& [name, into, from] : hs) {
      if (auto st = into->merge(*from); !st) {
        Error e = st.error();
        e.message = std::string(name) + ": " + e.message;
        return refused(e);
      }
    }
    out.start = std::min(out.start, r.start);
    out.duration_s = std::max(out.duration_s, r.duration_s);
    out.rate += r.rate;
  }
  return out;
}

}  // namespace vts::loadtest
