// DiskCache: SQLite 3 in WAL mode, one connection under one mutex.
//
// Schema (PRAGMA user_version = 2; a version-1 cache gets the fresh_for column when opened):
//
//   tilesets(id INTEGER PRIMARY KEY, key TEXT UNIQUE)   tileset key string -> small integer
//   tiles(tileset_id, z, x, y, size, checksum, atime, validated, pinned, etag, payload, fresh_for)
//     unique index tiles_key (tileset_id, z, x, y); index tiles_lru (pinned, atime) gives the
//     eviction order (unpinned rows, oldest access first, rowid breaking ties).
//     checksum = XXH3-64 (seed 0) of the whole payload, stored as a signed 64-bit integer.
//     atime = microseconds since the epoch of the last access (see next_time_us()).
//     validated = seconds since the epoch of the last fetch or revalidation.
//     fresh_for = seconds the tile stays fresh after `validated`, from the server's Cache-Control
//     (CachedTile::fresh_for); -1 when it said nothing. After the payload because it was added
//     by ALTER TABLE in version 2; only the tile read, which walks the payload anyway, reads it.
//     The payload is the last column, so reading the small columns (eviction, totals upkeep,
//     access-time updates) never walks the blob's overflow pages.
//   totals(id = 0, bytes, tiles, pinned_bytes, pinned_tiles)   one row
//     kept exact by triggers on tiles (insert, delete, update of size or pinned), which run in
//     the transaction of the change that fires them, whichever process or tool makes it. Upserts
//     use INSERT ... ON CONFLICT DO UPDATE rather than INSERT OR REPLACE, whose implicit delete
//     would not fire the delete trigger.
//
// Every change is one BEGIN IMMEDIATE transaction (the write lock is taken up front, so two
// writers never deadlock upgrading from read to write; busy_timeout makes the second one wait).
// With synchronous=NORMAL a commit is atomic and survives kill -9; only a power cut can lose the
// last commits (never corrupt the file).
//
// Size on disk, beyond the payload bytes (DiskCache::kFileSlackBytes and the max_bytes / 8
// allowance in the header; FileStaysNearTheCapUnderHeavyOverwriting measures it: with a 4 MiB cap
// and 8..40 KiB tiles the two files peaked at cap + 2.5 MiB):
//   - pages: each payload occupies whole 16 KiB pages (on average half a page lost per tile) plus
//     b-tree and index entries: a few percent for tiles of tens of KiB, but much more for tiles of
//     a few bytes (the cap counts payload bytes only);
//   - the WAL: checkpointed once it holds DiskCacheOptions::wal_checkpoint_bytes (2 MiB by
//     default) of pages and truncated back to that size after a checkpoint (a larger setting, as
//     `vts warm` uses, adds the difference); one transaction's pages more at worst (another
//     process reading through a checkpoint can make it grow further until it finishes);
//   - free pages: evictions free pages that the next puts reuse; when more than
//     2 * kFreePagesKept (1 MiB) are free, PRAGMA incremental_vacuum (auto_vacuum = INCREMENTAL,
//     set at creation) returns all but kFreePagesKept of them to the file system.
#include "vts/client/disk_cache.hpp"

#include <sqlite3.h>
#include <xxhash.h>

#include <algorithm>
#include <cassert>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <functional>
#include <mutex>
#include <span>
#include <system_error>
#include <thread>
#include <unordered_map>
#include <utility>
#include <vector>

namespace vts::client {
namespace {

constexpr int kEvictBatch = 64;              // rows fetched per eviction query
constexpr std::int64_t kFreePagesKept = 32;  // 512 KiB of 16 KiB pages
// The page size of new caches: 16 KiB rather than SQLite's 4 KiB, so a tile of tens of KiB is a
// quarter of the pages, and of the page writes (to the WAL, then again at each checkpoint).
// Caches made with 4 KiB pages keep them.
constexpr int kPageSize = 16384;
constexpr std::size_t kMaxPendingTouchesFactor = 16;  // drop access times beyond batch * this

constexpr const char* kSchemaSql = R"sql(
CREATE TABLE tilesets(
  id INTEGER PRIMARY KEY,
  key TEXT NOT NULL UNIQUE);
CREATE TABLE tiles(
  tileset_id INTEGER NOT NULL,
  z INTEGER NOT NULL,
  x INTEGER NOT NULL,
  y INTEGER NOT NULL,
  size INTEGER NOT NULL,
  checksum INTEGER NOT NULL,
  atime INTEGER NOT NULL,
  validated INTEGER NOT NULL,
  pinned INTEGER NOT NULL CHECK (pinned IN (0, 1)),
  etag TEXT NOT NULL,
  payload BLOB NOT NULL,
  fresh_for INTEGER NOT NULL DEFAULT -1);
CREATE UNIQUE INDEX tiles_key ON tiles(tileset_id, z, x, y);
CREATE INDEX tiles_lru ON tiles(pinned, atime);
CREATE TABLE totals(
  id INTEGER PRIMARY KEY CHECK (id = 0),
  bytes INTEGER NOT NULL,
  tiles INTEGER NOT NULL,
  pinned_bytes INTEGER NOT NULL,
  pinned_tiles INTEGER NOT NULL);
INSERT INTO totals VALUES (0, 0, 0, 0, 0);
CREATE TRIGGER tiles_totals_insert AFTER INSERT ON tiles BEGIN
  UPDATE totals SET bytes = bytes + NEW.size, tiles = tiles + 1,
                    pinned_bytes = pinned_bytes + NEW.pinned * NEW.size,
                    pinned_tiles = pinned_tiles + NEW.pinned
   WHERE id = 0;
END;
CREATE TRIGGER tiles_totals_delete AFTER DELETE ON tiles BEGIN
  UPDATE totals SET bytes = bytes - OLD.size, tiles = tiles - 1,
                    pinned_bytes = pinned_bytes - OLD.pinned * OLD.size,
                    pinned_tiles = pinned_tiles - OLD.pinned
   WHERE id = 0;
END;
CREATE TRIGGER tiles_totals_update AFTER UPDATE OF size, pinned ON tiles BEGIN
  UPDATE totals SET bytes = bytes - OLD.size + NEW.size,
                    pinned_bytes = pinned_bytes - OLD.pinned * OLD.size + NEW.pinned * NEW.size,
                    pinned_tiles = pinned_tiles - OLD.pinned + NEW.pinned
   WHERE id = 0;
END;
PRAGMA user_version = 2;
)sql";

// Version 1 → 2: each tile's freshness lifetime.
constexpr const char* kUpgradeTo2Sql = R"sql(
ALTER TABLE tiles ADD COLUMN fresh_for INTEGER NOT NULL DEFAULT -1;
PRAGMA user_version = 2;
)sql";

