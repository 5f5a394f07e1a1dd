#include "vts/client/cache_provider.hpp"

#include <cstdio>
#include <optional>
#include <stop_token>
#include <system_error>

namespace vts::client {

bool same_tileset(const SourceInfo& a, const SourceInfo& b) {
  const Geometry &ga = a.info.geometry, &gb = b.info.geometry;
  return a.key == b.key && ga.width() == gb.width() && ga.height() == gb.height() &&
         ga.tile_size() == gb.tile_size() && ga.border() == gb.border() &&
         a.info.codec == b.info.codec;
}

std::string default_tileset_name(std::string_view location) {
  std::string_view s = location.substr(0, location.find_first_of("?#"));
  while (!s.empty() && s.back() == '/') s.remove_suffix(1);
  const std::size_t scheme = s.find("://");
  if (scheme != std::string_view::npos && s.find('/', scheme + 3) == std::string_view::npos)
    return {};  // a bare origin ("http://host:8080") names no tileset
  if (const std::size_t slash = s.find_last_of('/'); slash != std::string_view::npos)
    s = s.substr(slash + 1);
  for (std::string_view ext : {".json", ".pmtiles"})
    if (s.size() > ext.size() && s.ends_with(ext)) s.remove_suffix(ext.size());
  return std::string(s);
}

// ---- ReconnectingSource ------------------------------------------------------------------------

ReconnectingSource::ReconnectingSource(SourceInfo info, std::unique_ptr<TileSource> online,
                                       std::string location, SourceOptions options,
                                       std::chrono::milliseconds retry, Hooks hooks)
    : info_(std::move(info)),
      online_(online != nullptr),
      current_(online ? std::shared_ptr<TileSource>(std::move(online)) : offline_source(info_)),
      location_(std::move(location)),
      options_(std::move(options)),
      retry_(retry),
      hooks_(std::move(hooks)) {
  if (!online_) reconnect_ = std::thread([this] { reconnect_loop(); });
}

ReconnectingSource::~ReconnectingSource() {
  {
    std::lock_guard lock(mutex_);
    quit_ = true;
  }
  cv_.notify_all();
  if (reconnect_.joinable()) reconnect_.join();
}

bool ReconnectingSource::online() const {
  std::lock_guard lock(mutex_);
  return online_;
}

bool ReconnectingSource::local() const {
  return current()->local();
}

std::shared_ptr<TileSource> ReconnectingSource::current() const {
  std::lock_guard lock(mutex_);
  return current_;
}

// The offline source answers inside fetch(): the entry is then gone before the handle is set.
TileSource::Handle ReconnectingSource::fetch(const SourceRequest& request,
                                             SourceCallback callback) {
  auto source = current();
  Handle h = 0;
  {
    std::lock_guard lock(mutex_);
    h = ++next_handle_;
    inner_.emplace(h, Inner{source, 0});
  }
  const Handle ih =
      source->fetch(request, [this, h, source, cb = std::move(callback)](SourceTile&& t) {
        {
          std::lock_guard lock(mutex_);
          inner_.erase(h);
        }
        if (t.kind == SourceTile::Kind::error && t.error && t.error->code == ErrorCode::changed)
          go_offline(source);
        cb(std::move(t));
      });
  std::lock_guard lock(mutex_);
  if (auto it = inner_.find(h); it != inner_.end()) it->second.handle = ih;
  return h;
}

void ReconnectingSource::cancel(Handle h) {
  std::shared_ptr<TileSource> source;
  Handle ih = 0;
  {
    std::lock_guard lock(mutex_);
    auto it = inner_.find(h);
    if (it == inner_.end()) return;
    source = it->second.source;
    ih = it->second.handle;
  }
  if (ih) source->cancel(ih);
}

void ReconnectingSource::go_offline(const std::shared_ptr<TileSource>& failed) {
  std::thread ended;
  {
    std::lock_guard lock(mutex_);
    if (quit_ || !online_ || current_ != failed) return;  // already offline, or reopened
    current_ = offline_source(info_);
    online_ = false;
    ended = std::move(reconnect_);  // the loop that brought it online has returned (or never ran)
    try {
      reconnect_ = std::thread([this] { reconnect_loop(); });
    } catch (const std::system_error& e) {
      // No thread to retry with (a task limit): stay offline, serving what the cache holds,
      // rather than let the exception end the thread that saw the origin fail.
      std::fprintf(stderr,
                   "vts cache: cannot start the reconnect thread (%s); serving the cache "
                   "only until restarted\n",
                   e.what());
    }
  }
  if (ended.joinable()) ended.join();
}

void ReconnectingSource::reconnect_loop() {
  std::unique_lock lock(mutex_);
  while (!quit_) {
    cv_.wait_for(lock, retry_, [this] { return quit_; });
    if (quit_) return;
    lock.unlock();
    auto opened = open_source(location_, options_);
    std::shared_ptr<TileSource> source;
    if (opened) {
      if (same_tileset((*opened)->info(), info_))
        source = std::move(*opened);
      else if (hooks_.changed)
        hooks_.changed((*opened)->info());
    }
    lock.lock();
    if (source) {
      current_ = source;
      online_ = true;
      lock.unlock();
      if (hooks_.back_online) hooks_.back_online(source->info());
      return;
    }
  }
}

// ---- CacheProvider -----------------------------------------------------------------------------

namespace {

ProvidedTile to_provided(PayloadResult&& r) {
  ProvidedTile t;
  switch (r.kind) {
    case PayloadResult::Kind::ok:
      t.kind = ProvidedTile::Kind::ok;
      t.payload = r.tile->payload;
      t.keep = std::move(r.tile);  // the response sends the cached bytes, no copy
      break;
    case PayloadResult::Kind::absent:
      t.kind = ProvidedTile::Kind::absent;
      break;
    case PayloadResult::Kind::error: {
      const ErrorCode c = r.error ? r.error->code : ErrorCode::io;
      // Bytes that came but fail verification: the upstream is broken (502). Anything else
      // (unreachable, timeouts, 5xx after retries, offline): unavailable for now (503).
      const bool broken = c == ErrorCode::checksum || c == ErrorCode::corrupt ||
                          c == ErrorCode::truncated || c == ErrorCode::too_large;
      t.kind = broken ? ProvidedTile::Kind::bad_origin : ProvidedTile::Kind::unavailable;
      if (r.error) t.message = r.error->message;
      break;
    }
    case PayloadResult::Kind::cancelled:
      t.kind = ProvidedTile::Kind::unavailable;
      t.message = "the request was cancelled (its client went away, or the daemon is stopping)";
      break;
  }
  return t;
}

void counter(std::string& out, const char* name, const char* help, std::uint64_t v) {
  out += std::string("# HELP ") + name + " " + help + "\n# TYPE " + name + " counter\n" + name +
         " " + std::to_string(v) + "\n";
}

}  // namespace

CacheProvider::CacheProvider(std::shared_ptr<const ProvidedTileset> tileset,
                             std::unique_ptr<TileCache> cache,
                             std::shared_ptr<const ReconnectingSource> upstream)
    : tileset_(std::move(tileset)), cache_(std::move(cache)), upstream_(std::move(upstream)) {}

std::shared_ptr<const ProvidedTileset> CacheProvider::find(std::string_view name) const {
  return name == tileset_->name ? tileset_ : nullptr;
}

std::vector<std::shared_ptr<const ProvidedTileset>> CacheProvider::all() const {
  return {tileset_};
}

void CacheProvider::tile(const std::shared_ptr<const ProvidedTileset>&, TileId id,
                         std::function<void(ProvidedTile)> done, std::stop_token abandon) {
  // A client that goes away cancels its get; the cache cancels the upstream fetch when no other
  // get waits for the tile. The stop callback lives as long as the get's callback (or this call):
  // whichever lets go last unregisters it, with no lock held.
  struct Watch {
    std::optional<std::stop_callback<std::function<void()>>> on_abandon;
  };
  auto watch = std::make_shared<Watch>();
  const TileCache::Handle h =
      cache_->get(id, GetOptions{}, [done = std::move(done), watch](PayloadResult&& r) mutable {
        done(to_provided(std::move(r)));
      });
  if (h != 0 && abandon.stop_possible())
    watch->on_abandon.emplace(abandon, [cache = cache_.get(), h] { cache->cancel(h); });
}

std::string CacheProvider::metrics_text() const {
  if (!cache_) return {};
  const TileCache::Stats s = cache_->stats();
  std::string out;
  counter(out, "vts_cache_gets_total", "Tile gets asked of the cache.", s.gets);
  out +=
      "# HELP vts_cache_hits_total Gets answered from the cache, by level.\n"
      "# TYPE vts_cache_hits_total counter\n"
      "vts_cache_hits_total{level=\"ram\"} " +
      std::to_string(s.ram_hits) + "\nvts_cache_hits_total{level=\"disk\"} " +
      std::to_string(s.disk_hits) + "\n";
  counter(out, "vts_cache_upstream_fetches_total", "Tiles fetched from the upstream.",
          s.network_fetches);
  counter(out, "vts_cache_absent_total", "Gets of tiles the upstream does not have.", s.absent);
  counter(out, "vts_cache_errors_total", "Gets that failed (upstream unavailable or unusable).",
          s.errors);
  counter(out, "vts_cache_corrupt_rejected_total", "Upstream payloads that failed verification.",
          s.corrupt_rejected);
  counter(out, "vts_cache_cancelled_total",
          "Gets abandoned by their client before the tile came (the upstream fetch is cancelled "
          "once no get waits for it).",
          s.cancelled);
  counter(out, "vts_cache_revalidations_total", "Stale tiles revalidated with the upstream.",
          s.revalidations);
  counter(out, "vts_cache_disk_write_errors_total", "Failed disk cache writes (e.g. disk full).",
          s.disk_write_errors);
  counter(out, "vts_cache_tileset_mismatch_rejected_total",
          "Tiles refused because their header contradicts the tileset (size, codec, format).",
          s.mismatch_rejected);
  out +=
      "# HELP vts_cache_disk_writes_failing Whether disk cache writes are failing now (1) or not "
      "(0).\n# TYPE vts_cache_disk_writes_failing gauge\nvts_cache_disk_writes_failing " +
      std::string(cache_->disk_health().failing ? "1" : "0") + "\n";
  out +=
      "# HELP vts_cache_upstream_online Whether the upstream is open (1) or not (0).\n"
      "# TYPE vts_cache_upstream_online gauge\nvts_cache_upstream_online " +
      std::string(upstream_->online() ? "1" : "0") + "\n";
  return out;
}

std::string CacheProvider::health_problem() const {
  if (!cache_) return {};
  const DiskHealth h = cache_->disk_health();
  if (!h.failing) return {};
  return "disk cache writes failing since " + std::to_string(h.failing_since_unix) +
         " (unix time): " + std::to_string(h.failed_writes) + " failed writes; the last: " +
         (h.last_error ? h.last_error->to_string() : std::string("unknown"));
}

Status CacheProvider::shutdown() {
  if (!cache_) return {};
  Status st = cache_->flush();
  cache_.reset();
  return st;
}

}  // namespace vts::client
