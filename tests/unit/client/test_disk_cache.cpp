// DiskCache against real SQLite files in a temporary folder. The tests also open the database
// directly with SQLite (linked through vts::client) to look behind the cache's back: to check the
// schema and totals, and to damage rows the way a failing disk would.
#include "vts/client/disk_cache.hpp"
#include "vts/client/source.hpp"
#include "vts/test/temp_dir.hpp"

#include "fault_vfs.hpp"

#include <gtest/gtest.h>
#include <sqlite3.h>
#include <stdlib.h>

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

namespace vts::client {
namespace {

namespace fs = std::filesystem;

// ---- helpers ------------------------------------------------------------------------------------

std::uint64_t splitmix(std::uint64_t& s) {
  std::uint64_t z = (s += 0x9e3779b97f4a7c15ULL);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

CachedTile make_tile(std::size_t size, std::uint64_t seed, std::string etag = "\"e\"",
                     std::int64_t validated = 1700000000) {
  CachedTile t;
  t.payload.resize(size);
  std::uint64_t s = seed;
  for (auto& b : t.payload) b = static_cast<std::uint8_t>(splitmix(s));
  t.etag = std::move(etag);
  t.validated_unix = validated;
  return t;
}

TileId tid(std::uint32_t x, std::uint32_t y = 0, std::uint8_t z = 12) {
  return TileId{z, x, y};
}

// A fresh folder, removed at the end of the test.
using TempFolder = vts::test::TempDir;

// A direct SQLite connection to a cache's database, for looking behind the cache's back.
class RawDb {
 public:
  explicit RawDb(const fs::path& file) {
    EXPECT_EQ(sqlite3_open(file.c_str(), &db_), SQLITE_OK);
    sqlite3_busy_timeout(db_, 10000);
  }
  ~RawDb() { sqlite3_close(db_); }
  void exec(const std::string& sql) {
    char* err = nullptr;
    EXPECT_EQ(sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &err), SQLITE_OK)
        << sql << ": " << (err ? err : "");
    sqlite3_free(err);
  }
  std::int64_t integer(const std::string& sql) {
    sqlite3_stmt* s = nullptr;
    EXPECT_EQ(sqlite3_prepare_v2(db_, sql.c_str(), -1, &s, nullptr), SQLITE_OK) << sql;
    std::int64_t v = -1;
    if (sqlite3_step(s) == SQLITE_ROW) v = sqlite3_column_int64(s, 0);
    sqlite3_finalize(s);
    return v;
  }
  std::string text(const std::string& sql, int column = 0) {
    sqlite3_stmt* s = nullptr;
    EXPECT_EQ(sqlite3_prepare_v2(db_, sql.c_str(), -1, &s, nullptr), SQLITE_OK) << sql;
    std::string v;
    if (sqlite3_step(s) == SQLITE_ROW) {
      const auto* t = sqlite3_column_text(s, column);
      if (t) v = reinterpret_cast<const char*>(t);
    }
    sqlite3_finalize(s);
    return v;
  }
  // The totals row must equal what the tiles table says.
  void expect_totals_exact() {
    EXPECT_EQ(integer("SELECT bytes FROM totals"),
              integer("SELECT COALESCE(SUM(size), 0) FROM tiles"));
    EXPECT_EQ(integer("SELECT tiles FROM totals"), integer("SELECT COUNT(*) FROM tiles"));
    EXPECT_EQ(integer("SELECT pinned_bytes FROM totals"),
              integer("SELECT COALESCE(SUM(size), 0) FROM tiles WHERE pinned = 1"));
    EXPECT_EQ(integer("SELECT pinned_tiles FROM totals"),
              integer("SELECT COUNT(*) FROM tiles WHERE pinned = 1"));
    EXPECT_EQ(integer("SELECT COUNT(*) FROM tiles WHERE size <> length(payload)"), 0);
  }

 private:
  sqlite3* db_ = nullptr;
};

DiskCacheOptions options_for(const fs::path& dir, std::uint64_t max_bytes = 1ull << 30) {
  DiskCacheOptions o;
  o.dir = dir;
  o.max_bytes = max_bytes;
  o.touch_batch = 1000000;  // access times only on flush(), unless a test says otherwise
  o.touch_interval = std::chrono::hours(1);
  return o;
}

std::unique_ptr<DiskCache> open_ok(const DiskCacheOptions& o) {
  auto r = DiskCache::open(o);
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().to_string());
  return r.ok() ? std::move(r).value() : nullptr;
}

void expect_tile(DiskCache& cache, std::string_view ts, TileId id, const CachedTile& want) {
  auto got = cache.get(ts, id);
  ASSERT_TRUE(got.ok()) << got.error().to_string();
  ASSERT_TRUE(got->has_value()) << ts << "/" << id.to_string() << " missing";
  EXPECT_EQ((*got)->payload, want.payload);
  EXPECT_EQ((*got)->etag, want.etag);
  EXPECT_EQ((*got)->validated_unix, want.validated_unix);
}

bool present(DiskCache& cache, std::string_view ts, TileId id) {
  auto r = cache.contains(ts, id);
  EXPECT_TRUE(r.ok()) << r.error().to_string();
  return r.ok() && *r;
}

std::uint64_t file_size_or_zero(const fs::path& p) {
  std::error_code ec;
  const auto n = fs::file_size(p, ec);
  return ec ? 0 : n;
}

// ---- basics -------------------------------------------------------------------------------------

TEST(DiskCache, StoresAndReadsBackPayloadEtagAndValidationTime) {
  TempFolder dir;
  auto cache = open_ok(options_for(dir.path() / "nested" / "cache"));
  ASSERT_TRUE(cache);
  const CachedTile t = make_tile(25000, 1, "W/\"abc\"", 1712345678);
  ASSERT_TRUE(cache->put("https://example.org/earth.json", tid(3, 4), t).ok());
  expect_tile(*cache, "https://example.org/earth.json", tid(3, 4), t);
  const CachedTile empty = make_tile(0, 2, "");
  ASSERT_TRUE(cache->put("https://example.org/earth.json", tid(5, 4), empty).ok());
  expect_tile(*cache, "https://example.org/earth.json", tid(5, 4), empty);
  EXPECT_EQ(cache->path(), dir.path() / "nested" / "cache" / "cache.db");
}

TEST(DiskCache, MissesOnAnUnknownTileOrTileset) {
  TempFolder dir;
  auto cache = open_ok(options_for(dir.path()));
  ASSERT_TRUE(cache->put("a", tid(1), make_tile(10, 1)).ok());
  for (auto [ts, id] :
       {std::pair{"a", tid(2)}, std::pair{"b", tid(1)}, std::pair{"a", tid(1, 1)}}) {
    auto got = cache->get(ts, id);
    ASSERT_TRUE(got.ok());
    EXPECT_FALSE(got->has_value());
  }
  const DiskCacheStats s = cache->stats();
  EXPECT_EQ(s.misses, 3u);
  EXPECT_EQ(s.hits, 0u);
}

TEST(DiskCache, KeepsTilesetsApart) {
  TempFolder dir;
  auto cache = open_ok(options_for(dir.path()));
  const CachedTile a = make_tile(100, 1), b = make_tile(200, 2);
  ASSERT_TRUE(cache->put("a", tid(1), a).ok());
  ASSERT_TRUE(cache->put("b", tid(1), b).ok());
  expect_tile(*cache, "a", tid(1), a);
  expect_tile(*cache, "b", tid(1), b);
  RawDb raw(cache->path());
  EXPECT_EQ(raw.integer("SELECT COUNT(*) FROM tilesets"), 2);
}

TEST(DiskCache, KeepsEachTilesFreshnessLifetime) {
  TempFolder dir;
  CachedTile t = make_tile(100, 1);
  t.fresh_for = 60;
  {
    auto cache = open_ok(options_for(dir.path()));
    ASSERT_TRUE(cache->put("a", tid(1), t).ok());
    ASSERT_TRUE(cache->put("a", tid(2), make_tile(100, 2)).ok());
    ASSERT_TRUE(cache->set_validated("a", tid(2), 1800000000, kFreshForever).ok());
  }
  auto cache = open_ok(options_for(dir.path()));
  EXPECT_EQ(cache->get("a", tid(1)).value()->fresh_for, 60);
  const auto second = cache->get("a", tid(2)).value();
  EXPECT_EQ(second->fresh_for, kFreshForever);
  EXPECT_EQ(second->validated_unix, 1800000000);
}

TEST(DiskCache, UpgradesAVersion1CacheKeepingItsTiles) {
  TempFolder dir;
  const CachedTile t = make_tile(5000, 3);
  {
    auto cache = open_ok(options_for(dir.path()));
    ASSERT_TRUE(cache->put("a", tid(1), t).ok());
  }
  {  // what version 1 looked like: no fresh_for column
    RawDb raw(dir.path() / "cache.db");
    raw.exec("ALTER TABLE tiles DROP COLUMN fresh_for; PRAGMA user_version = 1");
  }
  auto cache = open_ok(options_for(dir.path()));
  expect_tile(*cache, "a", tid(1), t);
  EXPECT_EQ(cache->get("a", tid(1)).value()->fresh_for, -1);
  RawDb raw(cache->path());
  EXPECT_EQ(raw.integer("PRAGMA user_version"), 2);
  EXPECT_EQ(raw.text("PRAGMA integrity_check"), "ok");
}

TEST(DiskCache, CreatesTheSchemaInWalModeWithIncrementalVacuum) {
  TempFolder dir;
  auto cache = open_ok(options_for(dir.path()));
  ASSERT_TRUE(cache->put("a", tid(1), make_tile(10, 1)).ok());
  RawDb raw(cache->path());
  EXPECT_EQ(raw.text("PRAGMA journal_mode"), "wal");
  EXPECT_EQ(raw.integer("PRAGMA auto_vacuum"), 2);  // incremental
  EXPECT_EQ(raw.integer("PRAGMA page_size"), 16384);
  EXPECT_EQ(raw.integer("PRAGMA user_version"), DiskCache::kSchemaVersion);
  for (const char* name : {"tilesets", "tiles", "totals", "tiles_key", "tiles_lru"})
    EXPECT_EQ(
        raw.integer(std::string("SELECT COUNT(*) FROM sqlite_schema WHERE name = '") + name + "'"),
        1)
        << name;
  // The eviction query walks the (pinned, atime) index instead of sorting.
  EXPECT_NE(raw.text("EXPLAIN QUERY PLAN SELECT rowid, size FROM tiles WHERE pinned = 0 AND "
                     "rowid <> 1 ORDER BY atime, rowid LIMIT 64",
                     3)
                .find("tiles_lru"),
            std::string::npos);
}

// ---- totals -------------------------------------------------------------------------------------

TEST(DiskCache, TotalsStayExactThroughReplacePinRemoveAndReopen) {
  TempFolder dir;
  {
    auto cache = open_ok(options_for(dir.path()));
    for (std::uint32_t i = 0; i < 20; ++i)
      ASSERT_TRUE(cache->put("a", tid(i), make_tile(1000 + i, i)).ok());
    ASSERT_TRUE(cache->put("a", tid(3), make_tile(5000, 99)).ok());  // replace: size changes
    ASSERT_TRUE(cache->put("a", tid(4), make_tile(10, 98), /*pin=*/true).ok());
    ASSERT_TRUE(cache->set_pinned("a", tid(5), true).ok());
    ASSERT_TRUE(cache->remove("a", tid(6)).ok());
    ASSERT_TRUE(cache->remove("a", tid(600)).ok());  // absent: fine
    const DiskCacheStats s = cache->stats();
    EXPECT_EQ(s.tiles, 19u);
    EXPECT_EQ(s.pinned_tiles, 2u);
    EXPECT_EQ(s.pinned_bytes, 10u + 1005u);
    RawDb raw(cache->path());
    raw.expect_totals_exact();
    EXPECT_EQ(std::int64_t(s.bytes), raw.integer("SELECT SUM(size) FROM tiles"));
  }
  auto cache = open_ok(options_for(dir.path()));
  const DiskCacheStats s = cache->stats();
  EXPECT_EQ(s.tiles, 19u);
  EXPECT_EQ(s.pinned_tiles, 2u);
  RawDb raw(cache->path());
  EXPECT_EQ(std::int64_t(s.bytes), raw.integer("SELECT SUM(size) FROM tiles"));
  // The totals come from the totals row, not from a scan: change it behind the cache's back and
  // stats() follows.
  raw.exec("UPDATE totals SET tiles = 12345");
  EXPECT_EQ(cache->stats().tiles, 12345u);
}

TEST(DiskCache, TwoInstancesOnOneFolderShareTilesAndExactTotals) {
  TempFolder dir;
  auto one = open_ok(options_for(dir.path(), 400000));
  auto two = open_ok(options_for(dir.path(), 400000));
  std::vector<std::thread> writers;
  for (int w = 0; w < 2; ++w) {
    writers.emplace_back([&, w] {
      DiskCache& c = w == 0 ? *one : *two;
      for (std::uint32_t i = 0; i < 150; ++i) {
        const Status s = c.put("shared", tid(i, w), make_tile(1000 + (i * 37) % 3000, i * 2 + w));
        EXPECT_TRUE(s.ok()) << s.error().to_string();
      }
    });
  }
  for (auto& t : writers) t.join();
  // Each sees the other's tiles, and both see the same totals.
  expect_tile(*one, "shared", tid(149, 1), make_tile(1000 + (149 * 37) % 3000, 149 * 2 + 1));
  expect_tile(*two, "shared", tid(149, 0), make_tile(1000 + (149 * 37) % 3000, 149 * 2));
  EXPECT_EQ(one->stats().bytes, two->stats().bytes);
  EXPECT_LE(one->stats().bytes, 400000u);
  RawDb raw(one->path());
  raw.expect_totals_exact();
}

// ---- eviction -----------------------------------------------------------------------------------

TEST(DiskCache, EvictsLeastRecentlyStoredTilesToStayUnderTheCap) {
  TempFolder dir;
  auto cache = open_ok(options_for(dir.path(), 10000));
  for (std::uint32_t i = 0; i < 10; ++i) {
    ASSERT_TRUE(cache->put("a", tid(i), make_tile(3000, i)).ok());
    EXPECT_LE(cache->stats().bytes, 10000u);
  }
  // Room for three: the last three stay.
  for (std::uint32_t i = 0; i < 7; ++i) EXPECT_FALSE(present(*cache, "a", tid(i))) << i;
  for (std::uint32_t i = 7; i < 10; ++i) EXPECT_TRUE(present(*cache, "a", tid(i))) << i;
  const DiskCacheStats s = cache->stats();
  EXPECT_EQ(s.evicted, 7u);
  EXPECT_EQ(s.tiles, 3u);
  EXPECT_EQ(s.bytes, 9000u);
}

TEST(DiskCache, FlushedAccessTimesSteerEviction) {
  TempFolder dir;
  auto cache = open_ok(options_for(dir.path(), 9000));
  for (std::uint32_t i = 0; i < 3; ++i)
    ASSERT_TRUE(cache->put("a", tid(i), make_tile(3000, i)).ok());
  auto hit = cache->get("a", tid(0));  // 0 is now the most recently used
  ASSERT_TRUE(hit.ok() && hit->has_value());
  ASSERT_TRUE(cache->flush().ok());
  ASSERT_TRUE(cache->put("a", tid(3), make_tile(3000, 3)).ok());
  EXPECT_TRUE(present(*cache, "a", tid(0)));
  EXPECT_FALSE(present(*cache, "a", tid(1)));
  EXPECT_TRUE(present(*cache, "a", tid(2)));
  ASSERT_TRUE(cache->put("a", tid(4), make_tile(3000, 4)).ok());
  EXPECT_TRUE(present(*cache, "a", tid(0)));
  EXPECT_FALSE(present(*cache, "a", tid(2)));
}

TEST(DiskCache, AccessTimesRecordedByOneInstanceSteerAnothersEviction) {
  TempFolder dir;
  auto reader = open_ok(options_for(dir.path(), 9000));
  auto writer = open_ok(options_for(dir.path(), 9000));
  for (std::uint32_t i = 0; i < 3; ++i)
    ASSERT_TRUE(writer->put("a", tid(i), make_tile(3000, i)).ok());
  auto hit = reader->get("a", tid(0));
  ASSERT_TRUE(hit.ok() && hit->has_value());
  ASSERT_TRUE(reader->flush().ok());
  ASSERT_TRUE(writer->put("a", tid(3), make_tile(3000, 3)).ok());
  EXPECT_TRUE(present(*writer, "a", tid(0)));
  EXPECT_FALSE(present(*writer, "a", tid(1)));
}

TEST(DiskCache, ManyHitsWriteNothingUntilFlushed) {
  TempFolder dir;
  auto cache = open_ok(options_for(dir.path()));
  for (std::uint32_t i = 0; i < 50; ++i)
    ASSERT_TRUE(cache->put("a", tid(i), make_tile(2000, i)).ok());
  RawDb raw(cache->path());
  const std::int64_t atimes_before = raw.integer("SELECT SUM(atime) FROM tiles");
  const std::uint64_t writes_before = cache->stats().write_transactions;
  const fs::path wal = cache->path().string() + "-wal";
  const auto wal_size = file_size_or_zero(wal);
  const auto db_size = file_size_or_zero(cache->path());
  for (int round = 0; round < 20; ++round)
    for (std::uint32_t i = 0; i < 50; ++i) ASSERT_TRUE(cache->get("a", tid(i)).ok());
  EXPECT_EQ(cache->stats().hits, 1000u);
  EXPECT_EQ(cache->stats().write_transactions, writes_before);
  EXPECT_EQ(raw.integer("SELECT SUM(atime) FROM tiles"), atimes_before);
  EXPECT_EQ(file_size_or_zero(wal), wal_size);
  EXPECT_EQ(file_size_or_zero(cache->path()), db_size);
  ASSERT_TRUE(cache->flush().ok());
  EXPECT_EQ(cache->stats().write_transactions, writes_before + 1);  // one transaction for all
  EXPECT_GT(raw.integer("SELECT SUM(atime) FROM tiles"), atimes_before);
  ASSERT_TRUE(cache->flush().ok());  // nothing pending: no transaction
  EXPECT_EQ(cache->stats().write_transactions, writes_before + 1);
}

TEST(DiskCache, WritesAccessTimesOnceABatchIsFull) {
  TempFolder dir;
  DiskCacheOptions o = options_for(dir.path());
  o.touch_batch = 10;
  auto cache = open_ok(o);
  for (std::uint32_t i = 0; i < 10; ++i)
    ASSERT_TRUE(cache->put("a", tid(i), make_tile(100, i)).ok());
  const std::uint64_t writes = cache->stats().write_transactions;
  for (std::uint32_t i = 0; i < 9; ++i) ASSERT_TRUE(cache->get("a", tid(i)).ok());
  EXPECT_EQ(cache->stats().write_transactions, writes);
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(cache->get("a", tid(0)).ok());  // same tile: one entry
  EXPECT_EQ(cache->stats().write_transactions, writes);
  ASSERT_TRUE(cache->get("a", tid(9)).ok());
  EXPECT_EQ(cache->stats().write_transactions, writes + 1);
}

TEST(DiskCache, WritesAccessTimesOnceTheIntervalHasPassed) {
  TempFolder dir;
  DiskCacheOptions o = options_for(dir.path());
  o.touch_interval = std::chrono::milliseconds(50);
  auto cache = open_ok(o);
  ASSERT_TRUE(cache->put("a", tid(0), make_tile(100, 0)).ok());
  const std::uint64_t writes = cache->stats().write_transactions;
  ASSERT_TRUE(cache->get("a", tid(0)).ok());
  EXPECT_EQ(cache->stats().write_transactions, writes);
  std::this_thread::sleep_for(std::chrono::milliseconds(80));
  ASSERT_TRUE(cache->get("a", tid(0)).ok());
  EXPECT_EQ(cache->stats().write_transactions, writes + 1);
}

TEST(DiskCache, WritesPendingAccessTimesOnDestruction) {
  TempFolder dir;
  std::int64_t before = 0;
  fs::path db;
  {
    auto cache = open_ok(options_for(dir.path()));
    db = cache->path();
    ASSERT_TRUE(cache->put("a", tid(0), make_tile(100, 0)).ok());
    before = RawDb(db).integer("SELECT atime FROM tiles");
    ASSERT_TRUE(cache->get("a", tid(0)).ok());
  }
  EXPECT_GT(RawDb(db).integer("SELECT atime FROM tiles"), before);
}

TEST(DiskCache, PinnedTilesAreNeverEvicted) {
  TempFolder dir;
  auto cache = open_ok(options_for(dir.path(), 10000));
  ASSERT_TRUE(cache->put("a", tid(0), make_tile(3000, 0), /*pin=*/true).ok());
  for (std::uint32_t i = 1; i < 20; ++i)
    ASSERT_TRUE(cache->put("a", tid(i), make_tile(3000, i)).ok());
  EXPECT_TRUE(present(*cache, "a", tid(0)));
  EXPECT_EQ(cache->stats().pinned_bytes, 3000u);
  // Refreshing a pinned tile without pin keeps it pinned.
  ASSERT_TRUE(cache->put("a", tid(0), make_tile(3000, 100)).ok());
  EXPECT_EQ(cache->stats().pinned_tiles, 1u);
  // Unpinned, it ages out like any other.
  ASSERT_TRUE(cache->set_pinned("a", tid(0), false).ok());
  for (std::uint32_t i = 20; i < 24; ++i)
    ASSERT_TRUE(cache->put("a", tid(i), make_tile(3000, i)).ok());
  EXPECT_FALSE(present(*cache, "a", tid(0)));
  const Status missing = cache->set_pinned("a", tid(0), true);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, ErrorCode::not_found);
}

