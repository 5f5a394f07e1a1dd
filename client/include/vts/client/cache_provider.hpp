// The cache daemon's parts (`vts cache serve`): an upstream that may be offline and reconnects in
// the background, and the AsyncTileProvider that answers an HTTP front's tile requests from a
// TileCache over it.
#pragma once

#include <chrono>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <stop_token>
#include <string>
#include <string_view>
#include <thread>
#include <unordered_map>

#include "vts/client/source.hpp"
#include "vts/client/tile_cache.hpp"
#include "vts/protocol/tile_provider.hpp"

namespace vts::client {

// The name a tileset served from `location` gets by default: its last path segment without
// ".json" / ".pmtiles" (other dots belong to the name): http://host:8080/earth -> earth,
// /data/earth.pmtiles -> earth; empty for a bare origin (http://host:8080).
std::string default_tileset_name(std::string_view location);

// Same key, geometry (size, tile size, border) and codec: tiles cached from one serve the other.
bool same_tileset(const SourceInfo& a, const SourceInfo& b);

// One TileSource whatever the upstream's state. Online: fetches go to the opened source. Offline
// (`online` null at construction): fetches go to offline_source(info), which fails each at once
// (the cache serves what it holds), while a background thread tries open_source(location) every
// `retry`; it goes online once the upstream opens with the same tileset (same_tileset). An online
// upstream that answers ErrorCode::changed (a local archive modified in place) goes offline the
// same way, so the source follows the archive that replaced it once that one opens.
// info() never changes: it is what the cache is keyed by. Thread-safe.
class ReconnectingSource final : public TileSource {
 public:
  struct Hooks {
    // The upstream reopened with the same tileset and fetches now go to it; called once, on the
    // reconnect thread.
    std::function<void(const SourceInfo& now)> back_online;
    // The upstream reopened with another tileset; the source stays offline and keeps retrying
    // (so this is called at every attempt while that lasts). On the reconnect thread.
    std::function<void(const SourceInfo& now)> changed;
  };

  ReconnectingSource(SourceInfo info, std::unique_ptr<TileSource> online, std::string location,
                     SourceOptions options, std::chrono::milliseconds retry, Hooks hooks = {});
  ~ReconnectingSource() override;  // stops and joins the reconnect thread

  bool online() const;
  const SourceInfo& info() const override { return info_; }
  bool local() const override;  // the current source's (offline, nothing costs network)
  Handle fetch(const SourceRequest& request, SourceCallback callback) override;
  void cancel(Handle h) override;  // effective once fetch() has returned

 private:
  struct Inner {
    std::shared_ptr<TileSource> source;
    Handle handle;
  };
  std::shared_ptr<TileSource> current() const;
  // Offline (and reconnecting) unless `failed` is no longer the current source.
  void go_offline(const std::shared_ptr<TileSource>& failed);
  void reconnect_loop();

  const SourceInfo info_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  bool online_;
  std::shared_ptr<TileSource> current_;      // the opened upstream, or an offline source
  std::unordered_map<Handle, Inner> inner_;  // fetches in flight, by our handle
  Handle next_handle_ = 0;
  bool quit_ = false;
  const std::string location_;
  const SourceOptions options_;
  const std::chrono::milliseconds retry_;
  const Hooks hooks_;
  std::thread reconnect_;
};

// Serves one tileset from a TileCache. tile() maps the cache's outcome to the HTTP front's:
// ok -> ok (the cached bytes, no copy), absent -> absent, a payload that failed verification ->
// bad_origin, any other error (unreachable, offline) or a cancelled get -> unavailable.
// metrics_text() is the cache's counters, whether the upstream is online and whether disk writes
// are failing, in Prometheus text.
class CacheProvider final : public AsyncTileProvider {
 public:
  CacheProvider(std::shared_ptr<const ProvidedTileset> tileset, std::unique_ptr<TileCache> cache,
                std::shared_ptr<const ReconnectingSource> upstream);

  std::shared_ptr<const ProvidedTileset> find(std::string_view name) const override;
  std::vector<std::shared_ptr<const ProvidedTileset>> all() const override;
  // Only before shutdown(). An `abandon` request cancels the cache get (its `done` then runs
  // with unavailable), and with it the upstream fetch unless another get waits for that tile.
  void tile(const std::shared_ptr<const ProvidedTileset>& tileset, TileId id,
            std::function<void(ProvidedTile)> done, std::stop_token abandon = {}) override;
  std::string metrics_text() const override;
  // "disk cache writes failing since ...: N failed writes; the last: ..." while the cache's
  // disk writes fail (TileCache::disk_health()), else empty.
  std::string health_problem() const override;

  // Finishes pending gets (their `done`s run with unavailable), writes what the disk cache has
  // batched and releases the cache; the flush's error, if any. Call after the server stops
  // calling tile() and before it is destroyed. Idempotent.
  Status shutdown();

 private:
  std::shared_ptr<const ProvidedTileset> tileset_;
  std::unique_ptr<TileCache> cache_;
  std::shared_ptr<const ReconnectingSource> upstream_;
};

}  // namespace vts::client
