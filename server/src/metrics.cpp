#include "metrics.hpp"

#include <cstdio>

namespace vts {
inline namespace server {
namespace http_detail {
namespace {

std::size_t status_index(int status) {
  for (std::size_t i = 0; i + 1 < kStatuses.size(); ++i)
    if (kStatuses[i] == status) return i;
  return kStatuses.size() - 1;  // "other"
}

void append_requests(const Metrics& m, std::string& out) {
  char line[256];
  out +=
      "# HELP vts_http_requests_total HTTP requests answered, by route and status.\n"
      "# TYPE vts_http_requests_total counter\n";
  for (int r = 0; r < kRouteCount; ++r)
    for (std::size_t s = 0; s < kStatuses.size(); ++s) {
      const auto n = m.requests[std::size_t(r)][s].load(std::memory_order_relaxed);
      if (n == 0) continue;
      const std::string status = kStatuses[s] ? std::to_string(kStatuses[s]) : "other";
      std::snprintf(line, sizeof line, "vts_http_requests_total{route=\"%s\",status=\"%s\"} %llu\n",
                    route_name(Route(r)), status.c_str(), (unsigned long long)n);
      out += line;
    }
}

void append_durations(const Metrics& m, std::string& out) {
  char line[256];
  out +=
      "# HELP vts_http_request_duration_seconds Time from a parsed request to its last byte "
      "written.\n"
      "# TYPE vts_http_request_duration_seconds histogram\n";
  std::uint64_t cumulative = 0;
  for (std::size_t b = 0; b <= kBuckets.size(); ++b) {
    cumulative += m.buckets[b].load(std::memory_order_relaxed);
    if (b < kBuckets.size())
      std::snprintf(line, sizeof line, "vts_http_request_duration_seconds_bucket{le=\"%g\"} %llu\n",
                    kBuckets[b], (unsigned long long)cumulative);
    else
      std::snprintf(line, sizeof line,
                    "vts_http_request_duration_seconds_bucket{le=\"+Inf\"} %llu\n",
                    (unsigned long long)cumulative);
    out += line;
  }
  std::snprintf(line, sizeof line,
                "vts_http_request_duration_seconds_sum %.6f\n"
                "vts_http_request_duration_seconds_count %llu\n",
                double(m.duration_us_sum.load()) * 1e-6, (unsigned long long)cumulative);
  out += line;
}

// One unlabelled sample with its HELP and TYPE lines.
void append_single(std::string& out, const char* name, const char* type, const char* help,
                   double value) {
  char buf[320];
  std::snprintf(buf, sizeof buf, "# HELP %s %s\n# TYPE %s %s\n%s %.17g\n", name, help, name, type,
                name, value);
  out += buf;
}

}  // namespace

void Metrics::record(Route route, int status, std::uint64_t bytes, std::chrono::nanoseconds d) {
  requests[std::size_t(route)][status_index(status)].fetch_add(1, std::memory_order_relaxed);
  response_bytes.fetch_add(bytes, std::memory_order_relaxed);
  const double s = std::chrono::duration<double>(d).count();
  std::size_t b = 0;
  while (b < kBuckets.size() && s > kBuckets[b]) ++b;
  buckets[b].fetch_add(1, std::memory_order_relaxed);
  duration_us_sum.fetch_add(
      std::uint64_t(std::chrono::duration_cast<std::chrono::microseconds>(d).count()),
      std::memory_order_relaxed);
}

std::string prometheus_text(const Metrics& m, std::size_t tilesets_loaded,
                            std::size_t archives_skipped, const AsyncTileProvider* provider) {
  std::string out;
  out.reserve(8192);
  append_requests(m, out);
  append_durations(m, out);
  append_single(out, "vts_http_response_bytes_total", "counter",
                "Response bytes written (headers and bodies).", double(m.response_bytes.load()));
  append_single(out, "vts_http_open_connections", "gauge", "Open client connections.",
                double(m.open_connections.load()));
  append_single(out, "vts_http_refused_connections_total", "counter",
                "Connections closed at once because max_connections were open.",
                double(m.refused_connections.load()));
  append_single(out, "vts_http_abandoned_connections_total", "counter",
                "Connections their client closed while responses were still owed: the provider "
                "fetches and web encodes only they waited for are dropped.",
                double(m.abandoned_connections.load()));
  const std::size_t provided = provider ? provider->all().size() : 0;
  append_single(out, "vts_tilesets_loaded", "gauge", "Tilesets being served.",
                double(tilesets_loaded + provided));
  append_single(out, "vts_archives_skipped", "gauge",
                "Archive files in served folders not served as they are (refused at start or by "
                "a reload; listed by /health).",
                double(archives_skipped));
  char line[256];
  std::snprintf(line, sizeof line,
                "# HELP vts_reloads_total Archive reloads, by result.\n"
                "# TYPE vts_reloads_total counter\n"
                "vts_reloads_total{result=\"swapped\"} %llu\n"
                "vts_reloads_total{result=\"refused\"} %llu\n",
                (unsigned long long)m.reloads_swapped.load(),
                (unsigned long long)m.reloads_refused.load());
  out += line;
  if (provider) out += provider->metrics_text();
  return out;
}

std::string store_metrics_text(const store::Counters& c) {
  const store::Counters::Snapshot n = c.snapshot();
  std::string out;
  append_single(out, "vts_store_requests_total", "counter",
                "Requests to object stores and web servers holding remote tilesets (retries and "
                "reload checks included).",
                double(n.requests));
  append_single(out, "vts_store_bytes_total", "counter", "Body bytes received from object stores.",
                double(n.bytes));
  append_single(out, "vts_store_retries_total", "counter",
                "Store requests repeated after a 5xx, a drop or a timeout.", double(n.retries));
  append_single(out, "vts_store_coalesced_reads_total", "counter",
                "Store reads that shared a GET another thread had in flight.", double(n.coalesced));
  return out;
}

}  // namespace http_detail
}  // namespace server
}  // namespace vts