#define VTS_TILE_KEY_WHERE "tileset_id = ?1 AND z = ?2 AND x = ?3 AND y = ?4"

// Owns the connection; declared first in Impl so that it closes after every statement is gone.
struct Connection {
  sqlite3* db = nullptr;
  Connection() = default;
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;
  ~Connection() { sqlite3_close_v2(db); }
};

class Statement {
 public:
  Statement() = default;
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;
  ~Statement() { sqlite3_finalize(stmt_); }
  sqlite3_stmt* get() const { return stmt_; }
  sqlite3_stmt** out() { return &stmt_; }
  void finalize() {
    sqlite3_finalize(stmt_);
    stmt_ = nullptr;
  }

 private:
  sqlite3_stmt* stmt_ = nullptr;
};

// Resets a statement when leaving a scope, so that no read snapshot or bound buffer outlives the
// call that used it.
class ResetGuard {
 public:
  explicit ResetGuard(sqlite3_stmt* s) : s_(s) {}
  ResetGuard(const ResetGuard&) = delete;
  ResetGuard& operator=(const ResetGuard&) = delete;
  ~ResetGuard() {
    sqlite3_reset(s_);
    sqlite3_clear_bindings(s_);
  }

 private:
  sqlite3_stmt* s_;
};

struct StringHash {
  using is_transparent = void;
  std::size_t operator()(std::string_view s) const noexcept {
    return std::hash<std::string_view>{}(s);
  }
};

struct TouchKey {
  std::int64_t tileset_id = 0;
  TileId id;
  bool operator==(const TouchKey&) const = default;
};
struct TouchKeyHash {
  std::size_t operator()(const TouchKey& k) const noexcept {
    std::uint64_t h = std::uint64_t(k.tileset_id) * 0x9e3779b97f4a7c15ULL;
    h ^= tile_key(k.id);
    h ^= h >> 31;
    return static_cast<std::size_t>(h * 0xbf58476d1ce4e5b9ULL);
  }
};

struct Totals {
  std::uint64_t bytes = 0, tiles = 0, pinned_bytes = 0, pinned_tiles = 0;
};

std::uint64_t checksum_of(std::span<const std::uint8_t> bytes) {
  return XXH3_64bits(bytes.data(), bytes.size());
}

std::string tile_name(std::string_view tileset, TileId id) {
  return "tile " + id.to_string() + " of '" + std::string(tileset) + "'";
}

std::string mib(std::uint64_t bytes) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f MiB", double(bytes) / (1 << 20));
  return buf;
}

}  // namespace

struct DiskCache::Impl {
  Connection conn;  // first: destroyed last
  DiskCacheOptions options;
  std::filesystem::path path;
  std::string path_str;

  std::mutex mutex;  // guards everything below and every use of the connection
  Statement find_tileset_stmt, insert_tileset_stmt, get_stmt, old_row_stmt, totals_stmt,
      upsert_stmt, evict_candidates_stmt, delete_rowid_stmt, delete_corrupt_stmt, touch_stmt,
      validated_stmt, pinned_stmt, remove_stmt, freelist_stmt;

  // Tileset ids seen committed in the database. Rows of `tilesets` are never deleted or renumbered,
  // so an id once seen stays right for every process.
  std::unordered_map<std::string, std::int64_t, StringHash, std::equal_to<>> tileset_ids;
  // Ids inserted by the open write transaction: known to tileset_ids only once it commits.
  std::vector<std::pair<std::string, std::int64_t>> txn_tilesets;
  std::uint64_t txn_evicted = 0;

  std::unordered_map<TouchKey, std::int64_t, TouchKeyHash> pending_touches;  // key -> atime (us)
  std::chrono::steady_clock::time_point first_pending_touch;
  std::int64_t last_time_us = 0;

  std::uint64_t hits = 0, misses = 0, corrupt_dropped = 0, evicted = 0, write_transactions = 0;

  sqlite3* db() const { return conn.db; }

  // ---- errors -----------------------------------------------------------------------------

  // The error for a failed SQLite call, built from the connection's current message (call it
  // before anything else touches the connection). `doing` says what the cache was doing.
  Error db_error(int rc, std::string_view doing) const {
    const std::string msg = db() ? sqlite3_errmsg(db()) : sqlite3_errstr(rc);
    const int sys = db() ? sqlite3_system_errno(db()) : 0;
    const int primary = rc & 0xff;
    const std::string what = " (" + std::string(doing) + ")";
    if (primary == SQLITE_FULL ||
        (primary == SQLITE_IOERR && (sys == ENOSPC || sys == EDQUOT || sys == EFBIG)))
      return make_error(ErrorCode::io,
                        "disk full writing cache " + path_str + ": " + msg +
                            (sys ? std::string(" [") + std::strerror(sys) + "]" : "") + what);
    if (primary == SQLITE_IOERR)
      return make_error(ErrorCode::io,
                        "I/O error on cache " + path_str + ": " + msg +
                            (sys ? std::string(" [") + std::strerror(sys) + "]" : "") + what);
    if (primary == SQLITE_BUSY || primary == SQLITE_LOCKED)
      return make_error(ErrorCode::io, "cache " + path_str + " stayed locked by another user for " +
                                           std::to_string(options.busy_timeout.count()) + " ms" +
                                           what);
    if (primary == SQLITE_NOTADB)
      return make_error(ErrorCode::corrupt, "cache " + path_str + " is not an SQLite database (" +
                                                msg + "); move it away or choose another folder");
    if (primary == SQLITE_CORRUPT)
      return make_error(ErrorCode::corrupt, "cache " + path_str + " is damaged: " + msg + what);
    if (primary == SQLITE_READONLY || primary == SQLITE_CANTOPEN || primary == SQLITE_PERM ||
        primary == SQLITE_AUTH)
      return make_error(ErrorCode::io, "cannot write cache " + path_str + ": " + msg + what);
    if (primary == SQLITE_TOOBIG)
      return make_error(ErrorCode::too_large, "cache " + path_str + ": " + msg + what);
    return make_error(ErrorCode::internal, "cache " + path_str + ": SQLite error " +
                                               std::to_string(rc) + ": " + msg + what);
  }