TEST(DiskCache, GetWithPinHandsOutAHitPinnedThatAnotherInstancesEvictionsKeep) {
  TempFolder dir;
  auto mine = open_ok(options_for(dir.path(), 10000));
  auto other = open_ok(options_for(dir.path(), 10000));
  const CachedTile t = make_tile(3000, 7);
  ASSERT_TRUE(mine->put("a", tid(0), t).ok());
  auto got = mine->get("a", tid(0), /*pin=*/true);
  ASSERT_TRUE(got.ok()) << got.error().to_string();
  ASSERT_TRUE(got->has_value());
  EXPECT_TRUE((*got)->pinned);
  EXPECT_EQ((*got)->payload, t.payload);
  EXPECT_EQ(mine->stats().hits, 1u);
  EXPECT_EQ(mine->stats().pinned_tiles, 1u);
  for (std::uint32_t i = 1; i < 20; ++i)
    ASSERT_TRUE(other->put("a", tid(i), make_tile(3000, i)).ok());
  EXPECT_TRUE(present(*mine, "a", tid(0)));
  // A miss pins nothing, and a tile already pinned is read without a write.
  auto miss = mine->get("a", tid(99), true);
  ASSERT_TRUE(miss.ok());
  EXPECT_FALSE(miss->has_value());
  EXPECT_EQ(mine->stats().misses, 1u);
  const auto writes = mine->stats().write_transactions;
  auto again = mine->get("a", tid(0), true);
  ASSERT_TRUE(again.ok() && again->has_value());
  EXPECT_TRUE((*again)->pinned);
  EXPECT_EQ(mine->stats().write_transactions, writes);
  RawDb raw(mine->path());
  raw.expect_totals_exact();
}

