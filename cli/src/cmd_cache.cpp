// vts cache serve: the cache daemon. Serves one upstream tileset (a `vts serve` tileset, TileJSON,
// a remote .pmtiles or a local archive) through a client::TileCache (RAM + disk), with the same
// HTTP protocol as `vts serve` (docs/PROTOCOL.md §11): the server's HTTP layer (vts::HttpServer)
// asks an AsyncTileProvider for tiles, and this file's provider answers from the cache.
//
// Glue only: the server library knows nothing of the client library; both meet here.
//
// Offline: whenever the upstream opens, its SourceInfo is saved in the cache folder
// (sources/<hash of the upstream location>.json, written atomically). When it does not open at
// start, the daemon serves from that saved SourceInfo with an offline source (what the cache
// holds: 200; the rest: 503) and keeps trying to reopen the upstream in the background; once it
// opens with the same tileset (same key, geometry and codec), tiles are fetched again.
#include <sys/resource.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>
#include <unordered_map>

#include "commands.hpp"
#include "vts/client/saved_source.hpp"
#include "vts/client/source.hpp"
#include "vts/client/tile_cache.hpp"
#include "vts/server/http_server.hpp"

namespace vts::cli {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

struct CacheServeArgs {
  std::string upstream, cache_dir, listen = "127.0.0.1:8081", admin = "127.0.0.1:9091", name;
  std::string access_log;
  std::uint64_t cache_size = 1ull << 30;
  std::uint64_t ram_size = 256ull << 20;
  int threads = 0;
  int reconnect_seconds = 30;
  bool no_admin = false;
};

// ---- small helpers ---------------------------------------------------------------------------

// A tileset name as URLs carry it (docs/PROTOCOL.md §1).
bool valid_name(std::string_view n) {
  if (n.empty() || n.size() > 128 || n.front() == '.') return false;
  for (char c : n) {
    const bool ok = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
                    c == '.' || c == '_' || c == '-';
    if (!ok) return false;
  }
  return true;
}

// The last path segment of the upstream, without ".json" / ".pmtiles" (other dots belong to
// the name): http://host:8080/earth → earth, /data/earth.pmtiles → earth.
std::string default_name(std::string_view location) {
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

bool same_shape(const TilesetInfo& a, const TilesetInfo& b) {
  const Geometry &ga = a.geometry, &gb = b.geometry;
  return ga.width() == gb.width() && ga.height() == gb.height() &&
         ga.tile_size() == gb.tile_size() && ga.border() == gb.border() && a.codec == b.codec;
}

// ---- the upstream, online or not -------------------------------------------------------------

// One TileSource whatever the upstream's state. Online: fetches go to the opened source. Offline
// (it could not be opened at start): fetches go to client::offline_source(info), which fails
// each at once (so the cache serves what it holds and the daemon answers 503 for the rest),
// while a background thread tries to open the upstream again every `retry`; it goes online once
// the upstream opens with the same tileset (key, geometry, codec). info() never changes: it is
// what the cache is keyed by.
class Upstream final : public client::TileSource {
 public:
  using OnOnline = std::function<void(const client::SourceInfo&)>;

  Upstream(client::SourceInfo info, std::unique_ptr<client::TileSource> online,
           std::string location, client::SourceOptions options, std::chrono::seconds retry,
           OnOnline on_online)
      : info_(std::move(info)),
        online_(online != nullptr),
        current_(online ? std::shared_ptr<client::TileSource>(std::move(online))
                        : client::offline_source(info_)),
        location_(std::move(location)),
        options_(std::move(options)),
        retry_(retry),
        on_online_(std::move(on_online)) {
    if (!online_) reconnect_ = std::thread([this] { reconnect_loop(); });
  }
  ~Upstream() override {
    {
      std::lock_guard lock(mutex_);
      quit_ = true;
    }
    cv_.notify_all();
    if (reconnect_.joinable()) reconnect_.join();
  }

  bool online() const {
    std::lock_guard lock(mutex_);
    return online_;
  }
  const client::SourceInfo& info() const override { return info_; }
  // Offline, nothing costs network (and the cache does not revalidate).
  bool local() const override { return current()->local(); }

  // The offline source answers inside fetch(): the entry is then gone before the handle is set.
  Handle fetch(const client::SourceRequest& request, client::SourceCallback callback) override {
    auto source = current();
    Handle h = 0;
    {
      std::lock_guard lock(mutex_);
      h = ++next_handle_;
      inner_.emplace(h, Inner{source, 0});
    }
    const Handle ih =
        source->fetch(request, [this, h, cb = std::move(callback)](client::SourceTile&& t) {
          {
            std::lock_guard lock(mutex_);
            inner_.erase(h);
          }
          cb(std::move(t));
        });
    std::lock_guard lock(mutex_);
    if (auto it = inner_.find(h); it != inner_.end()) it->second.handle = ih;
    return h;
  }

  // Effective once fetch() has returned (as TileCache uses it).
  void cancel(Handle h) override {
    std::shared_ptr<client::TileSource> source;
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

 private:
  struct Inner {
    std::shared_ptr<client::TileSource> source;
    Handle handle;
  };

  std::shared_ptr<client::TileSource> current() const {
    std::lock_guard lock(mutex_);
    return current_;
  }

  void reconnect_loop() {
    std::unique_lock lock(mutex_);
    while (!quit_) {
      cv_.wait_for(lock, retry_, [this] { return quit_; });
      if (quit_) return;
      lock.unlock();
      auto opened = client::open_source(location_, options_);
      std::shared_ptr<client::TileSource> source;
      if (opened) {
        const client::SourceInfo& got = (*opened)->info();
        if (got.key == info_.key && same_shape(got.info, info_.info)) {
          source = std::move(*opened);
          if (on_online_) on_online_(source->info());
          std::fprintf(stderr, "vts cache serve: upstream %s is back; fetching again\n",
                       location_.c_str());
        } else {
          std::fprintf(stderr,
                       "vts cache serve: warning: upstream %s now serves another tileset (other "
                       "key, geometry or codec); staying offline: restart the daemon to follow "
                       "it\n",
                       location_.c_str());
        }
      }
      lock.lock();
      if (source) {
        current_ = std::move(source);
        online_ = true;
        return;
      }
    }
  }

  const client::SourceInfo info_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  bool online_;
  std::shared_ptr<client::TileSource> current_;  // the opened upstream, or an offline source
  std::unordered_map<Handle, Inner> inner_;      // fetches in flight, by our handle
  Handle next_handle_ = 0;
  bool quit_ = false;
  const std::string location_;
  const client::SourceOptions options_;
  const std::chrono::seconds retry_;
  const OnOnline on_online_;
  std::thread reconnect_;
};

// ---- the provider: tiles from the cache --------------------------------------------------------

class CacheProvider final : public AsyncTileProvider {
 public:
  CacheProvider(std::shared_ptr<const ProvidedTileset> tileset,
                std::unique_ptr<client::TileCache> cache, std::shared_ptr<Upstream> upstream)
      : tileset_(std::move(tileset)), cache_(std::move(cache)), upstream_(std::move(upstream)) {}

  std::shared_ptr<const ProvidedTileset> find(std::string_view name) const override {
    return name == tileset_->name ? tileset_ : nullptr;
  }
  std::vector<std::shared_ptr<const ProvidedTileset>> all() const override { return {tileset_}; }

  // Called by the server's I/O threads only while it runs (shutdown() comes after run()).
  void tile(const std::shared_ptr<const ProvidedTileset>&, TileId id,
            std::function<void(ProvidedTile)> done) override {
    cache_->get(id, client::GetOptions{},
                [done = std::move(done)](client::PayloadResult&& r) mutable {
                  done(to_provided(std::move(r)));
                });
  }

  std::string metrics_text() const override {
    if (!cache_) return {};
    const client::TileCache::Stats s = cache_->stats();
    std::string out;
    auto counter = [&out](const char* name, const char* help, std::uint64_t v,
                          const char* labels = "") {
      out += std::string("# HELP ") + name + " " + help + "\n# TYPE " + name + " counter\n" + name +
             labels + " " + std::to_string(v) + "\n";
    };
    counter("vts_cache_gets_total", "Tile gets asked of the cache.", s.gets);
    out +=
        "# HELP vts_cache_hits_total Gets answered from the cache, by level.\n"
        "# TYPE vts_cache_hits_total counter\n"
        "vts_cache_hits_total{level=\"ram\"} " +
        std::to_string(s.ram_hits) + "\nvts_cache_hits_total{level=\"disk\"} " +
        std::to_string(s.disk_hits) + "\n";
    counter("vts_cache_upstream_fetches_total", "Tiles fetched from the upstream.",
            s.network_fetches);
    counter("vts_cache_absent_total", "Gets of tiles the upstream does not have.", s.absent);
    counter("vts_cache_errors_total", "Gets that failed (upstream unavailable or unusable).",
            s.errors);
    counter("vts_cache_corrupt_rejected_total", "Upstream payloads that failed verification.",
            s.corrupt_rejected);
    counter("vts_cache_revalidations_total", "Stale tiles revalidated with the upstream.",
            s.revalidations);
    counter("vts_cache_disk_write_errors_total", "Failed disk cache writes (e.g. disk full).",
            s.disk_write_errors);
    out +=
        "# HELP vts_cache_upstream_online Whether the upstream is open (1) or not (0).\n"
        "# TYPE vts_cache_upstream_online gauge\nvts_cache_upstream_online " +
        std::string(upstream_->online() ? "1" : "0") + "\n";
    return out;
  }

  // After the server's run(): finishes pending gets (their `done`s post to stopped contexts),
  // writes what the disk cache has batched, and releases the cache.
  void shutdown() {
    if (!cache_) return;
    if (auto st = cache_->flush(); !st.ok())
      std::fprintf(stderr, "vts cache serve: warning: flushing the cache: %s\n",
                   st.error().to_string().c_str());
    cache_.reset();
  }

 private:
  static ProvidedTile to_provided(client::PayloadResult&& r) {
    ProvidedTile t;
    switch (r.kind) {
      case client::PayloadResult::Kind::ok:
        t.kind = ProvidedTile::Kind::ok;
        t.payload = r.tile->payload;
        t.keep = std::move(r.tile);  // the response sends the cached bytes, no copy
        break;
      case client::PayloadResult::Kind::absent:
        t.kind = ProvidedTile::Kind::absent;
        break;
      case client::PayloadResult::Kind::error: {
        const ErrorCode c = r.error ? r.error->code : ErrorCode::io;
        // Bytes that came but fail verification: the upstream is broken (502). Anything else
        // (unreachable, timeouts, 5xx after retries, offline): unavailable for now (503).
        const bool broken = c == ErrorCode::checksum || c == ErrorCode::corrupt ||
                            c == ErrorCode::truncated || c == ErrorCode::too_large;
        t.kind = broken ? ProvidedTile::Kind::bad_origin : ProvidedTile::Kind::unavailable;
        if (r.error) t.message = r.error->message;
        break;
      }
      case client::PayloadResult::Kind::cancelled:
        t.kind = ProvidedTile::Kind::unavailable;
        t.message = "the cache daemon is shutting down";
        break;
    }
    return t;
  }

  std::shared_ptr<const ProvidedTileset> tileset_;
  std::unique_ptr<client::TileCache> cache_;
  std::shared_ptr<Upstream> upstream_;
};

void raise_fd_limit() {
  rlimit rl{};
  if (getrlimit(RLIMIT_NOFILE, &rl) == 0 && rl.rlim_cur < rl.rlim_max) {
    rl.rlim_cur = rl.rlim_max;
    setrlimit(RLIMIT_NOFILE, &rl);
  }
}

int run_cache_serve(const CacheServeArgs& a) {
  HttpServerOptions o;
  auto ep = parse_endpoint(a.listen);
  if (!ep) return report_error(ep.error());
  o.listen_host = ep->first;
  o.listen_port = ep->second;
  if (a.no_admin) {
    o.admin_enabled = false;
  } else {
    auto aep = parse_endpoint(a.admin);
    if (!aep) return report_error(aep.error());
    o.admin_host = aep->first;
    o.admin_port = aep->second;
  }
  o.threads = a.threads;
  o.access_log = a.access_log;
  o.reload_interval = std::chrono::milliseconds(0);  // no archives to reload

  const std::string name = a.name.empty() ? default_name(a.upstream) : a.name;
  if (!valid_name(name))
    return report_error(make_error(
        ErrorCode::invalid_argument,
        (a.name.empty() ? "cannot name the tileset after upstream '" + a.upstream + "' ('" + name +
                              "'); give --name"
                        : "--name '" + name + "'") +
            ": a name is [A-Za-z0-9._-]+, not starting with '.', at most 128 characters"));
  if (a.cache_dir.empty())
    return report_error(make_error(ErrorCode::invalid_argument, "--cache-dir is empty"));
  const fs::path cache_dir = a.cache_dir;

  // The daemon's own clients wait for it: fail an unreachable upstream sooner than a viewer
  // would.
  client::SourceOptions so;
  so.fetcher.max_attempts = 3;
  so.fetcher.connect_timeout = std::chrono::milliseconds(3000);
  so.fetcher.request_timeout = std::chrono::milliseconds(15000);

  client::SourceInfo info;
  std::unique_ptr<client::TileSource> online;
  if (auto opened = client::open_source(a.upstream, so)) {
    online = std::move(*opened);
    info = online->info();
    if (auto saved = client::load_source_info(cache_dir, a.upstream);
        saved && (saved->key != info.key || !same_shape(saved->info, info.info)))
      std::fprintf(stderr,
                   "vts cache serve: warning: %s changed geometry or codec since the cache was "
                   "filled; cached tiles of the old tileset may be served until revalidated\n",
                   a.upstream.c_str());
    if (auto st = client::save_source_info(cache_dir, a.upstream, info); !st.ok())
      std::fprintf(stderr, "vts cache serve: warning: %s (offline starts will not work)\n",
                   st.error().to_string().c_str());
  } else {
    auto saved = client::load_source_info(cache_dir, a.upstream);
    if (!saved) {
      Error e = opened.error();
      e.message += "; and it cannot be served offline: " + saved.error().message;
      return report_error(e);
    }
    info = std::move(*saved);
    std::fprintf(stderr,
                 "vts cache serve: warning: upstream %s is unavailable (%s); serving what the "
                 "cache holds, retrying every %d s\n",
                 a.upstream.c_str(), opened.error().message.c_str(), a.reconnect_seconds);
  }
  const bool started_online = online != nullptr;

  auto tileset = std::make_shared<ProvidedTileset>();
  tileset->name = name;
  tileset->info = info.info;
  tileset->version = info.version;

  const std::string location = a.upstream;
  auto upstream = std::make_shared<Upstream>(
      info, std::move(online), a.upstream, so, std::chrono::seconds(a.reconnect_seconds),
      [cache_dir, location](const client::SourceInfo& now) {
        if (auto st = client::save_source_info(cache_dir, location, now); !st.ok())
          std::fprintf(stderr, "vts cache serve: warning: %s\n", st.error().to_string().c_str());
      });

  client::TileCacheOptions co;
  co.ram_bytes = a.ram_size;
  co.disk = client::DiskCacheOptions{};
  co.disk->dir = cache_dir;
  co.disk->max_bytes = a.cache_size;
  auto cache = client::TileCache::create(upstream, co);
  if (!cache) return report_error(cache.error());
  auto provider = std::make_shared<CacheProvider>(tileset, std::move(*cache), upstream);
  o.provider = provider;

  raise_fd_limit();
  const std::string host = o.listen_host, admin_host = o.admin_host;
  auto server = HttpServer::create(std::move(o), std::make_shared<TilesetRegistry>());
  if (!server) {
    provider->shutdown();
    return report_error(server.error());
  }
  HttpServer& s = **server;
  s.set_ready(true);
  const std::string state = started_online ? "" : " (upstream offline: serving the cache)";
  if (s.admin_port())
    std::printf(
        "vts cache serve: listening on http://%s:%u (admin http://%s:%u), tileset %s from %s%s\n",
        host.c_str(), unsigned(s.port()), admin_host.c_str(), unsigned(s.admin_port()),
        name.c_str(), a.upstream.c_str(), state.c_str());
  else
    std::printf("vts cache serve: listening on http://%s:%u, tileset %s from %s%s\n", host.c_str(),
                unsigned(s.port()), name.c_str(), a.upstream.c_str(), state.c_str());
  std::fflush(stdout);
  s.run();
  // The provider's pending work must end before the server goes (http_server.hpp).
  provider->shutdown();
  server->reset();
  std::fprintf(stderr, "vts cache serve: stopped\n");
  return 0;
}

}  // namespace

Runner add_cache(CLI::App& app) {
  auto a = std::make_shared<CacheServeArgs>();
  CLI::App* cache = app.add_subcommand("cache", "The tile cache daemon");
  cache->require_subcommand(1);
  CLI::App* c = cache->add_subcommand(
      "serve", "Serve an upstream tileset through a RAM + disk cache, with vts serve's protocol");
  c->add_option("--upstream", a->upstream,
                "Tileset: http://host:port/NAME (vts serve), a TileJSON URL, a remote .pmtiles "
                "URL or a local archive")
      ->required();
  c->add_option("--cache-dir", a->cache_dir, "Cache folder (created if missing)")->required();
  c->add_option("--listen", a->listen, "HOST:PORT to serve tiles on")->capture_default_str();
  c->add_option("--admin", a->admin, "HOST:PORT for /metrics and /health")->capture_default_str();
  c->add_flag("--no-admin", a->no_admin, "Do not open the admin listener");
  c->add_option("--cache-size", a->cache_size,
                "Cap on the disk cache's payload bytes (suffix K/M/G/T: binary)")
      ->transform(CLI::AsSizeValue(false))
      ->capture_default_str();
  c->add_option("--ram-size", a->ram_size, "RAM cache budget in bytes (suffix K/M/G; 0: none)")
      ->transform(CLI::AsSizeValue(false))
      ->capture_default_str();
  c->add_option("--name", a->name,
                "Tileset name in URLs (default: the upstream's last path segment without "
                ".json/.pmtiles)");
  c->add_option("--threads", a->threads, "I/O threads (default: one per core)")
      ->check(CLI::Range(0, 256));
  c->add_option("--access-log", a->access_log, "JSON-lines access log: FILE, or - for stdout");
  c->add_option("--reconnect-interval", a->reconnect_seconds,
                "Seconds between attempts to reopen an upstream that was down at start")
      ->check(CLI::Range(1, 86400))
      ->capture_default_str();
  return [a, cache, c] {
    if (c->parsed()) return run_cache_serve(*a);
    std::fputs(cache->help().c_str(), stderr);
    return 2;
  };
}

}  // namespace vts::cli