  // ---- small helpers ----------------------------------------------------------------------

  int exec(const char* sql) { return sqlite3_exec(db(), sql, nullptr, nullptr, nullptr); }

  Status prepare(Statement& stmt, const char* sql) {
    const int rc =
        sqlite3_prepare_v3(db(), sql, -1, SQLITE_PREPARE_PERSISTENT, stmt.out(), nullptr);
    if (rc != SQLITE_OK)
      return make_error(
          ErrorCode::unsupported,
          "cache " + path_str + " does not have the expected tables: " + sqlite3_errmsg(db()));
    return {};
  }

  static void bind_key(sqlite3_stmt* s, std::int64_t tileset_id, TileId id) {
    sqlite3_bind_int64(s, 1, tileset_id);
    sqlite3_bind_int(s, 2, id.z);
    sqlite3_bind_int64(s, 3, id.x);
    sqlite3_bind_int64(s, 4, id.y);
  }

  // Runs a statement that returns no rows to completion. Returns SQLITE_DONE or the error code.
  static int run(sqlite3_stmt* s) {
    int rc;
    while ((rc = sqlite3_step(s)) == SQLITE_ROW) {
    }
    return rc;
  }

  // Microseconds since the epoch, strictly increasing across this connection's calls so that the
  // order of accesses is the order of atimes even within one clock tick.
  std::int64_t next_time_us() {
    const auto wall = std::chrono::duration_cast<std::chrono::microseconds>(
                          std::chrono::system_clock::now().time_since_epoch())
                          .count();
    last_time_us = std::max<std::int64_t>(wall, last_time_us + 1);
    return last_time_us;
  }

  Result<Totals> read_totals(std::string_view doing) {
    sqlite3_stmt* s = totals_stmt.get();
    ResetGuard guard(s);
    const int rc = sqlite3_step(s);
    if (rc != SQLITE_ROW) {
      if (rc == SQLITE_DONE)
        return make_error(ErrorCode::corrupt, "cache " + path_str + " has no totals row");
      return db_error(rc, doing);
    }
    Totals t;
    t.bytes = static_cast<std::uint64_t>(sqlite3_column_int64(s, 0));
    t.tiles = static_cast<std::uint64_t>(sqlite3_column_int64(s, 1));
    t.pinned_bytes = static_cast<std::uint64_t>(sqlite3_column_int64(s, 2));
    t.pinned_tiles = static_cast<std::uint64_t>(sqlite3_column_int64(s, 3));
    return t;
  }

  // The tileset's id if the database has one (nullopt if not). Does not insert.
  Result<std::optional<std::int64_t>> find_tileset(std::string_view tileset,
                                                   std::string_view doing) {
    if (auto it = tileset_ids.find(tileset); it != tileset_ids.end()) return {it->second};
    for (const auto& [key, id] : txn_tilesets)
      if (key == tileset) return {id};
    sqlite3_stmt* s = find_tileset_stmt.get();
    ResetGuard guard(s);
    sqlite3_bind_text64(s, 1, tileset.data(), tileset.size(), SQLITE_STATIC, SQLITE_UTF8);
    const int rc = sqlite3_step(s);
    if (rc == SQLITE_DONE) return {std::nullopt};
    if (rc != SQLITE_ROW) return db_error(rc, doing);
    const std::int64_t id = sqlite3_column_int64(s, 0);
    // Seen outside our own uncommitted inserts, so it is committed (we hold the write lock when
    // in a transaction, and a read outside one sees committed rows only).
    tileset_ids.emplace(std::string(tileset), id);
    return {id};
  }

  // The tileset's id, inserting a row for it if needed. Only inside a write transaction.
  Result<std::int64_t> tileset_for_write(std::string_view tileset, std::string_view doing) {
    auto found = find_tileset(tileset, doing);
    if (!found) return std::move(found).error();
    if (*found) return **found;
    sqlite3_stmt* s = insert_tileset_stmt.get();
    ResetGuard guard(s);
    sqlite3_bind_text64(s, 1, tileset.data(), tileset.size(), SQLITE_STATIC, SQLITE_UTF8);
    const int rc = run(s);
    if (rc != SQLITE_DONE) return db_error(rc, doing);
    const std::int64_t id = sqlite3_last_insert_rowid(db());
    txn_tilesets.emplace_back(std::string(tileset), id);
    return id;
  }

  // ---- transactions -----------------------------------------------------------------------

  // Runs `body` inside BEGIN IMMEDIATE ... COMMIT, after writing the pending access times. On any
  // failure the whole transaction is rolled back (SQLite may already have done so after a full
  // disk or I/O error), and the access times stay pending.
  template <typename Body>
  Status write_transaction(std::string_view doing, Body&& body) {
    txn_tilesets.clear();
    txn_evicted = 0;
    int rc = exec("BEGIN IMMEDIATE");
    if (rc != SQLITE_OK) {
      Error e = db_error(rc, doing);
      if (!sqlite3_get_autocommit(db())) exec("ROLLBACK");
      return e;
    }
    Status s = write_touches(doing);
    if (s.ok()) s = body();
    if (s.ok()) {
      rc = exec("COMMIT");
      if (rc != SQLITE_OK) s = db_error(rc, doing);
    }
    if (!s.ok()) {
      if (!sqlite3_get_autocommit(db())) exec("ROLLBACK");
      txn_tilesets.clear();
      return s;
    }
    ++write_transactions;
    evicted += txn_evicted;
    for (auto& [key, id] : txn_tilesets) tileset_ids.emplace(std::move(key), id);
    txn_tilesets.clear();
    pending_touches.clear();
    return {};
  }

  Status write_touches(std::string_view doing) {
    sqlite3_stmt* s = touch_stmt.get();
    for (const auto& [key, atime] : pending_touches) {
      ResetGuard guard(s);
      bind_key(s, key.tileset_id, key.id);
      sqlite3_bind_int64(s, 5, atime);
      const int rc = run(s);
      if (rc != SQLITE_DONE) return db_error(rc, doing);
    }
    return {};
  }

  // Records a hit's access time; writes the batch when it is full or old enough. A failure to
  // write them is not the reader's problem: they stay pending (up to a bound) for the next try.
  void touch(std::int64_t tileset_id, TileId id) {
    if (pending_touches.empty()) first_pending_touch = std::chrono::steady_clock::now();
    pending_touches[TouchKey{tileset_id, id}] = next_time_us();
    const std::size_t batch = std::max<std::size_t>(options.touch_batch, 1);
    if (pending_touches.size() >= batch ||
        std::chrono::steady_clock::now() - first_pending_touch >= options.touch_interval) {
      const Status s = write_transaction("writing access times", [] { return Status{}; });
      if (!s.ok() && pending_touches.size() >= batch * kMaxPendingTouchesFactor)
        pending_touches.clear();  // access times only steer eviction; do not grow without bound
    }
  }