// Another process evicts the tile at the worst moment: after this one has read it, just before it
// takes the write lock to pin it (fault::before_write_lock). Read then pinned in two steps, the
// pin finds no row; get(..., pin = true) is a miss instead, never a tile it could not keep.
TEST(DiskCache, GetWithPinIsAMissWhenAnotherProcessEvictsTheTileJustBeforeThePin) {
  TempFolder dir;
  DiskCacheOptions o = options_for(dir.path(), 10000);
  o.vfs = fault::register_vfs();
  auto mine = open_ok(o);
  auto other = open_ok(options_for(dir.path(), 3000));  // room for one tile: evicts all others
  ASSERT_TRUE(mine && other);
  std::uint32_t filler = 1000;
  const auto evict_before_write_lock = [&] {
    fault::set_before_write_lock([&] {
      const std::uint32_t x = filler++;
      ASSERT_TRUE(other->put("b", tid(x), make_tile(3000, x)).ok());
    });
  };

  // The two-step way loses the race (what `vts warm` beside `vts cache serve` did).
  ASSERT_TRUE(mine->put("a", tid(1), make_tile(3000, 1)).ok());
  auto read = mine->get("a", tid(1));
  ASSERT_TRUE(read.ok() && read->has_value());
  evict_before_write_lock();
  const Status pinned = mine->set_pinned("a", tid(1), true);
  ASSERT_FALSE(pinned.ok()) << "the eviction did not fall between the read and the pin";
  EXPECT_EQ(pinned.error().code, ErrorCode::not_found);

  // In one transaction: a miss, nothing pinned, exact totals.
  ASSERT_TRUE(mine->put("a", tid(2), make_tile(3000, 2)).ok());
  evict_before_write_lock();
  auto got = mine->get("a", tid(2), /*pin=*/true);
  ASSERT_TRUE(got.ok()) << got.error().to_string();
  EXPECT_FALSE(got->has_value());
  EXPECT_EQ(mine->stats().pinned_tiles, 0u);
  EXPECT_FALSE(present(*mine, "a", tid(2)));
  fault::set_before_write_lock(nullptr);

  // Evictions after the pin's transaction instead keep the tile.
  ASSERT_TRUE(mine->put("a", tid(3), make_tile(3000, 3)).ok());
  auto kept = mine->get("a", tid(3), true);
  ASSERT_TRUE(kept.ok() && kept->has_value());
  EXPECT_TRUE((*kept)->pinned);
  auto third = open_ok(options_for(dir.path(), 6000));  // room for the pinned tile and one more
  for (std::uint32_t x = 2000; x < 2003; ++x)
    ASSERT_TRUE(third->put("b", tid(x), make_tile(3000, x)).ok());
  EXPECT_TRUE(present(*mine, "a", tid(3)));
  EXPECT_EQ(mine->stats().pinned_tiles, 1u);
  RawDb raw(mine->path());
  raw.expect_totals_exact();
}

