#include "vts/client/warm.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <unordered_map>

#include "vts/client/saved_source.hpp"
#include "vts/client/tile_cache.hpp"

namespace vts::client {

namespace {

using Clock = std::chrono::steady_clock;

constexpr std::size_t kErrorsKept = 5;
// The cache's disk writes trail its deliveries (its disk thread serves reads first); waiting for
// them after every this many bytes or tiles fetched bounds the tiles queued for writing, which are
// held in memory.
constexpr std::uint64_t kFlushEveryBytes = 64ull << 20;
constexpr std::uint64_t kFlushEveryTiles = 16384;
constexpr auto kPoll = std::chrono::milliseconds(100);
// A bulk fill checkpoints the cache's write-ahead log after this many bytes rather than the
// default 2 MiB: a checkpoint syncs twice and copies every page it holds, so fewer of them cost
// fewer fsyncs and copy pages rewritten by several transactions (b-tree and index pages) once.
// bench/warm_bench.sh measures the choice (its table of SQLite settings).
constexpr std::uint64_t kWarmWalBytes = 32ull << 20;
constexpr std::uint64_t kDefaultWalBytes = 2ull << 20;
// Extra PRAGMAs for the cache's connection (DiskCacheOptions::extra_pragmas), for the bench.
constexpr const char* kPragmasEnv = "VTS_WARM_SQLITE_PRAGMAS";

// At most a sixteenth of the cap, so a small cache's files stay near their bound.
std::uint64_t warm_wal_checkpoint_bytes(std::uint64_t cache_bytes) {
  return std::max(kDefaultWalBytes, std::min(kWarmWalBytes, cache_bytes / 16));
}

// The tiles to warm: per level, the tile rectangle over the region; coarse levels first, each
// level in row-major order. Walked lazily (a planet has too many tiles to list).
class TileWalk {
 public:
  TileWalk(const Geometry& g, int first, int last, const TexelRect& region) {
    for (int z = first; z <= last && !region.empty(); ++z) {
      const TexelRect r = g.map_rect(g.max_zoom(), region, z);
      if (r.empty()) continue;
      const std::uint64_t t = g.tile_size();
      Range range{std::uint8_t(z), std::uint32_t(r.x0 / t), std::uint32_t(r.y0 / t),
                  std::uint32_t((r.x1 + t - 1) / t), std::uint32_t((r.y1 + t - 1) / t)};
      total_ += std::uint64_t(range.x1 - range.x0) * (range.y1 - range.y0);
      ranges_.push_back(range);
    }
    if (!ranges_.empty()) {
      x_ = ranges_[0].x0;
      y_ = ranges_[0].y0;
    }
  }
  std::uint64_t total() const { return total_; }

  bool next(TileId& out) {
    if (level_ >= ranges_.size()) return false;
    const Range& r = ranges_[level_];
    out = TileId{r.z, x_, y_};
    if (++x_ == r.x1) {
      x_ = r.x0;
      if (++y_ == r.y1 && ++level_ < ranges_.size()) {
        x_ = ranges_[level_].x0;
        y_ = ranges_[level_].y0;
      }
    }
    return true;
  }

 private:
  struct Range {
    std::uint8_t z;
    std::uint32_t x0, y0, x1, y1;  // tiles, half-open
  };
  std::vector<Range> ranges_;
  std::uint64_t total_ = 0;
  std::size_t level_ = 0;
  std::uint32_t x_ = 0, y_ = 0;
};

// What the cache's callbacks (on its threads) report to the walking thread.
struct WarmState {
  std::mutex mutex;
  std::condition_variable cv;
  std::uint64_t outstanding = 0;
  WarmReport counts;
  // Our sequence number -> the cache's handle (0 until get() has returned), for cancellation.
  std::unordered_map<std::uint64_t, TileCache::Handle> live;

  void record(TileId id, PayloadResult&& r) {
    switch (r.kind) {
      case PayloadResult::Kind::ok:
        if (r.from == PayloadResult::From::network) {
          ++counts.network;
          counts.bytes_network += r.tile->payload.size();
        } else {
          ++counts.cached;
          counts.bytes_cached += r.tile->payload.size();
        }
        break;
      case PayloadResult::Kind::absent:
        ++counts.absent;
        break;
      case PayloadResult::Kind::error:
        ++counts.failed;
        if (counts.first_errors.size() < kErrorsKept)
          counts.first_errors.push_back("tile " + id.to_string() + ": " +
                                        (r.error ? r.error->message : std::string("failed")));
        break;
      case PayloadResult::Kind::cancelled:
        ++counts.cancelled;
        break;
    }
  }
};

class WarmRun {
 public:
  WarmRun(const WarmOptions& o, std::uint64_t total) : o_(o), total_(total) {}

