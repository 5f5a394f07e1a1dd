// TileCache and TileClient over real archives (built here) and a real disk cache: the network is
// played by a wrapper around the local archive source that holds answers until the test releases
// them (to observe merging, cancellation and ordering) and can corrupt or count them.
#include "vts/client/tile_cache.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <deque>
#include <filesystem>
#include <map>
#include <mutex>
#include <thread>

#include "vts/archive/pmtiles.hpp"
#include "vts/builder/builder.hpp"
#include "vts/client/tile_client.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/test/address_space.hpp"
#include "vts/test/clock.hpp"
#include "vts/test/forge.hpp"
#include "vts/test/temp_dir.hpp"

#include "fault_vfs.hpp"

namespace fs = std::filesystem;
using namespace vts::client;
using vts::TileId;

namespace {

using vts::test::TempDir;

fs::path build_cache_archive(const fs::path& out,
                             std::optional<vts::TexelRect> region = std::nullopt) {
  vts::BuildOptions o;
  o.synthetic = vts::SyntheticSpec{1000, 600, region, 2};
  o.output = out;
  o.threads = 1;
  auto r = vts::build_synthetic_pyramid(o);
  EXPECT_TRUE(r.ok()) << r.error().to_string();
  return out;
}

// The local source, as if remote: answers are queued until release(), can be corrupted, and
// If-None-Match is honoured (not_modified when the ETag matches).
class HeldSource final : public TileSource {
 public:
  explicit HeldSource(std::unique_ptr<TileSource> inner) : inner_(std::move(inner)) {}
  const SourceInfo& info() const override { return inner_->info(); }
  bool local() const override { return false; }
  Handle fetch(const SourceRequest& request, SourceCallback callback) override {
    std::lock_guard lock(mutex_);
    const Handle h = next_++;
    fetches_.push_back(request.id);
    held_.emplace(h, Held{request, std::move(callback)});
    order_.push_back(h);
    return h;
  }
  void cancel(Handle h) override {
    SourceCallback cb;
    {
      std::lock_guard lock(mutex_);
      auto it = held_.find(h);
      if (it == held_.end()) return;
      cb = std::move(it->second.callback);
      held_.erase(it);
      ++cancels_;
    }
    SourceTile t;
    t.kind = SourceTile::Kind::cancelled;
    cb(std::move(t));
  }
  // Answers held requests in (level, -urgency, arrival) order, like the fetcher; returns how many.
  int release(int max = 1 << 30) {
    int n = 0;
    while (n < max) {
      Held h;
      {
        std::lock_guard lock(mutex_);
        if (held_.empty()) break;
        auto best = held_.begin();
        for (auto it = held_.begin(); it != held_.end(); ++it) {
          const auto& a = it->second.request;
          const auto& b = best->second.request;
          if (a.level < b.level || (a.level == b.level && a.urgency > b.urgency)) best = it;
        }
        h = std::move(best->second);
        held_.erase(best);
      }
      inner_->fetch(h.request, [&](SourceTile&& t) {
        if (t.kind == SourceTile::Kind::ok && !h.request.if_none_match.empty() &&
            t.etag == h.request.if_none_match) {
          t = SourceTile{};
          t.kind = SourceTile::Kind::not_modified;
        }
        if (t.kind == SourceTile::Kind::ok && corrupt_ > 0) {
          --corrupt_;
          t.payload[t.payload.size() / 2] ^= 0x40;
        }
        h.callback(std::move(t));
      });
      ++n;
    }
    return n;
  }
  std::size_t held() {
    std::lock_guard lock(mutex_);
    return held_.size();
  }
  std::vector<TileId> fetches() {
    std::lock_guard lock(mutex_);
    return fetches_;
  }
  int cancels() {
    std::lock_guard lock(mutex_);
    return cancels_;
  }
  std::atomic<int> corrupt_{0};