  // Deletes unpinned rows other than `keep_rowid`, least recently used first, until the payload
  // total is within max_bytes. Inside a write transaction.
  Status evict_to_cap(std::int64_t keep_rowid, std::string_view doing) {
    auto totals = read_totals(doing);
    if (!totals) return std::move(totals).error();
    std::uint64_t bytes = totals->bytes;
    bool evicted_any = false;
    std::vector<std::pair<std::int64_t, std::uint64_t>> victims;
    while (bytes > options.max_bytes) {
      victims.clear();
      {
        sqlite3_stmt* s = evict_candidates_stmt.get();
        ResetGuard guard(s);
        sqlite3_bind_int64(s, 1, keep_rowid);
        sqlite3_bind_int(s, 2, kEvictBatch);
        int rc;
        while ((rc = sqlite3_step(s)) == SQLITE_ROW)
          victims.emplace_back(sqlite3_column_int64(s, 0),
                               static_cast<std::uint64_t>(sqlite3_column_int64(s, 1)));
        if (rc != SQLITE_DONE) return db_error(rc, doing);
      }
      if (victims.empty()) break;  // only pinned rows (and the kept one) are left
      for (const auto& [rowid, size] : victims) {
        if (bytes <= options.max_bytes) break;
        sqlite3_stmt* s = delete_rowid_stmt.get();
        ResetGuard guard(s);
        sqlite3_bind_int64(s, 1, rowid);
        const int rc = run(s);
        if (rc != SQLITE_DONE) return db_error(rc, doing);
        bytes -= std::min(bytes, size);
        ++txn_evicted;
        evicted_any = true;
      }
    }
    return evicted_any ? vacuum_if_needed(doing) : Status{};
  }

  // Gives free pages beyond kFreePagesKept back to the file system once there are twice as many.
  Status vacuum_if_needed(std::string_view doing) {
    std::int64_t free_pages = 0;
    {
      sqlite3_stmt* s = freelist_stmt.get();
      ResetGuard guard(s);
      const int rc = sqlite3_step(s);
      if (rc != SQLITE_ROW) return db_error(rc, doing);
      free_pages = sqlite3_column_int64(s, 0);
    }
    if (free_pages <= 2 * kFreePagesKept) return {};
    const std::string sql =
        "PRAGMA incremental_vacuum(" + std::to_string(free_pages - kFreePagesKept) + ")";
    const int rc = exec(sql.c_str());
    if (rc != SQLITE_OK) return db_error(rc, doing);
    return {};
  }

  // ---- reads ------------------------------------------------------------------------------

  // A tile's row as get_stmt reads it.
  struct Row {
    std::int64_t rowid = 0, checksum = 0;
    std::uint64_t size = 0;
    CachedTile tile;
    bool verifies() const {
      return tile.payload.size() == size &&
             static_cast<std::int64_t>(checksum_of(tile.payload)) == checksum;
    }
  };

  Result<std::optional<Row>> read_row(std::int64_t tileset_id, TileId id, std::string_view doing) {
    sqlite3_stmt* s = get_stmt.get();
    ResetGuard guard(s);
    bind_key(s, tileset_id, id);
    const int rc = sqlite3_step(s);
    if (rc == SQLITE_DONE) return {std::nullopt};
    if (rc != SQLITE_ROW) return db_error(rc, doing);
    Row row;
    row.rowid = sqlite3_column_int64(s, 0);
    row.size = static_cast<std::uint64_t>(sqlite3_column_int64(s, 1));
    row.checksum = sqlite3_column_int64(s, 2);
    CachedTile& tile = row.tile;
    tile.validated_unix = sqlite3_column_int64(s, 3);
    const auto* etag = reinterpret_cast<const char*>(sqlite3_column_text(s, 4));
    if (etag) tile.etag.assign(etag, static_cast<std::size_t>(sqlite3_column_bytes(s, 4)));
    const auto* blob = static_cast<const std::uint8_t*>(sqlite3_column_blob(s, 5));
    const auto n = static_cast<std::size_t>(sqlite3_column_bytes(s, 5));
    if (blob) tile.payload.assign(blob, blob + n);
    tile.pinned = sqlite3_column_int(s, 6) != 0;
    tile.fresh_for = sqlite3_column_int64(s, 7);
    return {std::move(row)};
  }

  // Deletes only the bad version: another process may have replaced the row meanwhile. Inside a
  // write transaction.
  Status delete_corrupt(const Row& row, std::string_view doing) {
    sqlite3_stmt* s = delete_corrupt_stmt.get();
    ResetGuard guard(s);
    sqlite3_bind_int64(s, 1, row.rowid);
    sqlite3_bind_int64(s, 2, row.checksum);
    const int rc = run(s);
    if (rc != SQLITE_DONE) return db_error(rc, doing);
    return {};
  }

  // Looks a tile up and verifies it; drops a row that fails. With `count_and_touch`, counts a hit
  // or miss and records the access time of a hit. With `pin`, a hit that is not pinned yet is read
  // again, verified and pinned in one write transaction (lookup_and_pin). Called with `lock` held;
  // returns with it held.
  Result<std::optional<CachedTile>> lookup(std::unique_lock<std::mutex>& lock,
                                           std::string_view tileset, TileId id,
                                           bool count_and_touch, bool pin = false) {
    const std::string_view doing = "reading a tile";
    auto tsid = find_tileset(tileset, doing);
    if (!tsid) return std::move(tsid).error();
    if (!*tsid) {
      if (count_and_touch) ++misses;
      return {std::nullopt};
    }
    auto row = read_row(**tsid, id, doing);
    if (!row) return std::move(row).error();
    if (!*row) {
      if (count_and_touch) ++misses;
      return {std::nullopt};
    }
    // Hash without the lock: other threads may use the connection meanwhile.
    lock.unlock();
    const bool good = (*row)->verifies();
    lock.lock();
    if (!good) {
      ++corrupt_dropped;
      if (count_and_touch) ++misses;
      // If the delete fails (a full disk) the row stays, and is caught again on the next read.
      (void)write_transaction("dropping a corrupt tile",
                              [&] { return delete_corrupt(**row, "dropping a corrupt tile"); });
      return {std::nullopt};
    }
    // A pinned row stays (only an explicit unpin could change that): the read is enough.
    if (pin && !(*row)->tile.pinned) return lookup_and_pin(tileset, id);
    if (count_and_touch) {
      ++hits;
      touch(**tsid, id);
    }
    return {std::move((*row)->tile)};
  }