  // The state outlives the cache: the cache's destructor may still run callbacks.
  WarmReport run(std::unique_ptr<TileCache> cache, TileWalk& walk) {
    cache_ = std::move(cache);
    t0_ = Clock::now();
    bool too_many_errors = false;
    walk_tiles(walk, too_many_errors);
    const bool stopped = stop_requested() || disk_error_ || too_many_errors;
    if (stopped) cancel_live();
    drain(stopped);
    const Status flushed = cache_->flush();
    const double elapsed = seconds();
    if (!disk_error_) disk_error_ = cache_->last_disk_error();
    if (!disk_error_ && !flushed.ok()) disk_error_ = flushed.error();
    const DiskCacheStats ds = cache_->disk()->stats();
    cache_.reset();  // joins the cache's threads; no callback runs after this

    WarmReport r = std::move(st_.counts);
    r.tiles_total = total_;
    r.seconds = elapsed;
    r.interrupted = stop_requested();
    r.too_many_errors = too_many_errors;
    r.disk_error = disk_error_;
    r.cache = ds;
    return r;
  }

 private:
  bool stop_requested() const { return o_.stop && o_.stop->load(); }
  double seconds() const { return std::chrono::duration<double>(Clock::now() - t0_).count(); }

  void report_progress() {
    if (!o_.progress) return;
    WarmProgress p;
    {
      std::lock_guard lock(st_.mutex);
      p.done = st_.counts.done();
      p.cached = st_.counts.cached;
      p.bytes_network = st_.counts.bytes_network;
    }
    p.total = total_;
    p.seconds = seconds();
    o_.progress(p);
  }

  // Issues gets, at most `concurrency` outstanding, until the walk ends or something stops it.
  void walk_tiles(TileWalk& walk, bool& too_many_errors) {
    std::uint64_t flushed_bytes = 0, flushed_tiles = 0;
    for (;;) {
      if (stop_requested()) return;
      if (auto e = cache_->last_disk_error()) {
        disk_error_ = e;
        return;
      }
      bool room;
      {
        std::unique_lock lock(st_.mutex);
        st_.cv.wait_for(lock, kPoll, [&] { return st_.outstanding < o_.concurrency; });
        room = st_.outstanding < o_.concurrency;
        too_many_errors = o_.max_errors > 0 && st_.counts.failed >= o_.max_errors;
      }
      if (too_many_errors) return;
      report_progress();
      if (!room) continue;
      TileId id;
      if (!walk.next(id)) return;
      issue(id);
      std::uint64_t bytes, tiles;
      {
        std::lock_guard lock(st_.mutex);
        bytes = st_.counts.bytes_network;
        tiles = st_.counts.network;
      }
      if (bytes - flushed_bytes >= kFlushEveryBytes || tiles - flushed_tiles >= kFlushEveryTiles) {
        flushed_bytes = bytes;
        flushed_tiles = tiles;
        (void)cache_->flush();  // errors surface through last_disk_error()
      }
    }
  }

  void issue(TileId id) {
    GetOptions go;
    go.pin = true;          // warmed tiles are never evicted by browsing
    go.revalidate = false;  // a cached tile is what we came for; no extra request
    const std::uint64_t seq = next_seq_++;
    {
      std::lock_guard lock(st_.mutex);
      st_.live.emplace(seq, 0);
      ++st_.outstanding;
    }
    WarmState& st = st_;
    const auto h = cache_->get(id, go, [&st, seq, id](PayloadResult&& r) {
      std::lock_guard lock(st.mutex);
      st.live.erase(seq);
      --st.outstanding;
      st.record(id, std::move(r));
      st.cv.notify_all();
    });
    if (h) {
      std::lock_guard lock(st_.mutex);
      if (auto it = st_.live.find(seq); it != st_.live.end()) it->second = h;
    }
  }

  void cancel_live() {
    std::vector<TileCache::Handle> handles;
    {
      std::lock_guard lock(st_.mutex);
      for (const auto& [seq, h] : st_.live)
        if (h) handles.push_back(h);
    }
    for (auto h : handles) cache_->cancel(h);
  }

  // Waits for the gets still outstanding (a stop meanwhile cancels them).
  void drain(bool cancelled) {
    for (;;) {
      {
        std::unique_lock lock(st_.mutex);
        if (st_.cv.wait_for(lock, kPoll, [&] { return st_.outstanding == 0; })) return;
      }
      if (!cancelled && stop_requested()) {
        cancelled = true;
        cancel_live();
      }
      report_progress();
    }
  }