TEST(DiskCache, RefusesATileLargerThanTheCap) {
  TempFolder dir;
  auto cache = open_ok(options_for(dir.path(), 10000));
  ASSERT_TRUE(cache->put("a", tid(0), make_tile(5000, 0)).ok());
  const Status s = cache->put("a", tid(1), make_tile(10001, 1));
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, ErrorCode::too_large);
  EXPECT_NE(s.error().message.find("10001 bytes"), std::string::npos) << s.error().message;
  EXPECT_NE(s.error().message.find("cap"), std::string::npos) << s.error().message;
  EXPECT_NE(s.error().message.find("10000"), std::string::npos) << s.error().message;
  EXPECT_TRUE(present(*cache, "a", tid(0)));                       // nothing evicted for it
  EXPECT_TRUE(cache->put("a", tid(1), make_tile(10000, 1)).ok());  // exactly the cap fits
}

TEST(DiskCache, FailsClearlyWhenPinnedTilesFillTheCap) {
  TempFolder dir;
  auto cache = open_ok(options_for(dir.path(), 10000));
  ASSERT_TRUE(cache->put("a", tid(0), make_tile(4000, 0), true).ok());
  ASSERT_TRUE(cache->put("a", tid(1), make_tile(4000, 1), true).ok());
  ASSERT_TRUE(cache->put("a", tid(2), make_tile(2000, 2)).ok());
  const Status s = cache->put("a", tid(3), make_tile(3000, 3));
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, ErrorCode::too_large);
  EXPECT_NE(s.error().message.find("full of pinned tiles"), std::string::npos) << s.error().message;
  EXPECT_NE(s.error().message.find("10000"), std::string::npos) << s.error().message;
  // Nothing changed: the unpinned tile was not evicted in vain, the new one is not there.
  EXPECT_TRUE(present(*cache, "a", tid(2)));
  EXPECT_FALSE(present(*cache, "a", tid(3)));
  // Pinning the new tile would not fit either; replacing a pinned tile by a same-size one does.
  EXPECT_FALSE(cache->put("a", tid(3), make_tile(2001, 3), true).ok());
  EXPECT_TRUE(cache->put("a", tid(1), make_tile(4000, 11)).ok());
  EXPECT_TRUE(cache->put("a", tid(3), make_tile(2000, 3)).ok());  // evicts tile 2
  EXPECT_FALSE(present(*cache, "a", tid(2)));
  RawDb(cache->path()).expect_totals_exact();
}

