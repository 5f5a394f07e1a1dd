// vts warm: fill the disk cache with a tileset's tiles (all, or some levels / a region), pinned,
// for offline use. Thin glue over client::TileCache: the cache does the disk lookups, fetching,
// verification and storing; this file walks the tiles, bounds the gets in flight, reports.
//
// Resumable for free: a tile already cached (and valid) is a disk hit, counted as "already
// cached" and pinned; an interrupted run (Ctrl-C, kill -9) leaves a valid cache behind.
#include <atomic>
#include <cctype>
#include <chrono>
#include <condition_variable>
#include <csignal>
#include <cstdio>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "commands.hpp"
#include "progress.hpp"
#include "vts/client/saved_source.hpp"
#include "vts/client/source.hpp"
#include "vts/client/tile_cache.hpp"

namespace vts::cli {

namespace {

using Clock = std::chrono::steady_clock;

struct WarmArgs {
  std::string url, cache_dir, levels, region, cache_size = "10G";
  unsigned concurrency = 32;
  unsigned max_errors = 100;
  bool json = false, quiet = false;
};

// Decimal digits only, no sign; false on overflow or anything else.
bool parse_u64(std::string_view s, std::uint64_t& out) {
  if (s.empty() || s.size() > 19) return false;
  std::uint64_t v = 0;
  for (char c : s) {
    if (c < '0' || c > '9') return false;
    v = v * 10 + std::uint64_t(c - '0');
  }
  out = v;
  return true;
}

// "A-B" or "A" (one level).
Result<std::pair<int, int>> parse_levels(const std::string& text) {
  auto bad = [&](const std::string& why) {
    return make_error(ErrorCode::invalid_argument,
                      "--levels '" + text + "' " + why + " (expected A-B or A, e.g. 0-5)");
  };
  const std::size_t dash = text.find('-');
  std::uint64_t a = 0, b = 0;
  const std::string_view t = text;
  if (dash == std::string::npos) {
    if (!parse_u64(t, a)) return bad("is not a level range");
    b = a;
  } else if (!parse_u64(t.substr(0, dash), a) || !parse_u64(t.substr(dash + 1), b)) {
    return bad("is not a level range");
  }
  if (a > std::uint64_t(Geometry::kMaxZoom) || b > std::uint64_t(Geometry::kMaxZoom))
    return bad("names a level beyond " + std::to_string(Geometry::kMaxZoom));
  if (a > b) return bad("is empty: the first level is after the last");
  return std::pair<int, int>{int(a), int(b)};
}

// x0,y0,x1,y1 in finest-level texels, half-open, non-empty.
Result<TexelRect> parse_region(const std::string& text) {
  std::uint64_t v[4];
  std::size_t start = 0;
  for (int i = 0; i < 4; ++i) {
    const std::size_t comma = i < 3 ? text.find(',', start) : text.size();
    if (comma == std::string::npos ||
        !parse_u64(std::string_view(text).substr(start, comma - start), v[i]))
      return make_error(
          ErrorCode::invalid_argument,
          "--region '" + text + "' is not of the form x0,y0,x1,y1 (finest-level texels)");
    start = comma + 1;
  }
  TexelRect r{v[0], v[1], v[2], v[3]};
  if (r.empty())
    return make_error(ErrorCode::invalid_argument,
                      "--region '" + text + "' is empty (x1 must exceed x0 and y1 exceed y0)");
  return r;
}

// A byte count with an optional binary suffix: 1048576, 512M, 10G, 2GiB, 64KB.
Result<std::uint64_t> parse_size(const std::string& text) {
  auto bad = [&] {
    return make_error(ErrorCode::invalid_argument,
                      "--cache-size '" + text + "' is not a positive size (e.g. 500M, 10G)");
  };
  std::size_t n = 0;
  while (n < text.size() && text[n] >= '0' && text[n] <= '9') ++n;
  std::uint64_t v = 0;
  if (!parse_u64(std::string_view(text).substr(0, n), v) || v == 0) return bad();
  std::string suffix = text.substr(n);
  for (auto& c : suffix) c = char(std::toupper(static_cast<unsigned char>(c)));
  int shift = 0;
  if (!suffix.empty()) {
    const std::string units = "KMGT";
    const std::size_t u = units.find(suffix[0]);
    if (u == std::string::npos) return suffix == "B" ? Result<std::uint64_t>(v) : bad();
    shift = 10 * int(u + 1);
    const std::string rest = suffix.substr(1);
    if (!rest.empty() && rest != "B" && rest != "IB") return bad();
  }
  if (shift && v > (~std::uint64_t{0} >> shift)) return bad();
  return v << shift;
}

// The tiles to warm: per level, the tile rectangle over the region; coarse levels first, each
// level in row-major order. Walked lazily (a planet has too many tiles to list).
class TileWalk {
 public:
  TileWalk(const Geometry& g, int first, int last, const TexelRect& region) {
    for (int z = first; z <= last; ++z) {
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

// What the callbacks (on the cache's threads) report to the main thread.
struct WarmState {
  std::mutex mutex;
  std::condition_variable cv;
  std::uint64_t outstanding = 0;
  std::uint64_t network = 0, cached = 0, absent = 0, failed = 0, cancelled = 0;
  std::uint64_t bytes_network = 0, bytes_cached = 0;
  std::vector<std::string> first_errors;
  // Our sequence number → the cache's handle (0 until get() has returned), for cancellation.
  std::unordered_map<std::uint64_t, client::TileCache::Handle> live;

  std::uint64_t done() const { return network + cached + absent + failed; }
};

constexpr std::size_t kErrorsKept = 5;
// The cache's disk writes trail its deliveries (its disk thread serves reads first); waiting for
// them after every this many bytes or tiles fetched bounds the tiles queued for writing, which are
// held in memory.
constexpr std::uint64_t kFlushEveryBytes = 64ull << 20;
constexpr std::uint64_t kFlushEveryTiles = 16384;

std::string levels_text(int a, int b) {
  return a == b ? std::to_string(a) : std::to_string(a) + "-" + std::to_string(b);
}

int run_warm(const WarmArgs& a) {
  // Everything that can be checked without the network is checked first, and nothing touches
  // the cache folder before the source has opened and the request fits its geometry.
  std::optional<std::pair<int, int>> levels;
  if (!a.levels.empty()) {
    auto l = parse_levels(a.levels);
    if (!l) return report_error(l.error());
    levels = *l;
  }
  std::optional<TexelRect> region;
  if (!a.region.empty()) {
    auto r = parse_region(a.region);
    if (!r) return report_error(r.error());
    region = *r;
  }
  auto cache_size = parse_size(a.cache_size);
  if (!cache_size) return report_error(cache_size.error());
  if (a.cache_dir.empty())
    return report_error(make_error(ErrorCode::invalid_argument, "--cache-dir is empty"));
  const std::atomic<bool>& stop_requested = install_stop_signals();
  auto interrupted_early = [] {
    return report_error(make_error(ErrorCode::cancelled, "interrupted before warming began"));
  };

  client::SourceOptions so;
  so.fetcher.max_in_flight = a.concurrency;
  auto opened = client::open_source(a.url, so);
  bool offline = false;
  if (!opened && opened.error().code == ErrorCode::io) {
    // The network is gone, but a cache warmed from this URL before remembers the tileset: check
    // what it holds (and fail naming the tiles it lacks).
    auto saved = client::load_source_info(a.cache_dir, a.url);
    if (saved) {
      std::fprintf(stderr, "vts warm: %s: %s; checking the cache offline\n", a.url.c_str(),
                   opened.error().message.c_str());
      opened = client::offline_source(std::move(*saved));
      offline = true;
    }
  }
  if (!opened) return report_error(opened.error());
  std::shared_ptr<client::TileSource> source = std::move(*opened);
  const client::SourceInfo& info = source->info();
  const Geometry& g = info.info.geometry;

  const auto [first, last] = levels.value_or(std::pair<int, int>{0, g.max_zoom()});
  if (last > g.max_zoom())
    return report_error(make_error(ErrorCode::invalid_argument, "--levels " + a.levels + ": " +
                                                                    info.key + " has levels 0-" +
                                                                    std::to_string(g.max_zoom())));
  const TexelRect full{0, 0, g.width(), g.height()};
  if (region && (region->x1 > g.width() || region->y1 > g.height()))
    return report_error(make_error(
        ErrorCode::invalid_argument,
        "--region " + a.region + " reaches beyond the image (" + std::to_string(g.width()) + "x" +
            std::to_string(g.height()) + " texels at level " + std::to_string(g.max_zoom()) + ")"));
  TileWalk walk(g, first, last, region.value_or(full));
  const std::uint64_t total = walk.total();

  // No RAM cache: what the RAM cache pins it never evicts, so pinning every warmed tile there
  // would hold the whole tileset in memory. Warm only needs the disk.
  client::TileCacheOptions co;
  co.ram_bytes = 0;
  co.disk = client::DiskCacheOptions{};
  co.disk->dir = a.cache_dir;
  co.disk->max_bytes = *cache_size;
  if (stop_requested.load()) return interrupted_early();
  WarmState st;  // outlives the cache: the cache's destructor may still run callbacks
  auto created = client::TileCache::create(source, co);
  if (!created) return report_error(created.error());
  std::unique_ptr<client::TileCache> cache = std::move(*created);
  // Remember the tileset in the cache folder, so viewers and `vts cache serve` can open it with
  // the network gone.
  if (!offline)
    if (auto saved = client::save_source_info(a.cache_dir, a.url, info); !saved)
      return report_error(saved.error());

  const bool show = !a.quiet && !a.json;
  const bool tty = ProgressBar::stderr_is_terminal();
  ProgressBar bar("warm", "tiles", show);
  const auto t0 = Clock::now();
  auto seconds = [&] { return std::chrono::duration<double>(Clock::now() - t0).count(); };
  auto last_draw = t0, last_line = t0;
  auto report_progress = [&] {
    if (!show) return;
    const auto now = Clock::now();
    std::uint64_t done, cached, bytes;
    {
      std::lock_guard lock(st.mutex);
      done = st.done();
      cached = st.cached;
      bytes = st.bytes_network;
    }
    const double t = seconds();
    const std::string rate = human_bytes(t > 0 ? std::uint64_t(double(bytes) / t) : 0) + "/s";
    if (tty) {
      if (now - last_draw < std::chrono::milliseconds(100)) return;
      last_draw = now;
      bar.update(done, total,
                 human_bytes(bytes) + "  " + rate + "  " + std::to_string(cached) + " cached");
    } else {
      // Not a terminal (a log file, CI): one plain line every few seconds instead of a bar.
      if (now - last_line < std::chrono::seconds(5)) return;
      last_line = now;
      const double tps = t > 0 ? double(done) / t : 0.0;
      const std::string eta =
          tps > 0 && done < total ? human_duration(double(total - done) / tps) : "--";
      std::fprintf(stderr,
                   "warm: %llu/%llu tiles (%.1f%%), %.0f tiles/s, %s, %llu cached, ETA %s\n",
                   (unsigned long long)done, (unsigned long long)total,
                   total ? 100.0 * double(done) / double(total) : 100.0, tps, rate.c_str(),
                   (unsigned long long)cached, eta.c_str());
    }
  };

  client::GetOptions go;
  go.pin = true;          // warmed tiles are never evicted by browsing
  go.revalidate = false;  // a cached tile is what we came for; no extra request
  std::uint64_t next_seq = 1;
  std::uint64_t flushed_bytes = 0, flushed_tiles = 0;
  std::optional<Error> stop_error;  // a disk error that makes going on pointless
  bool too_many_errors = false;
  auto issue = [&](TileId id) {
    const std::uint64_t seq = next_seq++;
    {
      std::lock_guard lock(st.mutex);
      st.live.emplace(seq, 0);
      ++st.outstanding;
    }
    const auto h = cache->get(id, go, [&st, seq, id](client::PayloadResult&& r) {
      std::lock_guard lock(st.mutex);
      st.live.erase(seq);
      --st.outstanding;
      switch (r.kind) {
        case client::PayloadResult::Kind::ok:
          if (r.from == client::PayloadResult::From::network) {
            ++st.network;
            st.bytes_network += r.tile->payload.size();
          } else {
            ++st.cached;
            st.bytes_cached += r.tile->payload.size();
          }
          break;
        case client::PayloadResult::Kind::absent:
          ++st.absent;
          break;
        case client::PayloadResult::Kind::error:
          ++st.failed;
          if (st.first_errors.size() < kErrorsKept)
            st.first_errors.push_back("tile " + id.to_string() + ": " +
                                      (r.error ? r.error->message : std::string("failed")));
          break;
        case client::PayloadResult::Kind::cancelled:
          ++st.cancelled;
          break;
      }
      st.cv.notify_all();
    });
    if (h) {
      std::lock_guard lock(st.mutex);
      if (auto it = st.live.find(seq); it != st.live.end()) it->second = h;
    }
  };
  auto cancel_live = [&] {
    std::vector<client::TileCache::Handle> handles;
    {
      std::lock_guard lock(st.mutex);
      for (const auto& [seq, h] : st.live)
        if (h) handles.push_back(h);
    }
    for (auto h : handles) cache->cancel(h);
  };

  // Issue gets, at most `concurrency` outstanding, until the walk ends or something stops it.
  for (;;) {
    if (stop_requested.load()) break;
    if (auto e = cache->last_disk_error()) {
      stop_error = e;
      break;
    }
    bool room;
    {
      std::unique_lock lock(st.mutex);
      st.cv.wait_for(lock, std::chrono::milliseconds(100),
                     [&] { return st.outstanding < a.concurrency; });
      room = st.outstanding < a.concurrency;
      too_many_errors = a.max_errors > 0 && st.failed >= a.max_errors;
    }
    if (too_many_errors) break;
    report_progress();
    if (!room) continue;
    TileId id;
    if (!walk.next(id)) break;
    issue(id);
    std::uint64_t bytes, tiles;
    {
      std::lock_guard lock(st.mutex);
      bytes = st.bytes_network;
      tiles = st.network;
    }
    if (bytes - flushed_bytes >= kFlushEveryBytes || tiles - flushed_tiles >= kFlushEveryTiles) {
      flushed_bytes = bytes;
      flushed_tiles = tiles;
      (void)cache->flush();  // errors surface through last_disk_error()
    }
  }
  const bool stopped = stop_requested.load() || stop_error || too_many_errors;
  if (stopped) cancel_live();
  // Drain: wait for the gets still outstanding (a Ctrl-C meanwhile cancels them).
  for (bool cancelled = stopped;;) {
    {
      std::unique_lock lock(st.mutex);
      if (st.cv.wait_for(lock, std::chrono::milliseconds(100), [&] { return st.outstanding == 0; }))
        break;
    }
    if (!cancelled && stop_requested.load()) {
      cancelled = true;
      cancel_live();
    }
    report_progress();
  }
  bar.finish();
  const Status flushed = cache->flush();
  const double elapsed = seconds();
  if (!stop_error) stop_error = cache->last_disk_error();
  if (!stop_error && !flushed.ok()) stop_error = flushed.error();
  const client::DiskCacheStats ds = cache->disk()->stats();
  cache.reset();  // joins the cache's threads; no callback runs after this

  const bool interrupted = stop_requested.load();
  const std::uint64_t done = st.done();
  const bool complete = !interrupted && !stop_error && st.failed == 0 && done == total;
  const double tps = elapsed > 0 ? double(done) / elapsed : 0.0;
  const double bps = elapsed > 0 ? double(st.bytes_network) / elapsed : 0.0;

  if (a.json) {
    nlohmann::json j;
    j["source"] = info.key;
    j["cache_dir"] = a.cache_dir;
    j["levels"] = {first, last};
    j["region"] = region ? nlohmann::json{region->x0, region->y0, region->x1, region->y1}
                         : nlohmann::json(nullptr);
    j["tiles_total"] = total;
    j["from_network"] = st.network;
    j["already_cached"] = st.cached;
    j["absent"] = st.absent;
    j["failed"] = st.failed;
    j["not_done"] = total - done;
    j["bytes_fetched"] = st.bytes_network;
    j["bytes_cached"] = st.bytes_cached;
    j["seconds"] = elapsed;
    j["tiles_per_second"] = tps;
    j["bytes_per_second"] = bps;
    j["complete"] = complete;
    j["interrupted"] = interrupted;
    j["errors"] = st.first_errors;
    j["disk_error"] = stop_error ? nlohmann::json(stop_error->message) : nlohmann::json(nullptr);
    j["cache"] = {{"tiles", ds.tiles},
                  {"bytes", ds.bytes},
                  {"pinned_tiles", ds.pinned_tiles},
                  {"pinned_bytes", ds.pinned_bytes},
                  {"max_bytes", ds.max_bytes}};
    std::printf("%s\n", j.dump(2).c_str());
  } else if (!a.quiet) {
    std::printf("warmed %s into %s: %llu/%llu tiles of levels %s in %s (%.0f tiles/s, %s/s)\n",
                info.key.c_str(), a.cache_dir.c_str(), (unsigned long long)done,
                (unsigned long long)total, levels_text(first, last).c_str(),
                human_duration(elapsed).c_str(), tps, human_bytes(std::uint64_t(bps)).c_str());
    std::printf("  from network    %llu (%s)\n", (unsigned long long)st.network,
                human_bytes(st.bytes_network).c_str());
    std::printf("  already cached  %llu (%s)\n", (unsigned long long)st.cached,
                human_bytes(st.bytes_cached).c_str());
    std::printf("  absent          %llu\n", (unsigned long long)st.absent);
    std::printf("  failed          %llu\n", (unsigned long long)st.failed);
    if (done < total)
      std::printf("  not done        %llu (run again to resume)\n",
                  (unsigned long long)(total - done));
    std::printf("cache: %llu tiles, %s (%llu pinned, %s) of %s\n", (unsigned long long)ds.tiles,
                human_bytes(ds.bytes).c_str(), (unsigned long long)ds.pinned_tiles,
                human_bytes(ds.pinned_bytes).c_str(), human_bytes(ds.max_bytes).c_str());
  }
  std::fflush(stdout);

  for (const auto& e : st.first_errors) std::fprintf(stderr, "vts: warm: %s\n", e.c_str());
  if (stop_error) return report_error(*stop_error);
  if (interrupted)
    return report_error(make_error(ErrorCode::cancelled, "interrupted: " + std::to_string(done) +
                                                             " of " + std::to_string(total) +
                                                             " tiles done; run again to resume"));
  if (st.failed > 0)
    return report_error(make_error(
        ErrorCode::io,
        std::to_string(st.failed) + " of " + std::to_string(total) + " tiles failed" +
            (too_many_errors ? " (stopped after --max-errors " + std::to_string(a.max_errors) + ")"
                             : std::string()) +
            "; run again to retry them"));
  if (!complete)
    return report_error(make_error(
        ErrorCode::internal,
        std::to_string(total - done) + " of " + std::to_string(total) + " tiles were not warmed"));
  return 0;
}

}  // namespace

Runner add_warm(CLI::App& app) {
  auto a = std::make_shared<WarmArgs>();
  CLI::App* c = app.add_subcommand(
      "warm", "Fill a disk cache with a tileset's tiles (pinned) for offline use; resumable");
  c->add_option("url", a->url,
                "Tileset: http://host:port/NAME (vts serve), a TileJSON URL, a remote .pmtiles "
                "URL or a local archive")
      ->required();
  c->add_option("--cache-dir", a->cache_dir, "Cache folder (created if missing)")->required();
  c->add_option("--levels", a->levels, "Levels A-B (or one level A); default all");
  c->add_option("--region", a->region,
                "Only tiles over x0,y0,x1,y1 (finest-level texels, half-open) at every level");
  c->add_option("--concurrency", a->concurrency, "Tile requests in flight")
      ->check(CLI::Range(1u, 1024u))
      ->capture_default_str();
  c->add_option("--cache-size", a->cache_size,
                "Cap on the cache's payload bytes, pinned included (suffix K/M/G/T: binary)")
      ->capture_default_str();
  c->add_option("--max-errors", a->max_errors, "Stop after this many failed tiles (0: never)")
      ->capture_default_str();
  c->add_flag("--json", a->json, "Print the summary as JSON on stdout");
  c->add_flag("-q,--quiet", a->quiet, "No progress or summary");
  return [a] { return run_warm(*a); };
}

}  // namespace vts::cli