  // get(..., pin = true) of a row that was not pinned: reads, verifies and pins it in one write
  // transaction (with its access time), so another process's eviction is either wholly before
  // (a miss) or wholly after (the row is pinned and stays). Counts the hit or miss.
  Result<std::optional<CachedTile>> lookup_and_pin(std::string_view tileset, TileId id) {
    const std::string doing = "reading and pinning " + tile_name(tileset, id);
    std::optional<CachedTile> found;
    bool corrupt = false;
    const Status s = write_transaction(doing, [&]() -> Status {
      found.reset();
      corrupt = false;
      auto tsid = find_tileset(tileset, doing);
      if (!tsid) return std::move(tsid).error();
      if (!*tsid) return {};
      auto row = read_row(**tsid, id, doing);
      if (!row) return std::move(row).error();
      if (!*row) return {};  // evicted (or removed) since it was read
      if (!(*row)->verifies()) {
        corrupt = true;
        return delete_corrupt(**row, doing);
      }
      for (sqlite3_stmt* st : {pinned_stmt.get(), touch_stmt.get()}) {
        ResetGuard guard(st);
        bind_key(st, **tsid, id);
        sqlite3_bind_int64(st, 5, st == pinned_stmt.get() ? 1 : next_time_us());
        if (const int rc = run(st); rc != SQLITE_DONE) return db_error(rc, doing);
      }
      (*row)->tile.pinned = true;
      found = std::move((*row)->tile);
      return {};
    });
    if (!s.ok()) return s.error();
    if (corrupt) ++corrupt_dropped;
    if (found)
      ++hits;
    else
      ++misses;
    return {std::move(found)};
  }

  // ---- opening ----------------------------------------------------------------------------

  // The database's page size (kPageSize for caches we created; 4 KiB for older ones).
  std::int64_t read_page_size() {
    Statement stmt;
    if (sqlite3_prepare_v2(db(), "PRAGMA page_size", -1, stmt.out(), nullptr) != SQLITE_OK ||
        sqlite3_step(stmt.get()) != SQLITE_ROW)
      return kPageSize;
    return std::max<std::int64_t>(512, sqlite3_column_int64(stmt.get(), 0));
  }

  Status check_version(std::int64_t version, std::int64_t tables) {
    if (version > kSchemaVersion)
      return make_error(ErrorCode::unsupported,
                        "cache " + path_str + " has schema version " + std::to_string(version) +
                            ", newer than this build reads (" + std::to_string(kSchemaVersion) +
                            "); use a newer vtstream or another cache folder");
    if (version < 0 || (version == 0 && tables > 0))
      return make_error(ErrorCode::unsupported,
                        "cache " + path_str +
                            " is an SQLite database but not a vtstream cache (schema version " +
                            std::to_string(version) + ", " + std::to_string(tables) +
                            " tables); move it away or choose another cache folder");
    return {};
  }

  // The schema version and the number of tables, read in one statement so both come from one
  // snapshot: read separately, another process creating the cache could commit in between and
  // the pair would look like a foreign database (version 0 with tables).
  Status read_version(std::string_view doing, std::int64_t& version, std::int64_t& tables) {
    Statement stmt;
    int rc = sqlite3_prepare_v2(db(),
                                "SELECT (SELECT user_version FROM pragma_user_version), "
                                "(SELECT count(*) FROM sqlite_schema WHERE type = 'table')",
                                -1, stmt.out(), nullptr);
    if (rc != SQLITE_OK) return db_error(rc, doing);
    rc = sqlite3_step(stmt.get());
    if (rc != SQLITE_ROW) return db_error(rc, doing);
    version = sqlite3_column_int64(stmt.get(), 0);
    tables = sqlite3_column_int64(stmt.get(), 1);
    return {};
  }