TEST(DiskCache, ShrinksToASmallerCapOnOpen) {
  TempFolder dir;
  {
    auto cache = open_ok(options_for(dir.path(), 100000));
    for (std::uint32_t i = 0; i < 20; ++i)
      ASSERT_TRUE(cache->put("a", tid(i), make_tile(4000, i)).ok());
  }
  auto cache = open_ok(options_for(dir.path(), 20000));
  EXPECT_EQ(cache->stats().bytes, 20000u);
  EXPECT_EQ(cache->stats().evicted, 15u);
  EXPECT_TRUE(present(*cache, "a", tid(19)));
  EXPECT_FALSE(present(*cache, "a", tid(14)));
}

TEST(DiskCache, FileStaysNearTheCapUnderHeavyOverwriting) {
  TempFolder dir;
  const std::uint64_t cap = 4 << 20;
  const std::uint64_t bound = cap + cap / 8 + DiskCache::kFileSlackBytes;
  auto cache = open_ok(options_for(dir.path(), cap));
  const fs::path db = cache->path(), wal = db.string() + "-wal";
  std::uint64_t written = 0, largest = 0;
  std::uint64_t seed = 7;
  std::uint32_t i = 0;
  for (; written < 40ull << 20; ++i) {
    const std::size_t size = 8192 + splitmix(seed) % (32 * 1024);
    // Half new tiles, half overwrites of recent ones with a different size.
    const std::uint32_t x =
        (i % 2) ? i : (i > 100 ? i - 1 - std::uint32_t(splitmix(seed) % 100) : i);
    ASSERT_TRUE(cache->put("a", tid(x), make_tile(size, i)).ok());
    written += size;
    if (i % 10 == 0) {
      const std::uint64_t on_disk = file_size_or_zero(db) + file_size_or_zero(wal);
      largest = std::max(largest, on_disk);
      ASSERT_LE(on_disk, bound) << "after " << written << " bytes written";
    }
  }
  EXPECT_LE(cache->stats().bytes, cap);
  EXPECT_GT(cache->stats().bytes, cap - 64 * 1024);
  RecordProperty("largest_on_disk_bytes", std::to_string(largest));
  // Removing everything gives the space back (incremental vacuum, then the final checkpoint).
  for (std::uint32_t x = 0; x < i; ++x) ASSERT_TRUE(cache->remove("a", tid(x)).ok());
  EXPECT_EQ(cache->stats().bytes, 0u);
  cache.reset();
  RecordProperty("after_removing_all_bytes", std::to_string(file_size_or_zero(db)));
  EXPECT_LE(file_size_or_zero(db), (1u << 20) + (256u << 10));
}

