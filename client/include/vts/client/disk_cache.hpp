// The client's persistent tile cache: one SQLite 3 database, `cache.db`, in a cache folder.
//
// What it promises:
// - Never hands out a tile whose bytes changed since they were stored: every row carries an
//   XXH3-64 of its payload, verified on every read; a row that fails is deleted and reported as a
//   miss (stats().corrupt_dropped counts it).
// - Holds at most `max_bytes` of payload (pinned tiles included), evicting unpinned tiles in
//   least-recently-used order after each put. The files on disk (cache.db + cache.db-wal) stay
//   within max_bytes + max_bytes / 8 + kFileSlackBytes (page and index overhead, the write-ahead
//   log and a bounded free-page list; disk_cache.cpp has the breakdown), plus
//   wal_checkpoint_bytes beyond its default of 2 MiB when it is set larger.
// - Survives kill -9 at any moment (every change is one SQLite transaction; WAL journal with
//   synchronous=NORMAL: a commit is not synced, so a power cut, unlike kill -9, may lose the last
//   commits since the previous checkpoint, but never corrupts the file), a full
//   disk (the write fails with ErrorCode::io "disk full writing cache <path>: ...", the
//   transaction rolls back, reads keep working) and several processes sharing the folder (WAL lets
//   readers run beside the one writer; writers wait up to busy_timeout for each other).
// - Keeps exact running totals (bytes, tiles, pinned bytes/tiles) in the database, updated in the
//   same transaction as each change, so opening never scans the tiles.
//
// Access times (for LRU order) are not written on each hit: hits are remembered in memory and
// written in one transaction once `touch_batch` of them are pending, once the oldest pending one
// is `touch_interval` old (checked on the next hit; there is no background thread), on flush(), on
// destruction, and along with any other write transaction. Access times lost to kill -9 only make
// the eviction order slightly less exact.
//
// Thread safety: all member functions may be called from any thread; they share one SQLite
// connection under one mutex, so calls are serialised (a get waits for a put in progress, and
// a write waiting up to busy_timeout for another process's write holds up this process's reads).
// Two instances on one folder in one process work like two processes; one is the intended use.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "vts/base/result.hpp"
#include "vts/client/ram_cache.hpp"
#include "vts/protocol/geometry.hpp"

struct sqlite3_stmt;

namespace vts::client {

struct DiskCacheOptions {
  std::filesystem::path dir;             // created if missing
  std::uint64_t max_bytes = 1ull << 30;  // cap on payload bytes held (pinned included), > 0
  std::chrono::milliseconds busy_timeout{10000};
  std::size_t touch_batch = 256;                   // access times flushed after this many hits ...
  std::chrono::milliseconds touch_interval{5000};  // ... or this long, or on flush()/destruction
  // The write-ahead log is checkpointed into cache.db once it holds this many bytes of pages, and
  // truncated back to this size after. Each checkpoint syncs the log and the database (two
  // fsyncs) and copies every page once, so a bulk fill (`vts warm`) runs faster with a larger
  // log; the files on disk may then exceed the bound above by the difference from the default.
  std::uint64_t wal_checkpoint_bytes = 2ull << 20;
  // SQL run on the connection after the cache's own settings (PRAGMAs such as cache_size or
  // mmap_size), for measuring settings (bench/warm_bench.sh). Weakening synchronous or
  // journal_mode voids the crash guarantees above. Fails open (invalid_argument) when it fails.
  std::string extra_pragmas;
  // Name of a registered SQLite VFS to open the database with; empty for SQLite's default. Lets
  // tests inject I/O faults (a write failing with "disk full" at the n-th write).
  std::string vfs;
};

struct DiskCacheStats {
  // From the database's running totals: every process's writes included.
  std::uint64_t bytes = 0;  // payload bytes held
  std::uint64_t tiles = 0;
  std::uint64_t pinned_bytes = 0;  // part of `bytes`
  std::uint64_t pinned_tiles = 0;
  std::uint64_t max_bytes = 0;  // this instance's cap
  // This instance's own counters since open().
  std::uint64_t hits = 0;
  std::uint64_t misses = 0;              // includes rows dropped as corrupt
  std::uint64_t corrupt_dropped = 0;     // rows deleted because their checksum did not verify
  std::uint64_t evicted = 0;             // rows deleted to stay within max_bytes
  std::uint64_t write_transactions = 0;  // committed write transactions (for tests of batching)
};

struct VerifyReport {
  std::uint64_t rows_checked = 0;
  std::uint64_t rows_dropped = 0;  // rows whose checksum did not verify, now deleted
  std::string integrity;           // "ok" or SQLite's integrity_check messages joined by "; "
};

class DiskCache {
 public:
  static constexpr int kSchemaVersion = 2;  // PRAGMA user_version of the databases we write
  static constexpr const char* kFileName = "cache.db";
  // Allowance on top of max_bytes for the files on disk, besides max_bytes / 8 for page and index
  // overhead (which holds for tiles of a few KiB or more: the cap counts payload bytes only): the
  // write-ahead log (checkpointed every ~2 MiB, truncated back to 2 MiB) and up to 1 MiB of free
  // pages kept for reuse before an incremental vacuum gives them back.
  static constexpr std::uint64_t kFileSlackBytes = 4ull << 20;