  Status setup() {
    // The first read of the header tells a non-SQLite file apart.
    std::int64_t version_value = 0, tables_value = 0;
    if (Status s = read_version("opening", version_value, tables_value); !s.ok()) return s;
    const std::int64_t* version = &version_value;
    if (Status s = check_version(version_value, tables_value); !s.ok()) return s;

    if (*version == 0) {
      // Both take effect only before the first table is created (ignored otherwise). The page
      // size is what the slack constants above are counted in.
      const std::string create =
          "PRAGMA page_size = " + std::to_string(kPageSize) + "; PRAGMA auto_vacuum = INCREMENTAL";
      if (int rc = exec(create.c_str()); rc != SQLITE_OK)
        return db_error(rc, "creating the database");
    }
    {
      // Switching a new file to WAL needs the file to itself; SQLite answers SQLITE_BUSY without
      // calling the busy handler when another process is creating or filling it at that
      // moment, so the switch is retried here for up to the busy timeout.
      Statement stmt;
      int rc = SQLITE_BUSY;
      const auto deadline = std::chrono::steady_clock::now() + options.busy_timeout;
      for (;;) {
        stmt.finalize();
        rc = sqlite3_prepare_v2(db(), "PRAGMA journal_mode = WAL", -1, stmt.out(), nullptr);
        if (rc == SQLITE_OK) rc = sqlite3_step(stmt.get());
        if ((rc != SQLITE_BUSY && rc != SQLITE_LOCKED) ||
            std::chrono::steady_clock::now() >= deadline)
          break;
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
      }
      if (rc != SQLITE_ROW) return db_error(rc, "switching to WAL");
      const auto* mode = reinterpret_cast<const char*>(sqlite3_column_text(stmt.get(), 0));
      if (!mode || std::string_view(mode) != "wal")
        return make_error(ErrorCode::unsupported,
                          "cache " + path_str + " cannot use a write-ahead log (journal mode '" +
                              std::string(mode ? mode : "?") +
                              "'); is the folder on a network file system?");
    }
    // temp_store = MEMORY keeps each statement's journal in memory: an upsert (its triggers make
    // it one that may need a partial rollback) otherwise spilled every page it touched to a temp
    // file past 64 KiB, ~3 bytes written there for each byte cached (a cold `vts warm` of 65 MiB
    // wrote 190 MiB of them).
    // The WAL is checkpointed once it holds wal_checkpoint_bytes of pages and truncated back to
    // that size after (so the next transactions overwrite the file rather than grow it again).
    const std::uint64_t wal_bytes = std::max<std::uint64_t>(options.wal_checkpoint_bytes, 1);
    const std::int64_t wal_pages =
        std::max<std::int64_t>(1, static_cast<std::int64_t>(wal_bytes) / read_page_size());
    const std::string pragmas =
        "PRAGMA synchronous = NORMAL; PRAGMA temp_store = MEMORY; PRAGMA journal_size_limit = " +
        std::to_string(wal_bytes) + "; PRAGMA wal_autocheckpoint = " + std::to_string(wal_pages) +
        ";";
    if (int rc = exec(pragmas.c_str()); rc != SQLITE_OK) return db_error(rc, "opening");
    if (!options.extra_pragmas.empty()) {
      if (int rc = exec(options.extra_pragmas.c_str()); rc != SQLITE_OK)
        return make_error(ErrorCode::invalid_argument, "cache " + path_str + ": extra pragmas '" +
                                                           options.extra_pragmas +
                                                           "': " + sqlite3_errmsg(db()));
    }

    if (*version == 0) {
      // Another process may be creating the same cache right now: decide under the write lock.
      if (int rc = exec("BEGIN IMMEDIATE"); rc != SQLITE_OK)
        return db_error(rc, "creating the database");
      std::int64_t again = 0, tables_again = 0;
      Status s = read_version("creating the database", again, tables_again);
      if (s.ok()) s = check_version(again, tables_again);
      if (s.ok() && again == 0) {
        if (int rc = exec(kSchemaSql); rc != SQLITE_OK) s = db_error(rc, "creating the database");
      }
      if (s.ok()) {
        if (int rc = exec("COMMIT"); rc != SQLITE_OK) s = db_error(rc, "creating the database");
      }
      if (!s.ok()) {
        if (!sqlite3_get_autocommit(db())) exec("ROLLBACK");
        return s;
      }
    } else if (*version == 1) {
      // Upgrade under the write lock; another process may have done it meanwhile.
      if (int rc = exec("BEGIN IMMEDIATE"); rc != SQLITE_OK)
        return db_error(rc, "upgrading the database");
      std::int64_t again = 0, tables_again = 0;
      Status s = read_version("upgrading the database", again, tables_again);
      if (s.ok() && again == 1) {
        if (int rc = exec(kUpgradeTo2Sql); rc != SQLITE_OK)
          s = db_error(rc, "upgrading the database");
      }
      if (s.ok()) {
        if (int rc = exec("COMMIT"); rc != SQLITE_OK) s = db_error(rc, "upgrading the database");
      }
      if (!s.ok()) {
        if (!sqlite3_get_autocommit(db())) exec("ROLLBACK");
        return s;
      }
    }

    struct {
      Statement* stmt;
      const char* sql;
    } const statements[] = {
        {&find_tileset_stmt, "SELECT id FROM tilesets WHERE key = ?1"},
        {&insert_tileset_stmt, "INSERT INTO tilesets(key) VALUES (?1)"},
        {&get_stmt,
         "SELECT rowid, size, checksum, validated, etag, payload, pinned, fresh_for FROM tiles "
         "WHERE " VTS_TILE_KEY_WHERE},
        {&old_row_stmt, "SELECT rowid, size, pinned FROM tiles WHERE " VTS_TILE_KEY_WHERE},
        {&totals_stmt, "SELECT bytes, tiles, pinned_bytes, pinned_tiles FROM totals WHERE id = 0"},
        {&upsert_stmt,
         "INSERT INTO tiles(tileset_id, z, x, y, size, checksum, atime, validated, pinned, etag, "
         "payload, fresh_for) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12) "
         "ON CONFLICT(tileset_id, z, x, y) DO UPDATE SET size = excluded.size, "
         "checksum = excluded.checksum, atime = excluded.atime, validated = excluded.validated, "
         "pinned = max(pinned, excluded.pinned), etag = excluded.etag, "
         "payload = excluded.payload, fresh_for = excluded.fresh_for"},
        {&evict_candidates_stmt,
         "SELECT rowid, size FROM tiles WHERE pinned = 0 AND rowid <> ?1 "
         "ORDER BY atime, rowid LIMIT ?2"},
        {&delete_rowid_stmt, "DELETE FROM tiles WHERE rowid = ?1"},
        {&delete_corrupt_stmt, "DELETE FROM tiles WHERE rowid = ?1 AND checksum = ?2"},
        {&touch_stmt, "UPDATE tiles SET atime = ?5 WHERE " VTS_TILE_KEY_WHERE " AND atime < ?5"},
        {&validated_stmt,
         "UPDATE tiles SET validated = ?5, fresh_for = ?6 WHERE " VTS_TILE_KEY_WHERE},
        {&pinned_stmt, "UPDATE tiles SET pinned = ?5 WHERE " VTS_TILE_KEY_WHERE},
        {&remove_stmt, "DELETE FROM tiles WHERE " VTS_TILE_KEY_WHERE},
        {&freelist_stmt, "PRAGMA freelist_count"},
    };
    for (const auto& [stmt, sql] : statements)
      if (Status s = prepare(*stmt, sql); !s.ok()) return s;

    // A smaller cap than the cache was filled with: shrink now rather than on the next put.
    auto totals = read_totals("opening");
    if (!totals) return std::move(totals).error();
    if (totals->bytes > options.max_bytes)
      return write_transaction("evicting down to a smaller cap",
                               [&] { return evict_to_cap(-1, "evicting down to a smaller cap"); });
    return {};
  }
};