// The log is checkpointed once it holds wal_checkpoint_bytes, and not before: with 8 MiB it grows
// past the default's 2 MiB, yet stays within 8 MiB and one transaction; every tile survives.
TEST(DiskCache, WalIsCheckpointedAtTheConfiguredSizeAndNotBefore) {
  TempFolder dir;
  const std::uint64_t wal_bytes = 8 << 20, tile_bytes = 40 << 10;
  auto o = options_for(dir.path());
  o.wal_checkpoint_bytes = wal_bytes;
  auto cache = open_ok(o);
  const fs::path wal = cache->path().string() + "-wal";
  std::uint64_t largest = 0;
  for (std::uint32_t i = 0; i < 600; ++i) {  // 24 MiB, one tile per transaction
    ASSERT_TRUE(cache->put("a", tid(i), make_tile(tile_bytes, i)).ok());
    largest = std::max(largest, file_size_or_zero(wal));
    ASSERT_LE(file_size_or_zero(wal), wal_bytes + 4 * tile_bytes) << "after tile " << i;
  }
  EXPECT_GT(largest, 6u << 20);  // not checkpointed at the default 2 MiB
  cache.reset();
  auto again = open_ok(options_for(dir.path()));
  for (std::uint32_t i = 0; i < 600; i += 97)
    expect_tile(*again, "a", tid(i), make_tile(tile_bytes, i));
  EXPECT_EQ(again->stats().tiles, 600u);
}