 private:
  struct Held {
    SourceRequest request;
    SourceCallback callback;
  };
  std::unique_ptr<TileSource> inner_;
  std::mutex mutex_;
  Handle next_ = 1;
  std::map<Handle, Held> held_;
  std::deque<Handle> order_;
  std::vector<TileId> fetches_;
  int cancels_ = 0;
};

std::shared_ptr<HeldSource> held(const fs::path& archive) {
  auto s = open_source(archive.string());
  EXPECT_TRUE(s.ok()) << s.error().to_string();
  return std::make_shared<HeldSource>(std::move(*s));
}

std::vector<std::uint8_t> stored(const fs::path& archive, TileId id) {
  auto r = vts::archive::Reader::open(archive);
  auto p = (*r)->get(id);
  return {p->begin(), p->end()};
}

struct Got {
  std::mutex m;
  std::vector<PayloadResult> results;
  PayloadCallback callback() {
    return [this](PayloadResult&& r) {
      std::lock_guard lock(m);
      results.push_back(std::move(r));
    };
  }
  std::size_t size() {
    std::lock_guard lock(m);
    return results.size();
  }
};

// Answers held fetches until `got` has `n` results (gets with a disk cache reach the source
// from the disk thread, a moment later).
void drain(HeldSource& source, Got& got, std::size_t n) {
  for (int i = 0; i < 5000 && got.size() < n; ++i) {
    if (source.release() == 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
}

template <class T>
T take(vts::Result<T> r) {
  EXPECT_TRUE(r.ok()) << r.error().to_string();
  return std::move(*r);
}

TileCacheOptions with_disk(const fs::path& dir) {
  TileCacheOptions o;
  o.disk = DiskCacheOptions{};
  o.disk->dir = dir;
  return o;
}

}  // namespace

TEST(TileCache, EveryTileComesByteExactFromTheSourceThenDiskThenRam) {
  TempDir d;
  const auto archive = build_cache_archive(d.path() / "a.pmtiles");
  auto reader = vts::archive::Reader::open(archive);
  std::vector<TileId> ids;
  ASSERT_TRUE((*reader)
                  ->for_each_entry([&](const vts::archive::Entry& e) {
                    for (std::uint64_t i = 0; i < e.run_length; ++i)
                      ids.push_back(*vts::archive::tile_id_to_zxy(e.tile_id + i));
                    return true;
                  })
                  .ok());
  ASSERT_GT(ids.size(), 10u);
  for (const auto expected_from :
       {PayloadResult::From::network, PayloadResult::From::disk, PayloadResult::From::ram}) {
    // A new cache over the same folder for the disk pass; the same one for the RAM pass.
    static std::unique_ptr<TileCache> cache;
    static std::shared_ptr<HeldSource> source;
    if (expected_from != PayloadResult::From::ram) {
      cache.reset();
      source = held(archive);
      auto c = TileCache::create(source, with_disk(d.path() / "cache"));
      ASSERT_TRUE(c.ok()) << c.error().to_string();
      cache = std::move(*c);
    }
    Got got;
    for (const auto id : ids) cache->get(id, {}, got.callback());
    drain(*source, got, ids.size());
    ASSERT_TRUE(cache->flush().ok());
    ASSERT_EQ(got.size(), ids.size());
    for (std::size_t i = 0; i < ids.size(); ++i) {
      const auto& r = got.results[i];
      ASSERT_EQ(r.kind, PayloadResult::Kind::ok);
      EXPECT_EQ(r.from, expected_from);
    }
    std::size_t exact = 0;
    for (const auto& r : got.results)
      for (const auto id : ids)
        if (r.tile->payload == stored(archive, id)) {
          ++exact;
          break;
        }
    EXPECT_EQ(exact, ids.size());
    if (expected_from != PayloadResult::From::network) {
      EXPECT_TRUE(source->fetches().empty());
    }
    if (expected_from == PayloadResult::From::ram) {
      cache.reset();
      source.reset();
    }
  }
}

TEST(TileCache, ConcurrentGetsOfOneTileAreMergedIntoOneFetch) {
  TempDir d;
  const auto archive = build_cache_archive(d.path() / "a.pmtiles");
  auto source = held(archive);
  auto cache = take(TileCache::create(source, {}));
  Got got;
  for (int i = 0; i < 5; ++i) cache->get(TileId{1, 1, 0}, {}, got.callback());
  EXPECT_EQ(source->held(), 1u);
  source->release();
  ASSERT_EQ(got.size(), 5u);
  for (const auto& r : got.results) {
    EXPECT_EQ(r.kind, PayloadResult::Kind::ok);
    EXPECT_EQ(r.tile->payload, stored(archive, TileId{1, 1, 0}));
  }
  EXPECT_EQ(source->fetches().size(), 1u);
}

TEST(TileCache, CancellingTheLastWaiterCancelsTheFetchButOthersKeepIt) {
  TempDir d;
  const auto archive = build_cache_archive(d.path() / "a.pmtiles");
  auto source = held(archive);
  auto cache = take(TileCache::create(source, {}));
  Got a, b;
  const auto ha = cache->get(TileId{2, 0, 0}, {}, a.callback());
  const auto hb = cache->get(TileId{2, 0, 0}, {}, b.callback());
  cache->cancel(ha);
  ASSERT_EQ(a.size(), 1u);
  EXPECT_EQ(a.results[0].kind, PayloadResult::Kind::cancelled);
  EXPECT_EQ(source->cancels(), 0);  // b still wants it
  cache->cancel(hb);
  EXPECT_EQ(b.results[0].kind, PayloadResult::Kind::cancelled);
  EXPECT_EQ(source->cancels(), 1);
  EXPECT_EQ(source->held(), 0u);
  EXPECT_EQ(cache->stats().cancelled, 2u);
}

TEST(TileCache, ACorruptPayloadIsRefetchedAndNeverCachedOrDelivered) {
  TempDir d;
  const auto archive = build_cache_archive(d.path() / "a.pmtiles");
  auto source = held(archive);
  auto cache = take(TileCache::create(source, with_disk(d.path() / "cache")));
  // One bad answer: refetched, then the good bytes.
  source->corrupt_ = 1;
  Got got;
  cache->get(TileId{0, 0, 0}, {}, got.callback());
  drain(*source, got, 1);
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got.results[0].kind, PayloadResult::Kind::ok);
  EXPECT_EQ(got.results[0].tile->payload, stored(archive, TileId{0, 0, 0}));
  EXPECT_EQ(cache->stats().corrupt_rejected, 1u);
  // Always bad: an error naming the tile after corrupt_retries re-fetches; nothing cached.
  source->corrupt_ = 100;
  Got bad;
  cache->get(TileId{1, 0, 0}, {}, bad.callback());
  drain(*source, bad, 1);
  ASSERT_EQ(bad.size(), 1u);
  ASSERT_EQ(bad.results[0].kind, PayloadResult::Kind::error);
  EXPECT_NE(bad.results[0].error->message.find("1/0/0"), std::string::npos);
  EXPECT_EQ(source->fetches().size(), 2u + 3u);
  ASSERT_TRUE(cache->flush().ok());
  EXPECT_EQ(cache->ram()->get(TileKey{cache->info().key, TileId{1, 0, 0}}), nullptr);
  auto row = cache->disk()->get(cache->info().key, TileId{1, 0, 0});
  ASSERT_TRUE(row.ok());
  EXPECT_FALSE(row->has_value());
}

// Tiles whose header contradicts the tileset (264 x 264 lossless): verified bytes of the wrong
// size or codec, written into the archive with the real writer.
struct ForgedArchive {
  fs::path good, forged;
  static constexpr TileId kSmall{2, 1, 1};  // 64 x 64
  static constexpr TileId kHuge{2, 2, 1};   // 8192 x 8192 declared (256 MiB), 8 KiB stored
  static constexpr TileId kBc1{2, 3, 2};    // 264 x 264, but bc1
  explicit ForgedArchive(const fs::path& dir)
      : good(dir / "good.pmtiles"), forged(dir / "f.pmtiles") {
    build_cache_archive(good);
    // 66 x 66 blocks of one byte value, framed as the builder's bc1 encoder frames its blocks.
    const std::vector<std::uint8_t> blocks(66u * 66u * 8u, 0x80);
    auto bc1 = vts::pack_tile(vts::CodecId::bc1, 264, 264, blocks, 3);
    EXPECT_TRUE(bc1.ok());
    vts::test::copy_archive_replacing(good, forged,
                                      {{kSmall, vts::test::flat_tile(64, 64, 7)},
                                       {kHuge, vts::test::flat_tile(8192, 8192, 7)},
                                       {kBc1, *bc1}});
  }
};

TEST(TileCache, ATileThatContradictsTheTilesetIsRefusedNeverCachedAndCounted) {
  TempDir d;
  ForgedArchive a(d.path());
  auto source = take(open_source(a.forged.string()));
  ASSERT_EQ(source->info().info.geometry.stored_size(), 264u);
  auto cache = take(TileCache::create(std::move(source), with_disk(d.path() / "cache")));
  const std::pair<TileId, const char*> cases[] = {{ForgedArchive::kSmall, "64x64"},
                                                  {ForgedArchive::kHuge, "8192x8192"},
                                                  {ForgedArchive::kBc1, "codec bc1"}};
  for (const auto& [id, says] : cases) {
    for (int again = 0; again < 2; ++again) {  // the second get finds nothing cached either
      Got got;
      cache->get(id, {}, got.callback());
      ASSERT_TRUE(vts::test::wait_until([&] { return got.size() == 1; }));
      const PayloadResult& r = got.results[0];
      ASSERT_EQ(r.kind, PayloadResult::Kind::error) << id.to_string();
      EXPECT_EQ(r.error->code, vts::ErrorCode::corrupt) << r.error->to_string();
      EXPECT_NE(r.error->message.find(says), std::string::npos) << r.error->message;
      EXPECT_NE(r.error->message.find(id.to_string()), std::string::npos) << r.error->message;
    }
  }
  Got fine;
  cache->get(TileId{2, 0, 0}, {}, fine.callback());
  ASSERT_TRUE(vts::test::wait_until([&] { return fine.size() == 1; }));
  EXPECT_EQ(fine.results[0].kind, PayloadResult::Kind::ok);
  ASSERT_TRUE(cache->flush().ok());
  for (const auto& c : cases) {
    EXPECT_EQ(cache->ram()->get(TileKey{cache->info().key, c.first}), nullptr);
    auto row = cache->disk()->get(cache->info().key, c.first);
    ASSERT_TRUE(row.ok());
    EXPECT_FALSE(row->has_value()) << c.first.to_string() << " reached the disk";
  }
  EXPECT_TRUE(cache->disk()->get(cache->info().key, TileId{2, 0, 0})->has_value());
  // 3 tiles x 2 gets x (1 + corrupt_retries) fetches, each refused.
  EXPECT_EQ(cache->stats().mismatch_rejected, 3u * 2u * 3u);
  EXPECT_EQ(cache->stats().corrupt_rejected, 3u * 2u * 3u);
}

TEST(TileCache, ADiskRowThatContradictsTheTilesetIsDroppedAndFetchedAgain) {
  TempDir d;
  ForgedArchive a(d.path());
  auto source = take(open_source(a.good.string()));
  const std::string key = source->info().key;
  {  // a cache folder that holds a forged row (another writer, an older version...)
    DiskCacheOptions o;
    o.dir = d.path() / "cache";
    auto disk = take(DiskCache::open(o));
    CachedTile forged;
    forged.payload = vts::test::flat_tile(64, 64, 7);
    forged.etag = "\"forged\"";
    ASSERT_TRUE(disk->put(key, ForgedArchive::kSmall, forged).ok());
  }
  auto cache = take(TileCache::create(std::move(source), with_disk(d.path() / "cache")));
  Got got;
  cache->get(ForgedArchive::kSmall, {}, got.callback());
  ASSERT_TRUE(vts::test::wait_until([&] { return got.size() == 1; }));
  ASSERT_EQ(got.results[0].kind, PayloadResult::Kind::ok);
  EXPECT_EQ(got.results[0].from, PayloadResult::From::network);
  EXPECT_EQ(got.results[0].tile->payload, stored(a.good, ForgedArchive::kSmall));
  EXPECT_EQ(cache->stats().mismatch_rejected, 1u);
  EXPECT_EQ(cache->stats().disk_hits, 0u);
  ASSERT_TRUE(cache->flush().ok());
  auto row = cache->disk()->get(key, ForgedArchive::kSmall);
  ASSERT_TRUE(row.ok() && row->has_value());
  EXPECT_EQ((*row)->payload, stored(a.good, ForgedArchive::kSmall)) << "the row was replaced";
}

// Writes that fail (a full disk, here SQLite's own SQLITE_FULL from the fault VFS) are reported:
// the first at once, then at most one line per interval counting the ones in between; the disk
// is marked failing until a tile is stored again, which is reported too.
TEST(TileCache, FailingDiskWritesAreReportedRateLimitedAndTheStateRecovers) {
  TempDir d;
  const auto archive = build_cache_archive(d.path() / "a.pmtiles");
  vts::test::FakeClock clock;
  std::mutex m;
  std::vector<std::string> lines;
  TileCacheOptions o = with_disk(d.path() / "cache");
  o.disk->vfs = fault::register_vfs();
  ASSERT_NE(o.disk->vfs, "");
  o.disk_report = [&](const std::string& line) {
    std::lock_guard lock(m);
    lines.push_back(line);
  };
  o.disk_report_interval = std::chrono::minutes(1);
  o.clock = clock.fn();
  auto cache = take(TileCache::create(take(open_source(archive.string())), o));
  auto get = [&](TileId id) {
    Got got;
    cache->get(id, {}, got.callback());
    EXPECT_TRUE(vts::test::wait_until([&] { return got.size() == 1; }));
    EXPECT_EQ(got.results[0].kind, PayloadResult::Kind::ok) << "gets never fail for the disk";
    (void)cache->flush();  // waits for the queued write (its own access-time write may fail)
  };
  auto reported = [&] {
    std::lock_guard lock(m);
    return lines;
  };
  get(TileId{2, 0, 0});
  EXPECT_FALSE(cache->disk_health().failing);
  EXPECT_TRUE(reported().empty());

  fault::writes_left = 0;  // the disk is full
  for (std::uint32_t x = 1; x < 4; ++x) get(TileId{2, x, 0});
  DiskHealth h = cache->disk_health();
  EXPECT_TRUE(h.failing);
  EXPECT_GE(h.failed_writes, 3u);
  ASSERT_TRUE(h.last_error);
  EXPECT_NE(h.last_error->message.find("disk full"), std::string::npos) << h.last_error->message;
  EXPECT_GE(cache->stats().disk_write_errors, 3u);
  ASSERT_EQ(reported().size(), 1u) << "one line for the first failure, the rest held back";
  EXPECT_NE(reported()[0].find("disk cache write failed"), std::string::npos) << reported()[0];
  EXPECT_NE(reported()[0].find("disk full"), std::string::npos) << reported()[0];

  clock.advance(std::chrono::seconds(61));
  get(TileId{2, 0, 1});
  ASSERT_EQ(reported().size(), 2u);
  EXPECT_NE(reported()[1].find("disk cache writes failing: "), std::string::npos) << reported()[1];
  EXPECT_NE(reported()[1].find(" failed writes since the last report"), std::string::npos);
  get(TileId{2, 1, 1});
  EXPECT_EQ(reported().size(), 2u) << "within the interval: counted, not printed";

  fault::writes_left = -1;  // space again
  get(TileId{2, 2, 1});
  EXPECT_FALSE(cache->disk_health().failing);
  ASSERT_EQ(reported().size(), 3u);
  EXPECT_NE(reported()[2].find("disk cache writes succeed again"), std::string::npos)
      << reported()[2];
  auto row = cache->disk()->get(cache->info().key, TileId{2, 2, 1});
  ASSERT_TRUE(row.ok() && row->has_value()) << "stored once the disk had room";
}

// `vts warm` (pinned gets) beside `vts cache serve` on one folder: the other process evicts the
// tile between this one's disk read and its pin (fault::before_write_lock runs that eviction just
// before this cache's next write transaction). Read and pinned in two steps, the pin failed with
// "... is not in cache" (which ends a warm) and the tile was gone from the disk; taken in one
// transaction, the read is a miss, the tile comes from the source and is stored pinned.
TEST(TileCache, APinnedGetKeepsTheTileWhenAnotherProcessEvictsItBeforeThePin) {
  TempDir d;
  const auto archive = build_cache_archive(d.path() / "a.pmtiles");
  TileCacheOptions o = with_disk(d.path() / "cache");
  o.ram_bytes = 0;  // as `vts warm`: every get reads the disk
  o.disk->vfs = fault::register_vfs();
  ASSERT_NE(o.disk->vfs, "");
  auto cache = take(TileCache::create(take(open_source(archive.string())), o));
  const TileId id{2, 1, 1};
  auto get = [&](bool pin) {
    Got got;
    GetOptions go;
    go.pin = pin;
    cache->get(id, go, got.callback());
    EXPECT_TRUE(vts::test::wait_until([&] { return got.size() == 1; }));
    EXPECT_EQ(got.results[0].kind, PayloadResult::Kind::ok);
    EXPECT_EQ(got.results[0].tile->payload, stored(archive, id));
    EXPECT_TRUE(cache->flush().ok());
  };
  get(false);  // on disk, not pinned
  ASSERT_TRUE(cache->disk()->contains(cache->info().key, id).value());

  DiskCacheOptions other_options;
  other_options.dir = d.path() / "cache";
  other_options.max_bytes = 1000;  // each put evicts every other unpinned tile
  auto other = take(DiskCache::open(other_options));
  CachedTile filler;
  filler.payload.assign(1000, 0x5a);
  fault::set_before_write_lock([&] {
    ASSERT_TRUE(other->put("another tileset", TileId{0, 0, 0}, filler).ok());
  });
  get(true);
  fault::set_before_write_lock(nullptr);

  EXPECT_FALSE(cache->last_disk_error()) << cache->last_disk_error()->to_string();
  auto row = cache->disk()->get(cache->info().key, id);
  ASSERT_TRUE(row.ok()) << row.error().to_string();
  ASSERT_TRUE(row->has_value()) << "the tile was evicted between the read and the pin";
  EXPECT_TRUE((*row)->pinned);
  EXPECT_EQ(cache->disk()->stats().pinned_tiles, 1u);
}

TEST(TileCache, AbsentTilesAreRememberedAndNotAskedForAgain) {
  TempDir d;
  // Sparse: only the top-left finest tile exists.
  const auto archive = build_cache_archive(d.path() / "s.pmtiles", vts::TexelRect{0, 0, 256, 256});
  auto source = held(archive);
  auto cache = take(TileCache::create(source, {}));
  Got got;
  cache->get(TileId{2, 3, 2}, {}, got.callback());
  source->release();
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got.results[0].kind, PayloadResult::Kind::absent);
  EXPECT_EQ(cache->get(TileId{2, 3, 2}, {}, got.callback()), 0u);  // answered inline
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got.results[1].kind, PayloadResult::Kind::absent);
  EXPECT_EQ(source->fetches().size(), 1u);
}