  const WarmOptions& o_;
  const std::uint64_t total_;
  WarmState st_;
  std::unique_ptr<TileCache> cache_;
  Clock::time_point t0_;
  std::uint64_t next_seq_ = 1;
  std::optional<Error> disk_error_;  // a disk error that makes going on pointless
};

std::string degrees_text(const LonLatBounds& b) {
  char text[128];
  std::snprintf(text, sizeof text, "%.9g,%.9g,%.9g,%.9g", b.west, b.south, b.east, b.north);
  return text;
}

}  // namespace

Result<TexelRect> bbox_region(const TilesetInfo& info, const LonLatBounds& bbox) {
  if (!info.georeference)
    return make_error(ErrorCode::invalid_argument,
                      "--bbox needs a georeferenced tileset; this one has no georeference "
                      "(use --region, in texels)");
  const LonLatBounds& b = bbox;
  if (!std::isfinite(b.west) || !std::isfinite(b.south) || !std::isfinite(b.east) ||
      !std::isfinite(b.north) || b.west >= b.east || b.south >= b.north)
    return make_error(ErrorCode::invalid_argument,
                      "--bbox " + degrees_text(b) +
                          ": needs finite west < east and south < north (degrees; a box across "
                          "the antimeridian is not supported)");
  const Georeference& geo = *info.georeference;
  const LonLatBounds clipped{std::max(b.west, geo.bounds.west), std::max(b.south, geo.bounds.south),
                             std::min(b.east, geo.bounds.east),
                             std::min(b.north, geo.bounds.north)};
  if (clipped.west >= clipped.east || clipped.south >= clipped.north) return TexelRect{};
  return footprint_texels(geo.tiling, info.geometry, clipped);
}

std::uint64_t warm_tile_count(const Geometry& geometry, int first_level, int last_level,
                              const TexelRect& region) {
  return TileWalk(geometry, first_level, last_level, region).total();
}

Result<WarmReport> warm_cache(const WarmOptions& o) {
  const SourceInfo& info = o.source->info();
  const Geometry& g = info.info.geometry;
  TileWalk walk(g, o.first_level, o.last_level,
                o.region.value_or(TexelRect{0, 0, g.width(), g.height()}));
  // No RAM cache: what the RAM cache pins it never evicts, so pinning every warmed tile there
  // would hold the whole tileset in memory. Warm only needs the disk.
  TileCacheOptions co;
  co.ram_bytes = 0;
  co.disk = DiskCacheOptions{};
  co.disk->dir = o.cache_dir;
  co.disk->max_bytes = o.cache_bytes;
  co.disk->wal_checkpoint_bytes = warm_wal_checkpoint_bytes(o.cache_bytes);
  if (const char* pragmas = std::getenv(kPragmasEnv)) co.disk->extra_pragmas = pragmas;
  if (o.stop && o.stop->load())
    return make_error(ErrorCode::cancelled, "interrupted before warming began");
  WarmRun run(o, walk.total());
  auto created = TileCache::create(o.source, co);
  if (!created) return created.error();
  std::unique_ptr<TileCache> cache = std::move(*created);
  if (o.remember_as)
    if (auto saved = save_source_info(o.cache_dir, *o.remember_as, info); !saved)
      return saved.error();
  return run.run(std::move(cache), walk);
}

nlohmann::json warm_report_json(const WarmOptions& o, const WarmReport& r) {
  const auto& region = o.region;
  nlohmann::json j;
  j["source"] = o.source->info().key;
  j["cache_dir"] = o.cache_dir.string();
  j["levels"] = {o.first_level, o.last_level};
  j["region"] = region ? nlohmann::json{region->x0, region->y0, region->x1, region->y1}
                       : nlohmann::json(nullptr);
  j["bbox"] = o.bbox ? nlohmann::json{o.bbox->west, o.bbox->south, o.bbox->east, o.bbox->north}
                     : nlohmann::json(nullptr);
  j["tiles_total"] = r.tiles_total;
  j["from_network"] = r.network;
  j["already_cached"] = r.cached;
  j["absent"] = r.absent;
  j["failed"] = r.failed;
  j["not_done"] = r.tiles_total - r.done();
  j["bytes_fetched"] = r.bytes_network;
  j["bytes_cached"] = r.bytes_cached;
  j["seconds"] = r.seconds;
  j["tiles_per_second"] = r.seconds > 0 ? double(r.done()) / r.seconds : 0.0;
  j["bytes_per_second"] = r.seconds > 0 ? double(r.bytes_network) / r.seconds : 0.0;
  j["complete"] = r.complete();
  j["interrupted"] = r.interrupted;
  j["errors"] = r.first_errors;
  j["disk_error"] = r.disk_error ? nlohmann::json(r.disk_error->message) : nlohmann::json(nullptr);
  j["cache"] = {{"tiles", r.cache.tiles},
                {"bytes", r.cache.bytes},
                {"pinned_tiles", r.cache.pinned_tiles},
                {"pinned_bytes", r.cache.pinned_bytes},
                {"max_bytes", r.cache.max_bytes}};
  return j;
}

}  // namespace vts::client