TEST(DiskCache, ExtraPragmasRunAfterTheCachesOwnAndABadOneFailsTheOpen) {
  TempFolder dir;
  auto o = options_for(dir.path());
  o.extra_pragmas = "PRAGMA cache_size = -8192; PRAGMA mmap_size = 1048576";
  {
    auto cache = open_ok(o);
    ASSERT_TRUE(cache->put("a", tid(1), make_tile(1000, 1)).ok());
    expect_tile(*cache, "a", tid(1), make_tile(1000, 1));
  }
  o.extra_pragmas = "PRAGMA no_such_thing = ; nonsense";
  auto bad = DiskCache::open(o);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().code, ErrorCode::invalid_argument);
  EXPECT_NE(bad.error().message.find("nonsense"), std::string::npos) << bad.error().message;
}

// ---- corruption ---------------------------------------------------------------------------------

TEST(DiskCache, DropsARowWhoseChecksumDoesNotMatch) {
  TempFolder dir;
  auto cache = open_ok(options_for(dir.path()));
  const CachedTile good = make_tile(25000, 1);
  ASSERT_TRUE(cache->put("a", tid(1), good).ok());
  ASSERT_TRUE(cache->put("a", tid(2), good).ok());
  {
    RawDb raw(cache->path());
    // One byte changed in the middle of the payload, size unchanged.
    const std::string byte = good.payload[12000] == 0x5a ? "X'a5'" : "X'5a'";
    raw.exec("UPDATE tiles SET payload = CAST(substr(payload, 1, 12000) || " + byte +
             " || substr(payload, 12002) AS BLOB) WHERE x = 1");
    EXPECT_EQ(raw.integer("SELECT length(payload) FROM tiles WHERE x = 1"), 25000);
    EXPECT_EQ(raw.integer("SELECT COUNT(*) FROM tiles WHERE payload = (SELECT payload FROM tiles "
                          "WHERE x = 2)"),
              1);
  }
  auto got = cache->get("a", tid(1));
  ASSERT_TRUE(got.ok()) << got.error().to_string();
  EXPECT_FALSE(got->has_value());
  DiskCacheStats s = cache->stats();
  EXPECT_EQ(s.corrupt_dropped, 1u);
  EXPECT_EQ(s.misses, 1u);
  EXPECT_EQ(s.tiles, 1u);
  RawDb raw(cache->path());
  EXPECT_EQ(raw.integer("SELECT COUNT(*) FROM tiles WHERE x = 1"), 0);
  raw.expect_totals_exact();
  expect_tile(*cache, "a", tid(2), good);  // its neighbour is fine
}

TEST(DiskCache, DropsARowWhosePayloadWasTruncated) {
  TempFolder dir;
  auto cache = open_ok(options_for(dir.path()));
  ASSERT_TRUE(cache->put("a", tid(1), make_tile(5000, 1)).ok());
  RawDb(cache->path()).exec("UPDATE tiles SET payload = substr(payload, 1, 4999)");
  auto contains = cache->contains("a", tid(1));
  ASSERT_TRUE(contains.ok());
  EXPECT_FALSE(*contains);
  EXPECT_EQ(cache->stats().corrupt_dropped, 1u);
  EXPECT_EQ(cache->stats().tiles, 0u);
}

TEST(DiskCache, VerifyChecksEveryRowAndDropsTheBadOnes) {
  TempFolder dir;
  auto cache = open_ok(options_for(dir.path()));
  for (std::uint32_t i = 0; i < 30; ++i)
    ASSERT_TRUE(cache->put("a", tid(i), make_tile(3000, i)).ok());
  RawDb(cache->path()).exec("UPDATE tiles SET payload = zeroblob(3000) WHERE x IN (3, 17)");
  auto report = cache->verify();
  ASSERT_TRUE(report.ok()) << report.error().to_string();
  EXPECT_EQ(report->integrity, "ok");
  EXPECT_EQ(report->rows_checked, 30u);
  EXPECT_EQ(report->rows_dropped, 2u);
  EXPECT_EQ(cache->stats().tiles, 28u);
  EXPECT_EQ(cache->stats().corrupt_dropped, 2u);
  EXPECT_FALSE(present(*cache, "a", tid(3)));
  EXPECT_TRUE(present(*cache, "a", tid(4)));
}

