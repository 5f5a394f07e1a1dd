// The payload level of the client stack: a TileSource decorated with a RAM cache, a disk cache
// and a negative cache, behind one asynchronous get(). Used directly by the cache daemon
// (`vts cache serve`) and `vts warm`, and by TileClient (which adds ancestors and decoding).
//
// A get() looks in RAM (inline, on the caller's thread), then on disk (on the cache's own disk
// thread), then asks the source (on the source's network thread). Each stage has its own thread
// and queue, so a RAM or disk hit never waits behind the network, and the network never waits
// behind SQLite: a tile found on disk is delivered even while every network slot is stuck on a
// dead server.
//
// What the caches hand out is always verified: a payload from the network is checked (tile
// header + XXH3 checksum of its body, and the header against the tileset: size, codec and pixel
// format, vts::check_tile_against) before it is cached or delivered, and re-fetched when it
// fails (up to `corrupt_retries` times; then an error, ErrorCode::checksum or corrupt); rows read
// from disk are checked by the disk cache's own checksum and again here (a row that fails is
// dropped and fetched again). So a tile of another size or codec never reaches RAM, disk or a
// caller. A tile older than its freshness lifetime (its server's Cache-Control max-age / immutable,
// else `revalidate_after`) is delivered at once and then
// revalidated at the lowest priority (If-None-Match; 304 refreshes its age). Tiles the source
// says are absent are remembered for the session and never asked for again.
//
// Concurrent gets of one tile are merged: one disk read, one network fetch. Cancelling a get
// removes its callback; when a tile's last waiter is cancelled its network fetch is cancelled.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "vts/base/result.hpp"
#include "vts/client/disk_cache.hpp"
#include "vts/client/ram_cache.hpp"
#include "vts/client/source.hpp"

namespace vts::client {

struct TileCacheOptions {
  std::size_t ram_bytes = 256u << 20;    // 0 = no RAM cache
  std::optional<DiskCacheOptions> disk;  // none = no disk cache
  // A tile's freshness lifetime when its server's Cache-Control stated none (see
  // cache_control_lifetime()): max-age=N → N s, immutable → never stale, no-cache/no-store → stale
  // at every hit. 0 = revalidate on every disk/RAM hit.
  std::chrono::seconds revalidate_after{3600};
  bool fixed_revalidate_after = false;  // true: revalidate_after for every tile, whatever it said
  int corrupt_retries = 2;              // re-fetches of a payload that failed its checksum
  // Where failed disk writes (disk full, I/O error, a damaged or read-only cache.db) are
  // reported, one line without a newline, called on the disk thread: the first failure at once,
  // then at most one line per `disk_report_interval` counting the failures since the last line,
  // and one line when a tile is stored again. Unset: not reported (disk_health() and the stats
  // still tell). A tile too large for the cache or a row evicted meanwhile is not a failure.
  std::function<void(const std::string& line)> disk_report;
  std::chrono::milliseconds disk_report_interval{60000};
  // The clock of that interval; unset: std::chrono::steady_clock (tests pass a fake one).
  std::function<std::chrono::steady_clock::time_point()> clock;
};

// The disk cache's write state: failing from a failed write until a tile is stored again.
struct DiskHealth {
  bool failing = false;
  std::uint64_t failed_writes = 0;  // since failing began
  std::int64_t failing_since_unix = 0;
  std::optional<Error> last_error;  // of the current failing spell
};

struct GetOptions {
  int level = -1;          // fetch order (lower first); -1 = the tile's z
  double urgency = 0;      // within a level, higher first
  bool pin = false;        // pin the tile in the caches (warm; the roots)
  bool revalidate = true;  // revalidate a stale hit in the background
};

struct PayloadResult {
  enum class Kind { ok, absent, error, cancelled };
  enum class From { ram, disk, network };
  Kind kind = Kind::error;
  From from = From::network;
  std::shared_ptr<const CachedTile> tile;  // Kind::ok
  std::optional<Error> error;              // Kind::error
  // From::network: the HTTP exchange that brought it, when the source reports one (the last
  // one when a corrupt payload was fetched again).
  std::optional<SourceTransfer> transfer;
};

// Runs on the caller's thread (RAM hits, absent tiles: before get() returns), on the disk
// thread or on the source's thread. Must not block.
using PayloadCallback = std::function<void(PayloadResult&&)>;

class TileCache {
 public:
  static Result<std::unique_ptr<TileCache>> create(std::shared_ptr<TileSource> source,
                                                   TileCacheOptions options);
  ~TileCache();  // cancels pending gets (their callbacks run with Kind::cancelled)
  TileCache(const TileCache&) = delete;
  TileCache& operator=(const TileCache&) = delete;

  const SourceInfo& info() const;
  // 0 when the get completed before returning (RAM hit, known-absent tile).
  using Handle = std::uint64_t;
  Handle get(TileId id, const GetOptions& options, PayloadCallback callback);
  void cancel(Handle h);
  // Writes what is batched (disk access times) and waits for queued disk writes.
  Status flush();

  struct Stats {
    std::uint64_t gets = 0, ram_hits = 0, disk_hits = 0, network_fetches = 0, absent = 0,
                  errors = 0, corrupt_rejected = 0, revalidations = 0, not_modified = 0,
                  disk_write_errors = 0, cancelled = 0,
                  mismatch_rejected = 0;  // tiles refused for contradicting the tileset
  };
  Stats stats() const;
  RamCache* ram();    // nullptr when disabled
  DiskCache* disk();  // nullptr when disabled
  // The last disk write error (e.g. disk full), for reporting; empty when none.
  std::optional<Error> last_disk_error() const;
  // Whether disk writes are failing now (see TileCacheOptions::disk_report). Thread-safe.
  DiskHealth disk_health() const;

 private:
  class Impl;
  explicit TileCache(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace vts::client