TEST(TileCache, AStaleTileIsServedAtOnceThenRevalidatedInTheBackground) {
  TempDir d;
  const auto archive = build_cache_archive(d.path() / "a.pmtiles");
  auto source = held(archive);
  TileCacheOptions o;
  o.revalidate_after = std::chrono::seconds(0);
  auto cache = take(TileCache::create(source, o));
  Got got;
  cache->get(TileId{0, 0, 0}, {}, got.callback());
  source->release();
  ASSERT_EQ(got.size(), 1u);
  // The RAM hit is delivered inline, and a revalidation (with the ETag) is queued.
  cache->get(TileId{0, 0, 0}, {}, got.callback());
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got.results[1].from, PayloadResult::From::ram);
  EXPECT_EQ(source->held(), 1u);
  source->release();
  EXPECT_EQ(cache->stats().revalidations, 1u);
  EXPECT_EQ(cache->stats().not_modified, 1u);
}

TEST(TileCache, DiskReadsAreNotBlockedByAStuckNetwork) {
  TempDir d;
  const auto archive = build_cache_archive(d.path() / "a.pmtiles");
  {
    auto source = held(archive);
    auto cache = take(TileCache::create(source, with_disk(d.path() / "cache")));
    Got got;
    cache->get(TileId{0, 0, 0}, {}, got.callback());
    drain(*source, got, 1);
    ASSERT_TRUE(cache->flush().ok());
  }
  auto source = held(archive);
  TileCacheOptions o = with_disk(d.path() / "cache");
  o.ram_bytes = 0;
  auto cache = take(TileCache::create(source, o));
  // Many network requests stay unanswered ...
  Got stuck;
  for (std::uint32_t x = 0; x < 4; ++x) cache->get(TileId{2, x, 1}, {}, stuck.callback());
  // ... while a tile on disk is delivered.
  Got got;
  cache->get(TileId{0, 0, 0}, {}, got.callback());
  vts::test::wait_until([&] { return got.size() > 0; });
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got.results[0].from, PayloadResult::From::disk);
  EXPECT_EQ(stuck.size(), 0u);
  source->release();
}