// ---- bad files ----------------------------------------------------------------------------------

TEST(DiskCache, RefusesAFileThatIsNotSqliteNamingIt) {
  TempFolder dir;
  std::ofstream(dir.path() / "cache.db") << std::string(8192, 'x');
  auto r = DiskCache::open(options_for(dir.path()));
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::corrupt);
  EXPECT_NE(r.error().message.find((dir.path() / "cache.db").string()), std::string::npos)
      << r.error().message;
  EXPECT_NE(r.error().message.find("not an SQLite database"), std::string::npos)
      << r.error().message;
}

TEST(DiskCache, RefusesANewerSchemaVersion) {
  TempFolder dir;
  { ASSERT_TRUE(open_ok(options_for(dir.path()))); }
  RawDb(dir.path() / "cache.db").exec("PRAGMA user_version = 99");
  auto r = DiskCache::open(options_for(dir.path()));
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::unsupported);
  EXPECT_NE(r.error().message.find("schema version 99"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find((dir.path() / "cache.db").string()), std::string::npos);
}

TEST(DiskCache, RefusesAnSqliteDatabaseThatIsNotACache) {
  TempFolder dir;
  RawDb(dir.path() / "cache.db").exec("CREATE TABLE photos(id INTEGER PRIMARY KEY, data BLOB)");
  auto r = DiskCache::open(options_for(dir.path()));
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::unsupported);
  EXPECT_NE(r.error().message.find("not a vtstream cache"), std::string::npos) << r.error().message;
}

TEST(DiskCache, RefusesAFolderThatIsAFile) {
  TempFolder dir;
  std::ofstream(dir.path() / "file") << "x";
  auto r = DiskCache::open(options_for(dir.path() / "file"));
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::io);
  EXPECT_NE(r.error().message.find((dir.path() / "file").string()), std::string::npos);
  auto zero = DiskCache::open(options_for(dir.path() / "c", 0));
  ASSERT_FALSE(zero.ok());
  EXPECT_EQ(zero.error().code, ErrorCode::invalid_argument);
}

// ---- full disk ----------------------------------------------------------------------------------

// The fault VFS (fault_vfs.hpp): writes fail with SQLITE_FULL after fault::writes_left more.

TEST(DiskCache, AFullDiskFailsThePutCleanlyAtEveryWriteAndReadsKeepWorking) {
  TempFolder dir;
  DiskCacheOptions o = options_for(dir.path(), 5 * 20000);
  o.vfs = fault::register_vfs();
  o.touch_batch = 1;  // every hit tries to write its access time: those writes fail too
  auto cache = open_ok(o);
  ASSERT_TRUE(cache);
  const CachedTile first = make_tile(20000, 1000);
  ASSERT_TRUE(cache->put("a", tid(1000), first, /*pin=*/true).ok());
  for (std::uint32_t i = 0; i < 5; ++i)
    ASSERT_TRUE(cache->put("a", tid(i), make_tile(20000, i)).ok());

  int failed_puts = 0;
  for (long n = 0;; ++n) {
    ASSERT_LT(n, 1000) << "the put never got through";
    const std::uint32_t x = 100 + std::uint32_t(n);
    const CachedTile t = make_tile(20000, x);
    fault::failures = 0;
    fault::writes_left = n;  // the (n+1)-th write from now on fails, and all after it
    const Status s = cache->put("a", tid(x), t);
    const bool hit_fault = fault::failures > 0;
    if (!s.ok()) {
      ++failed_puts;
      EXPECT_EQ(s.error().code, ErrorCode::io) << s.error().to_string();
      EXPECT_NE(s.error().message.find("disk full writing cache " + cache->path().string()),
                std::string::npos)
          << s.error().message;
      // The disk is still full: reads keep working (their access-time writes fail quietly).
      auto got = cache->get("a", tid(1000));
      ASSERT_TRUE(got.ok()) << got.error().to_string();
      EXPECT_TRUE(got->has_value());
      auto missing = cache->get("a", tid(x));
      ASSERT_TRUE(missing.ok()) << missing.error().to_string();
      EXPECT_FALSE(missing->has_value());
    }
    fault::writes_left = -1;  // space again
    {
      RawDb raw(cache->path());
      EXPECT_EQ(raw.text("PRAGMA integrity_check"), "ok") << "after failing write " << n;
      raw.expect_totals_exact();
    }
    auto report = cache->verify();
    ASSERT_TRUE(report.ok()) << report.error().to_string();
    EXPECT_EQ(report->rows_dropped, 0u);
    EXPECT_LE(cache->stats().bytes, o.max_bytes);
    if (s.ok()) {
      expect_tile(*cache, "a", tid(x), t);
      if (!hit_fault) break;  // the put needed no more than n writes: every write point was hit
    }
  }
  EXPECT_GT(failed_puts, 0);
  RecordProperty("failed_puts", failed_puts);
  expect_tile(*cache, "a", tid(1000), first);  // the pinned tile came through it all
}

}  // namespace
}  // namespace vts::client