  // Opens (creating the folder and database if needed) the cache in options.dir. Fails with a
  // message naming the file when it is not an SQLite database (corrupt), is an SQLite database
  // that is not a vtstream cache or was written by a newer version (unsupported), or cannot be
  // created or opened (io). If the cache holds more than max_bytes (a smaller cap than last
  // time), evicts down to it.
  static Result<std::unique_ptr<DiskCache>> open(DiskCacheOptions options);
  ~DiskCache();  // flushes pending access times; errors are ignored
  DiskCache(const DiskCache&) = delete;
  DiskCache& operator=(const DiskCache&) = delete;

  // The tile, or nullopt on a miss. Verifies the row's checksum; a mismatching row is deleted
  // (counted in corrupt_dropped) and reported as a miss. A hit records an access time (batched).
  // Errors only when the database cannot be read (busy beyond busy_timeout, I/O error).
  // pin = true also pins a hit (the tile comes back with pinned = true), in one write transaction
  // with the read, so no other process's eviction can fall between them: the tile is either
  // handed out pinned or a miss. Errors then also when that transaction cannot be written (a full
  // disk: io); a plain get may still read the tile.
  Result<std::optional<CachedTile>> get(std::string_view tileset, TileId id, bool pin = false);
  // True when a row is present and its checksum verifies (a bad row is dropped as in get()).
  // Neither counts as a hit or miss nor updates the access time.
  Result<bool> contains(std::string_view tileset, TileId id);
  // Stores or replaces the tile as the most recently used, then evicts unpinned tiles in LRU order
  // until the total is within max_bytes. pin = true pins the tile; pin = false keeps an existing
  // row's pin (a refresh does not unpin). Fails, storing nothing, with too_large when the payload
  // alone exceeds max_bytes or when pinned tiles leave no room for it, and with io on a full disk.
  Status put(std::string_view tileset, TileId id, const CachedTile& tile, bool pin = false);
  // Several puts in one transaction (one commit instead of one per tile: what makes a cold fetch
  // keep up with the network). All or nothing: on error nothing of the batch is stored.
  struct BatchItem {
    TileId id;
    const CachedTile* tile = nullptr;
    bool pin = false;
  };
  Status put_batch(std::string_view tileset, std::span<const BatchItem> items);
  // Records a successful revalidation (HTTP 304). not_found when the tile is not cached.
  // fresh_for: the tile's new freshness lifetime (CachedTile::fresh_for).
  Status set_validated(std::string_view tileset, TileId id, std::int64_t validated_unix,
                       std::int64_t fresh_for = -1);
  // Pins (never evicted) or unpins a cached tile. not_found when the tile is not cached (another
  // process may have evicted it since it was read: to keep a tile that is read, get(..., true)).
  Status set_pinned(std::string_view tileset, TileId id, bool pinned);
  // Deletes the tile if present (absent is not an error).
  Status remove(std::string_view tileset, TileId id);
  // Writes the batched access times now (one transaction; nothing when none are pending).
  Status flush();
  // Totals from the database (zero when it cannot be read) and this instance's counters.
  DiskCacheStats stats();
  // PRAGMA integrity_check, then reads every row and verifies its checksum, deleting bad rows.
  // Reads the whole database: for maintenance commands and tests, not the hot path.
  Result<VerifyReport> verify();

  const std::filesystem::path& path() const;  // the database file, <dir>/cache.db

 private:
  struct Impl;
  static Status put_row(Impl& m, std::string_view tileset, TileId id, const CachedTile& tile,
                        bool pin, const std::string& doing);
  Status update_row(std::string_view tileset, TileId id, const std::string& doing,
                    sqlite3_stmt* (*stmt)(Impl&), const std::function<void(sqlite3_stmt*)>& bind);
  explicit DiskCache(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace vts::client