TEST(TileClient, EveryTileAskedForIsDecodedExactlyAndNoOtherIsFetched) {
  TempDir d;
  const auto archive = build_cache_archive(d.path() / "a.pmtiles");
  auto source = held(archive);
  auto client = take(TileClient::create(source, {}));
  // No ancestor is added: the caller's wanted list has them (the renderer's TileStream).
  client->request(TileId{2, 3, 1}, 1.0);
  client->request(TileId{2, 0, 2}, 5.0);
  client->request(TileId{1, 1, 0}, 0.0);
  client->request(TileId{0, 0, 0}, 0.0);
  EXPECT_EQ(source->held(), 4u);
  EXPECT_EQ(client->stats().requested, 4u);
  source->release();
  for (int i = 0; i < 4; ++i) {
    auto e = client->wait(std::chrono::seconds(5));
    ASSERT_TRUE(e.has_value());
    ASSERT_EQ(e->kind, TileEvent::Kind::decoded);
    auto expected = vts::decode_tile(stored(archive, e->id));
    ASSERT_TRUE(expected.ok());
    EXPECT_EQ(e->image.pixels, expected->pixels) << e->id.to_string();
  }
  // What was asked for, once each, and nothing else.
  auto fetched = source->fetches();
  std::sort(fetched.begin(), fetched.end());
  EXPECT_EQ(fetched, (std::vector<TileId>{{0, 0, 0}, {1, 1, 0}, {2, 0, 2}, {2, 3, 1}}));
  // Delivered tiles are not asked for again until released.
  client->request(TileId{2, 3, 1});
  client->request(TileId{2, 2, 1});
  EXPECT_EQ(source->held(), 1u);
  client->release(TileId{2, 3, 1});
  client->request(TileId{2, 3, 1});  // delivered again, from the RAM cache
  auto again = client->wait(std::chrono::seconds(5));
  ASSERT_TRUE(again.has_value());
  EXPECT_EQ(again->id, (TileId{2, 3, 1}));
  EXPECT_EQ(again->from, PayloadResult::From::ram);
  EXPECT_EQ(source->held(), 1u);
  // The root is pinned in RAM.
  EXPECT_EQ(client->cache().ram()->stats().pinned_bytes > 0, true);
}

