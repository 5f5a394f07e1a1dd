// The warm engine behind `vts warm`: fills a disk cache with a tileset's tiles (all, or some
// levels over a region), pinned, for offline use. A TileCache (no RAM cache) does the disk
// lookups, fetching, verification and storing; the engine walks the tiles (coarse levels first,
// each level row-major), keeps at most `concurrency` gets in flight and counts the outcomes.
//
// Resumable: a tile already cached is a disk hit, counted as already cached and pinned; an
// interrupted run leaves a valid cache behind.
//
// The cache's write-ahead log is checkpointed every 32 MiB (at most a sixteenth of cache_bytes)
// rather than the cache's default 2 MiB (DiskCacheOptions::wal_checkpoint_bytes): fewer fsyncs
// for the same durability. The environment variable VTS_WARM_SQLITE_PRAGMAS, when set, is run on
// the cache's connection after its own settings (DiskCacheOptions::extra_pragmas): the way
// bench/warm_bench.sh measures settings; not for normal use.
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/client/disk_cache.hpp"
#include "vts/client/source.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/protocol/tileset.hpp"
#include "vts/protocol/tiling.hpp"

namespace vts::client {

// Counts so far; handed to WarmOptions::progress.
struct WarmProgress {
  std::uint64_t done = 0, total = 0, cached = 0;
  std::uint64_t bytes_network = 0;
  double seconds = 0;  // since the walk started
};

struct WarmOptions {
  std::shared_ptr<TileSource> source;  // opened (possibly an offline_source)
  std::filesystem::path cache_dir;     // created if missing
  std::uint64_t cache_bytes = 10ull << 30;
  int first_level = 0, last_level = 0;  // inclusive; last_level <= the geometry's max zoom
  std::optional<TexelRect> region;      // finest-level texels inside the image; none = all
  // The --bbox the region came from (bbox_region), for the report only.
  std::optional<LonLatBounds> bbox;
  unsigned concurrency = 32;  // gets in flight, >= 1
  unsigned max_errors = 100;  // stop after this many failed tiles; 0 = never
  // When set, the source's description is saved in the cache folder under this location
  // (save_source_info) once the cache is open, before the first get.
  std::optional<std::string> remember_as;
  const std::atomic<bool>* stop = nullptr;  // set to stop early (the gets in flight are cancelled)
  // Called on the calling thread, at every get issued and at least every 100 ms; not throttled.
  std::function<void(const WarmProgress&)> progress;
};

struct WarmReport {
  std::uint64_t tiles_total = 0;
  std::uint64_t network = 0, cached = 0, absent = 0, failed = 0, cancelled = 0;
  std::uint64_t bytes_network = 0, bytes_cached = 0;
  double seconds = 0;
  bool interrupted = false;               // `stop` was set
  bool too_many_errors = false;           // stopped after max_errors failures
  std::vector<std::string> first_errors;  // the first few failures, "tile Z/X/Y: message"
  std::optional<Error> disk_error;        // a disk write or flush error that stopped the run
  DiskCacheStats cache;                   // the disk cache at the end

  std::uint64_t done() const { return network + cached + absent + failed; }
  bool complete() const {
    return !interrupted && !disk_error && failed == 0 && done() == tiles_total;
  }
};

// The region (finest-level texels) of a box in degrees on a georeferenced tileset: the box clipped
// to the tileset's footprint (georeference bounds), then footprint_texels() (tiling.hpp), so at
// every level the tiles warmed are exactly footprint_tiles() of the clipped box: all of them exist
// in a sparse archive. A box that does not overlap the footprint gives an empty rectangle (no
// tiles). Errors (invalid_argument): a tileset without georeference; a box that is not finite or
// has west >= east or south >= north (a box across the antimeridian is not supported).
Result<TexelRect> bbox_region(const TilesetInfo& info, const LonLatBounds& bbox);

// Tiles of levels first..last over `region` (finest-level texels); an empty region has none.
std::uint64_t warm_tile_count(const Geometry& geometry, int first_level, int last_level,
                              const TexelRect& region);

// Blocks until the walk ends, `stop` is set, max_errors tiles failed or the disk fails; the
// outcome of each tile is in the report, not an error. Errors (before any tile is asked for):
// cancelled when `stop` is already set, and those of TileCache::create and save_source_info.
Result<WarmReport> warm_cache(const WarmOptions& options);

// The `vts warm --json` document of a run: source (key), cache_dir, levels [first, last], region
// ([x0, y0, x1, y1] or null), bbox ([west, south, east, north] as asked, or null), tiles_total,
// from_network, already_cached, absent, failed, not_done, bytes_fetched, bytes_cached, seconds,
// tiles_per_second, bytes_per_second, complete, interrupted, errors, disk_error (or null), cache
// {tiles, bytes, pinned_tiles, pinned_bytes, max_bytes}.
nlohmann::json warm_report_json(const WarmOptions& options, const WarmReport& report);

}  // namespace vts::client
