// vts cache serve: the cache daemon. Serves one upstream tileset through a client::CacheProvider
// (RAM + disk cache over a ReconnectingSource) behind the server's HTTP layer (vts::HttpServer),
// with the same protocol as `vts serve`. This file parses, wires the two and prints.
//
// Offline: whenever the upstream opens, its SourceInfo is saved in the cache folder. When it does
// not open at start, the daemon serves what the cache holds (the rest: 503) from that saved
// SourceInfo and keeps trying to reopen the upstream in the background.
#include <chrono>
#include <cstdio>
#include <string>

#include "commands.hpp"
#include "progress.hpp"
#include "vts/client/cache_provider.hpp"
#include "vts/client/saved_source.hpp"
#include "vts/client/source.hpp"
#include "vts/protocol/tileset.hpp"
#include "vts/server/http_server.hpp"

namespace vts::cli {

namespace {

struct CacheServeArgs {
  std::string upstream, cache_dir, listen = "127.0.0.1:8081", admin = "127.0.0.1:9091", name;
  std::string access_log, cache_size = "1G", ram_size = "256M";
  int threads = 0, reconnect_seconds = 30, deadline_seconds = 20, region_cap = 8;
  int revalidate_seconds = 3600;
  bool no_admin = false;
};

Result<HttpServerOptions> server_options(const CacheServeArgs& a) {
  HttpServerOptions o;
  auto ep = parse_endpoint(a.listen);
  if (!ep) return ep.error();
  o.listen_host = ep->first;
  o.listen_port = ep->second;
  if (a.no_admin) {
    o.admin_enabled = false;
  } else {
    auto aep = parse_endpoint(a.admin);
    if (!aep) return aep.error();
    o.admin_host = aep->first;
    o.admin_port = aep->second;
  }
  o.threads = a.threads;
  o.access_log = a.access_log;
  o.reload_interval = std::chrono::milliseconds(0);  // no archives to reload
  return o;
}

Result<std::string> tileset_name(const CacheServeArgs& a) {
  const std::string name = a.name.empty() ? client::default_tileset_name(a.upstream) : a.name;
  if (!tileset_name_problem(name).empty())
    return make_error(
        ErrorCode::invalid_argument,
        (a.name.empty() ? "cannot name the tileset after upstream '" + a.upstream + "' ('" + name +
                              "'); give --name"
                        : "--name '" + name + "'") +
            ": a name is [A-Za-z0-9._-]+, not starting with '.', at most 128 characters");
  if (a.cache_dir.empty()) return make_error(ErrorCode::invalid_argument, "--cache-dir is empty");
  return name;
}

void warn(const std::string& message) {
  std::fprintf(stderr, "vts cache serve: warning: %s\n", message.c_str());
}

// Opens the upstream, or falls back on what the cache folder remembers of it (`online` stays
// null); saves its description whenever it opens, for offline starts.
Result<client::SourceInfo> open_upstream(const CacheServeArgs& a, const client::SourceOptions& so,
                                         std::unique_ptr<client::TileSource>& online) {
  auto opened = client::open_source(a.upstream, so);
  if (!opened) {
    auto saved = client::load_source_info(a.cache_dir, a.upstream);
    if (!saved) {
      Error e = opened.error();
      e.message += "; and it cannot be served offline: " + saved.error().message;
      return e;
    }
    warn("upstream " + a.upstream + " is unavailable (" + opened.error().message +
         "); serving what the cache holds, retrying every " + std::to_string(a.reconnect_seconds) +
         " s");
    return std::move(*saved);
  }
  online = std::move(*opened);
  client::SourceInfo info = online->info();
  if (auto saved = client::load_source_info(a.cache_dir, a.upstream);
      saved && !client::same_tileset(*saved, info))
    warn(a.upstream +
         " changed geometry or codec since the cache was filled; cached tiles of the old tileset "
         "may be served until revalidated");
  if (auto st = client::save_source_info(a.cache_dir, a.upstream, info); !st.ok())
    warn(st.error().to_string() + " (offline starts will not work)");
  return info;
}

Result<std::shared_ptr<client::CacheProvider>> make_provider(const CacheServeArgs& a,
                                                             const std::string& name,
                                                             bool& started_online) {
  // The daemon's own clients wait for it: fail an unreachable upstream sooner than a viewer
  // would.
  client::SourceOptions so;
  so.fetcher.max_attempts = 3;
  so.vtstream_only = true;  // the daemon serves our tiles (ETags from their headers)
  so.fetcher.connect_timeout = std::chrono::milliseconds(3000);
  so.fetcher.request_timeout = std::chrono::milliseconds(15000);
  so.fetcher.deadline = std::chrono::seconds(a.deadline_seconds);
  so.fetcher.max_in_flight_per_group = std::size_t(a.region_cap);
  std::unique_ptr<client::TileSource> online;
  auto info = open_upstream(a, so, online);
  if (!info) return info.error();
  started_online = online != nullptr;

  auto tileset = std::make_shared<ProvidedTileset>();
  tileset->name = name;
  tileset->info = info->info;
  tileset->version = info->version;
  client::ReconnectingSource::Hooks hooks;
  hooks.back_online = [dir = a.cache_dir, location = a.upstream](const client::SourceInfo& now) {
    if (auto st = client::save_source_info(dir, location, now); !st.ok())
      warn(st.error().to_string());
    std::fprintf(stderr, "vts cache serve: upstream %s is back; fetching again\n",
                 location.c_str());
  };
  hooks.changed = [location = a.upstream](const client::SourceInfo&) {
    warn("upstream " + location +
         " now serves another tileset (other key, geometry or codec); staying offline: restart "
         "the daemon to follow it");
  };
  auto upstream = std::make_shared<client::ReconnectingSource>(
      *info, std::move(online), a.upstream, so, std::chrono::seconds(a.reconnect_seconds),
      std::move(hooks));

  client::TileCacheOptions co;
  co.ram_bytes = 0;
  if (a.ram_size != "0") {
    auto ram = parse_byte_size(a.ram_size, "--ram-size");
    if (!ram) return ram.error();
    co.ram_bytes = *ram;
  }
  co.disk_report = [](const std::string& line) { warn(line); };
  co.revalidate_after = std::chrono::seconds(a.revalidate_seconds);
  auto disk = parse_byte_size(a.cache_size, "--cache-size");
  if (!disk) return disk.error();
  co.disk = client::DiskCacheOptions{};
  co.disk->dir = a.cache_dir;
  co.disk->max_bytes = *disk;
  auto cache = client::TileCache::create(upstream, co);
  if (!cache) return cache.error();
  return std::make_shared<client::CacheProvider>(tileset, std::move(*cache), upstream);
}

void shutdown(client::CacheProvider& provider) {
  if (auto st = provider.shutdown(); !st.ok())
    warn("flushing the cache: " + st.error().to_string());
}

void print_listening(const CacheServeArgs& a, const HttpServer& s, const std::string& host,
                     const std::string& admin_host, const std::string& name, bool online) {
  const std::string admin =
      s.admin_port() ? " (admin http://" + admin_host + ":" + std::to_string(s.admin_port()) + ")"
                     : "";
  std::printf("vts cache serve: listening on http://%s:%u%s, tileset %s from %s%s\n", host.c_str(),
              unsigned(s.port()), admin.c_str(), name.c_str(), a.upstream.c_str(),
              online ? "" : " (upstream offline: serving the cache)");
  std::fflush(stdout);
}

int run_cache_serve(const CacheServeArgs& a) {
  auto o = server_options(a);
  if (!o) return report_error(o.error());
  auto name = tileset_name(a);
  if (!name) return report_error(name.error());
  bool online = false;
  auto provider = make_provider(a, *name, online);
  if (!provider) return report_error(provider.error());
  o->provider = *provider;

  raise_fd_limit_for_connections();
  const std::string host = o->listen_host, admin_host = o->admin_host;
  auto server = HttpServer::create(std::move(*o), std::make_shared<TilesetRegistry>());
  if (!server) {
    shutdown(**provider);
    return report_error(server.error());
  }
  HttpServer& s = **server;
  s.set_ready(true);
  print_listening(a, s, host, admin_host, *name, online);
  const Status ran = s.run();
  // The provider's pending work must end before the server goes (http_server.hpp).
  shutdown(**provider);
  server->reset();
  if (!ran.ok()) return report_error(ran.error());
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
      ->capture_default_str();
  c->add_option("--ram-size", a->ram_size, "RAM cache budget in bytes (suffix K/M/G; 0: none)")
      ->capture_default_str();
  c->add_option("--name", a->name,
                "Tileset name in URLs (default: the upstream's last path segment without "
                ".json/.pmtiles)");
  c->add_option("--threads", a->threads, "I/O threads (default: one per core)")
      ->check(CLI::Range(0, 256));
  c->add_option("--access-log", a->access_log, "JSON-lines access log: FILE, or - for stdout");
  c->add_option("--revalidate-after", a->revalidate_seconds,
                "Revalidate a tile after this many seconds when its Cache-Control gave no lifetime")
      ->check(CLI::Range(0, 31536000))
      ->capture_default_str();
  c->add_option("--reconnect-interval", a->reconnect_seconds,
                "Seconds between attempts to reopen an upstream that was down at start")
      ->check(CLI::Range(1, 86400))
      ->capture_default_str();
  c->add_option("--upstream-deadline", a->deadline_seconds,
                "Seconds one upstream fetch may take, retries included (then 503)")
      ->check(CLI::Range(1, 3600))
      ->capture_default_str();
  c->add_option("--upstream-region-cap", a->region_cap,
                "Upstream fetches of one 8x8-tile region of a level at once (0: no cap)")
      ->check(CLI::Range(0, 1024))
      ->capture_default_str();
  return [a, cache, c] {
    if (c->parsed()) return run_cache_serve(*a);
    std::fputs(cache->help().c_str(), stderr);
    return 2;
  };
}

}  // namespace vts::cli
