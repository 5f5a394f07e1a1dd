// The server's counters and their Prometheus text exposition (served at /metrics). Counters are
// relaxed atomics: any thread records, any thread formats.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <string>

#include "vts/protocol/tile_provider.hpp"
#include "vts/server/router.hpp"
#include "vts/store/options.hpp"

namespace vts {
inline namespace server {
namespace http_detail {

// Statuses counted by label; anything else counts as "other" (the trailing 0).
inline constexpr std::array<int, 17> kStatuses = {200, 204, 206, 304, 400, 401, 403, 404, 405,
                                                  413, 414, 416, 431, 500, 502, 503, 0};
// Request-duration histogram bounds, in seconds.
inline constexpr std::array<double, 16> kBuckets = {0.0001, 0.00025, 0.0005, 0.001, 0.0025, 0.005,
                                                    0.01,   0.025,   0.05,   0.1,   0.25,   0.5,
                                                    1.0,    2.5,     5.0,    10.0};

struct Metrics {
  std::array<std::array<std::atomic<std::uint64_t>, kStatuses.size()>, kRouteCount> requests{};
  std::array<std::atomic<std::uint64_t>, kBuckets.size() + 1> buckets{};  // last = +Inf
  std::atomic<std::uint64_t> duration_us_sum{0};
  std::atomic<std::uint64_t> response_bytes{0};
  std::atomic<std::int64_t> open_connections{0};
  std::atomic<std::uint64_t> reloads_swapped{0}, reloads_refused{0};
  std::atomic<std::uint64_t> refused_connections{0};
  // Connections whose client went away while responses were still owed (their work abandoned).
  std::atomic<std::uint64_t> abandoned_connections{0};

  // One answered request: its route, status, bytes written and time to its last byte.
  void record(Route route, int status, std::uint64_t bytes, std::chrono::nanoseconds d);
};

// The exposition: every counter above, the tileset gauges (served; archive files skipped, as
// TilesetRegistry::skipped() lists them), then the provider's own text.
// The object-store requests of remote tilesets (store::Counters): requests, body bytes, retries,
// reads that shared another's GET.
std::string store_metrics_text(const store::Counters& c);

std::string prometheus_text(const Metrics& m, std::size_t tilesets_loaded,
                            std::size_t archives_skipped, const AsyncTileProvider* provider);

}  // namespace http_detail
}  // namespace server
}  // namespace vts