DiskCache::DiskCache(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

DiskCache::~DiskCache() {
  std::lock_guard lock(impl_->mutex);
  if (!impl_->pending_touches.empty())
    (void)impl_->write_transaction("writing access times", [] { return Status{}; });
}

Result<std::unique_ptr<DiskCache>> DiskCache::open(DiskCacheOptions options) {
  if (options.dir.empty()) return make_error(ErrorCode::invalid_argument, "no cache folder given");
  if (options.max_bytes == 0)
    return make_error(ErrorCode::invalid_argument,
                      "cache " + options.dir.string() + ": the byte cap must be more than 0");
  std::error_code ec;
  std::filesystem::create_directories(options.dir, ec);
  if (ec)
    return make_error(ErrorCode::io,
                      "cannot create cache folder " + options.dir.string() + ": " + ec.message());
  if (!std::filesystem::is_directory(options.dir, ec))
    return make_error(ErrorCode::io, "cache folder " + options.dir.string() + " is not a folder");

  auto impl = std::make_unique<Impl>();
  impl->path = options.dir / kFileName;
  impl->path_str = impl->path.string();
  impl->options = std::move(options);
  const int flags = SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX;
  const char* vfs = impl->options.vfs.empty() ? nullptr : impl->options.vfs.c_str();
  const int rc = sqlite3_open_v2(impl->path_str.c_str(), &impl->conn.db, flags, vfs);
  if (rc != SQLITE_OK) {
    const std::string msg = impl->conn.db ? sqlite3_errmsg(impl->conn.db) : sqlite3_errstr(rc);
    return make_error(ErrorCode::io, "cannot open cache " + impl->path_str + ": " + msg);
  }
  sqlite3_extended_result_codes(impl->db(), 1);
  sqlite3_busy_timeout(impl->db(), static_cast<int>(std::clamp<std::int64_t>(
                                       impl->options.busy_timeout.count(), 0, 1 << 30)));
  std::lock_guard lock(impl->mutex);
  if (Status s = impl->setup(); !s.ok()) return s.error();
  return std::unique_ptr<DiskCache>(new DiskCache(std::move(impl)));
}

const std::filesystem::path& DiskCache::path() const {
  return impl_->path;
}

Result<std::optional<CachedTile>> DiskCache::get(std::string_view tileset, TileId id, bool pin) {
  std::unique_lock lock(impl_->mutex);
  return impl_->lookup(lock, tileset, id, true, pin);
}

Result<bool> DiskCache::contains(std::string_view tileset, TileId id) {
  std::unique_lock lock(impl_->mutex);
  auto found = impl_->lookup(lock, tileset, id, false);
  if (!found) return std::move(found).error();
  return found->has_value();
}

// One tile's insert or replace, inside the caller's write transaction.
Status DiskCache::put_row(Impl& m, std::string_view tileset, TileId id, const CachedTile& tile,
                          bool pin, const std::string& doing) {
  const std::uint64_t size = tile.payload.size();
  if (size > m.options.max_bytes)
    return make_error(ErrorCode::too_large, tile_name(tileset, id) + " is " + std::to_string(size) +
                                                " bytes, more than the whole cap of cache " +
                                                m.path_str + " (" +
                                                std::to_string(m.options.max_bytes) + " bytes)");
  const auto checksum = static_cast<std::int64_t>(checksum_of(tile.payload));
  auto tsid = m.tileset_for_write(tileset, doing);
  if (!tsid) return std::move(tsid).error();

  std::optional<std::int64_t> old_rowid;
  std::uint64_t old_size = 0;
  bool old_pinned = false;
  {
    sqlite3_stmt* s = m.old_row_stmt.get();
    ResetGuard guard(s);
    DiskCache::Impl::bind_key(s, *tsid, id);
    const int rc = sqlite3_step(s);
    if (rc == SQLITE_ROW) {
      old_rowid = sqlite3_column_int64(s, 0);
      old_size = static_cast<std::uint64_t>(sqlite3_column_int64(s, 1));
      old_pinned = sqlite3_column_int(s, 2) != 0;
    } else if (rc != SQLITE_DONE) {
      return m.db_error(rc, doing);
    }
  }

  auto totals = m.read_totals(doing);
  if (!totals) return std::move(totals).error();
  const std::uint64_t pinned_elsewhere =
      totals->pinned_bytes - std::min(totals->pinned_bytes, old_pinned ? old_size : 0);
  if (pinned_elsewhere + size > m.options.max_bytes)
    return make_error(ErrorCode::too_large,
                      "cache " + m.path_str +
                          " is full of pinned tiles: " + std::to_string(pinned_elsewhere) +
                          " bytes (" + mib(pinned_elsewhere) + ") pinned of its cap of " +
                          std::to_string(m.options.max_bytes) + " bytes (" +
                          mib(m.options.max_bytes) + "), no room for " + tile_name(tileset, id) +
                          " (" + std::to_string(size) + " bytes); unpin tiles or raise the cap");

  {
    sqlite3_stmt* s = m.upsert_stmt.get();
    ResetGuard guard(s);
    DiskCache::Impl::bind_key(s, *tsid, id);
    sqlite3_bind_int64(s, 5, static_cast<std::int64_t>(size));
    sqlite3_bind_int64(s, 6, checksum);
    sqlite3_bind_int64(s, 7, m.next_time_us());
    sqlite3_bind_int64(s, 8, tile.validated_unix);
    sqlite3_bind_int(s, 9, pin ? 1 : 0);
    sqlite3_bind_text64(s, 10, tile.etag.data(), tile.etag.size(), SQLITE_STATIC, SQLITE_UTF8);
    // A zero-length blob needs a non-null pointer, or SQLite binds NULL.
    static const std::uint8_t kEmpty = 0;
    sqlite3_bind_blob64(s, 11, size ? tile.payload.data() : &kEmpty, size, SQLITE_STATIC);
    sqlite3_bind_int64(s, 12, tile.fresh_for);
    const int rc = DiskCache::Impl::run(s);
    if (rc != SQLITE_DONE) return m.db_error(rc, doing);
  }
  const std::int64_t rowid = old_rowid ? *old_rowid : sqlite3_last_insert_rowid(m.db());
  return m.evict_to_cap(rowid, doing);
}

Status DiskCache::put(std::string_view tileset, TileId id, const CachedTile& tile, bool pin) {
  Impl& m = *impl_;
  const std::string doing = "storing " + tile_name(tileset, id);
  std::lock_guard lock(m.mutex);
  return m.write_transaction(doing,
                             [&]() -> Status { return put_row(m, tileset, id, tile, pin, doing); });
}

Status DiskCache::put_batch(std::string_view tileset, std::span<const BatchItem> items) {
  if (items.empty()) return {};
  Impl& m = *impl_;
  const std::string doing = "storing " + std::to_string(items.size()) + " tiles of " +
                            std::string(tileset) + " (from " + tile_name(tileset, items[0].id) +
                            ")";
  std::lock_guard lock(m.mutex);
  return m.write_transaction(doing, [&]() -> Status {
    for (const auto& item : items)
      if (Status s = put_row(m, tileset, item.id, *item.tile, item.pin, doing); !s) return s;
    return {};
  });
}

// One UPDATE of an existing row (`stmt`, with the tile key in ?1-?4 and `bind` setting the rest)
// in a write transaction; not_found when the cache has no such tile.
Status DiskCache::update_row(std::string_view tileset, TileId id, const std::string& doing,
                             sqlite3_stmt* (*stmt)(Impl&),
                             const std::function<void(sqlite3_stmt*)>& bind) {
  Impl& m = *impl_;
  std::lock_guard lock(m.mutex);
  auto tsid = m.find_tileset(tileset, doing);
  if (!tsid) return std::move(tsid).error();
  const auto missing = [&] {
    return make_error(ErrorCode::not_found,
                      tile_name(tileset, id) + " is not in cache " + m.path_str);
  };
  if (!*tsid) return missing();
  return m.write_transaction(doing, [&]() -> Status {
    sqlite3_stmt* s = stmt(m);
    ResetGuard guard(s);
    Impl::bind_key(s, **tsid, id);
    bind(s);
    const int rc = Impl::run(s);
    if (rc != SQLITE_DONE) return m.db_error(rc, doing);
    if (sqlite3_changes(m.db()) == 0) return missing();
    return {};
  });
}

Status DiskCache::set_validated(std::string_view tileset, TileId id, std::int64_t validated_unix,
                                std::int64_t fresh_for) {
  return update_row(
      tileset, id, "recording the revalidation of " + tile_name(tileset, id),
      [](Impl& m) { return m.validated_stmt.get(); },
      [&](sqlite3_stmt* s) {
        sqlite3_bind_int64(s, 5, validated_unix);
        sqlite3_bind_int64(s, 6, fresh_for);
      });
}

Status DiskCache::set_pinned(std::string_view tileset, TileId id, bool pinned) {
  return update_row(
      tileset, id, std::string(pinned ? "pinning " : "unpinning ") + tile_name(tileset, id),
      [](Impl& m) { return m.pinned_stmt.get(); },
      [&](sqlite3_stmt* s) { sqlite3_bind_int(s, 5, pinned ? 1 : 0); });
}

Status DiskCache::remove(std::string_view tileset, TileId id) {
  Impl& m = *impl_;
  const std::string doing = "removing " + tile_name(tileset, id);
  std::lock_guard lock(m.mutex);
  auto tsid = m.find_tileset(tileset, doing);
  if (!tsid) return std::move(tsid).error();
  if (!*tsid) return {};
  return m.write_transaction(doing, [&]() -> Status {
    sqlite3_stmt* s = m.remove_stmt.get();
    ResetGuard guard(s);
    Impl::bind_key(s, **tsid, id);
    const int rc = Impl::run(s);
    if (rc != SQLITE_DONE) return m.db_error(rc, doing);
    return sqlite3_changes(m.db()) > 0 ? m.vacuum_if_needed(doing) : Status{};
  });
}

Status DiskCache::flush() {
  std::lock_guard lock(impl_->mutex);
  if (impl_->pending_touches.empty()) return {};
  return impl_->write_transaction("writing access times", [] { return Status{}; });
}

DiskCacheStats DiskCache::stats() {
  Impl& m = *impl_;
  std::lock_guard lock(m.mutex);
  DiskCacheStats out;
  if (auto totals = m.read_totals("reading totals")) {
    out.bytes = totals->bytes;
    out.tiles = totals->tiles;
    out.pinned_bytes = totals->pinned_bytes;
    out.pinned_tiles = totals->pinned_tiles;
  }
  out.max_bytes = m.options.max_bytes;
  out.hits = m.hits;
  out.misses = m.misses;
  out.corrupt_dropped = m.corrupt_dropped;
  out.evicted = m.evicted;
  out.write_transactions = m.write_transactions;
  return out;
}

Result<VerifyReport> DiskCache::verify() {
  Impl& m = *impl_;
  const std::string_view doing = "verifying";
  std::lock_guard lock(m.mutex);
  VerifyReport report;
  {
    Statement stmt;
    int rc = sqlite3_prepare_v2(m.db(), "PRAGMA integrity_check", -1, stmt.out(), nullptr);
    if (rc != SQLITE_OK) return m.db_error(rc, doing);
    while ((rc = sqlite3_step(stmt.get())) == SQLITE_ROW) {
      const auto* line = reinterpret_cast<const char*>(sqlite3_column_text(stmt.get(), 0));
      if (!report.integrity.empty()) report.integrity += "; ";
      report.integrity += line ? line : "?";
    }
    if (rc != SQLITE_DONE) return m.db_error(rc, doing);
  }
  std::vector<std::pair<std::int64_t, std::int64_t>> bad;  // rowid, stored checksum
  {
    Statement stmt;
    int rc = sqlite3_prepare_v2(m.db(), "SELECT rowid, size, checksum, payload FROM tiles", -1,
                                stmt.out(), nullptr);
    if (rc != SQLITE_OK) return m.db_error(rc, doing);
    sqlite3_stmt* s = stmt.get();
    while ((rc = sqlite3_step(s)) == SQLITE_ROW) {
      ++report.rows_checked;
      const auto* blob = static_cast<const std::uint8_t*>(sqlite3_column_blob(s, 3));
      const auto n = static_cast<std::size_t>(sqlite3_column_bytes(s, 3));
      const std::span<const std::uint8_t> payload(blob, blob ? n : 0);
      const bool good =
          payload.size() == static_cast<std::uint64_t>(sqlite3_column_int64(s, 1)) &&
          static_cast<std::int64_t>(checksum_of(payload)) == sqlite3_column_int64(s, 2);
      if (!good) bad.emplace_back(sqlite3_column_int64(s, 0), sqlite3_column_int64(s, 2));
    }
    if (rc != SQLITE_DONE) return m.db_error(rc, doing);
  }
  if (!bad.empty()) {
    Status s = m.write_transaction("dropping corrupt tiles", [&]() -> Status {
      for (const auto& [rowid, checksum] : bad) {
        sqlite3_stmt* st = m.delete_corrupt_stmt.get();
        ResetGuard guard(st);
        sqlite3_bind_int64(st, 1, rowid);
        sqlite3_bind_int64(st, 2, checksum);
        const int rc = Impl::run(st);
        if (rc != SQLITE_DONE) return m.db_error(rc, "dropping corrupt tiles");
      }
      return m.vacuum_if_needed("dropping corrupt tiles");
    });
    if (!s.ok()) return s.error();
    report.rows_dropped = bad.size();
    m.corrupt_dropped += bad.size();
  }
  return report;
}

}  // namespace vts::client