TEST(TileClient, ADecodeThreadTheSystemRefusesIsAnIoErrorNotAnAbort) {
  if (vts::test::sanitized()) GTEST_SKIP() << "sanitizers reserve the address space";
  TempDir d;
  const auto archive = build_cache_archive(d.path() / "a.pmtiles");
  auto source = held(archive);
  TileClientOptions o;
  o.decode_threads = 512;  // some start, then one is refused
  vts::Result<std::unique_ptr<TileClient>> client = vts::make_error(vts::ErrorCode::internal, "");
  {
    vts::test::AddressSpaceLimit limit(48u << 20);
    ASSERT_TRUE(limit.ok());
    client = TileClient::create(source, o);
  }
  ASSERT_FALSE(client.ok());
  EXPECT_EQ(client.error().code, vts::ErrorCode::io);
  EXPECT_NE(client.error().message.find("cannot start a thread (vts-decode)"), std::string::npos)
      << client.error().message;
}

TEST(TileClient, DecodedTilesWaitWithinTheirByteBudget) {
  TempDir d;
  const auto archive = build_cache_archive(d.path() / "a.pmtiles");
  auto source = held(archive);
  TileClientOptions o;
  o.decoded_bytes = 1;  // one tile at a time
  auto client = take(TileClient::create(source, o));
  for (std::uint32_t x = 0; x < 4; ++x) client->request(TileId{2, x, 0});
  source->release();
  vts::test::wait_until([&] { return client->stats().decoded >= 1; });
  const auto s = client->stats();
  EXPECT_EQ(s.decoded, 1u);  // the others wait for room
  int n = 0;
  while (auto e = client->wait(std::chrono::seconds(5))) {
    ++n;
    if (n == 4) break;
  }
  EXPECT_EQ(n, 4);
}

TEST(TileClient, CancelledTilesProduceNoEvent) {
  TempDir d;
  const auto archive = build_cache_archive(d.path() / "a.pmtiles");
  auto source = held(archive);
  auto client = take(TileClient::create(source, {}));
  client->request(TileId{2, 3, 2});
  client->request(TileId{1, 0, 1});
  client->cancel(TileId{2, 3, 2});
  source->release();
  auto e = client->wait(std::chrono::seconds(5));
  ASSERT_TRUE(e.has_value());
  EXPECT_EQ(e->id, (TileId{1, 0, 1}));
  EXPECT_FALSE(client->wait(std::chrono::milliseconds(100)).has_value());
  EXPECT_EQ(client->stats().cancelled, 1u);
}
