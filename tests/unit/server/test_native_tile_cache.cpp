// The RAM cache of native tiles: its bounds and eviction (NativeTileCache), and, through the real
// router, registry and archive files, that it never answers for an archive that changed.
#include "native_tile_cache.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <string>
#include <vector>

#include "vts/builder/builder.hpp"
#include "vts/server/router.hpp"
#include "vts/server/tileset_registry.hpp"
#include "vts/test/temp_dir.hpp"

namespace fs = std::filesystem;
using vts::http_detail::CachedTile;
using vts::http_detail::CachedTilePtr;
using vts::http_detail::NativeTileCache;

namespace {

CachedTilePtr tile_of(std::size_t bytes, std::uint64_t checksum = 0) {
  auto t = std::make_shared<CachedTile>();
  t->bytes.assign(bytes, std::uint8_t(checksum));
  t->checksum = checksum;
  return t;
}

TEST(NativeTileCache, KeepsTilesWithinItsByteCapAndEvictsTheLeastRecentlyUsed) {
  const std::size_t each = 1000 + NativeTileCache::kEntryOverhead;
  NativeTileCache cache(3 * each, /*shards=*/1);
  for (std::uint64_t id = 1; id <= 3; ++id) cache.insert(7, id, tile_of(1000, id));
  EXPECT_EQ(cache.size(), 3u);
  EXPECT_EQ(cache.bytes(), 3 * each);
  ASSERT_NE(cache.find(7, 1), nullptr);  // 1 is now the most recently used: 2 goes next
  cache.insert(7, 4, tile_of(1000, 4));
  EXPECT_EQ(cache.size(), 3u);
  EXPECT_LE(cache.bytes(), cache.capacity());
  EXPECT_EQ(cache.find(7, 2), nullptr) << "the least recently used tile was evicted";
  for (std::uint64_t id : {1, 3, 4}) {
    auto t = cache.find(7, id);
    ASSERT_NE(t, nullptr) << id;
    EXPECT_EQ(t->checksum, id);
  }
  EXPECT_EQ(cache.evictions.load(), 1u);
  EXPECT_EQ(cache.find(8, 1), nullptr) << "another generation's tile 1 is another key";
}

TEST(NativeTileCache, StaysWithinItsCapWhateverIsInsertedAndKeepsNoTileLargerThanAShard) {
  NativeTileCache cache(64 * 1024, /*shards=*/4);
  for (std::uint64_t id = 0; id < 500; ++id) {
    cache.insert(1, id, tile_of(100 + (id * 37) % 3000, id));
    ASSERT_LE(cache.bytes(), cache.capacity()) << "after tile " << id;
  }
  EXPECT_GT(cache.size(), 0u);
  cache.insert(1, 1000, tile_of(16 * 1024));  // over a quarter of the cap, with its overhead
  EXPECT_EQ(cache.find(1, 1000), nullptr);
  NativeTileCache none(0);
  none.insert(1, 1, tile_of(10));
  EXPECT_EQ(none.find(1, 1), nullptr) << "capacity 0 keeps nothing";
  EXPECT_EQ(none.bytes(), 0u);
}

TEST(NativeTileCache, ATileHandedOutOutlivesItsEviction) {
  NativeTileCache cache(1000 + NativeTileCache::kEntryOverhead, 1);
  cache.insert(1, 1, tile_of(1000, 5));
  CachedTilePtr held = cache.find(1, 1);
  cache.insert(1, 2, tile_of(1000, 6));
  EXPECT_EQ(cache.find(1, 1), nullptr);
  ASSERT_NE(held, nullptr);
  EXPECT_EQ(held->bytes.size(), 1000u);
  EXPECT_EQ(held->bytes[999], 5);
}

TEST(NativeTileCache, DropsTheTilesOfAGenerationAndOfGenerationsNoLongerServed) {
  NativeTileCache cache(1 << 20, 2);
  for (std::uint64_t g = 1; g <= 3; ++g)
    for (std::uint64_t id = 0; id < 10; ++id) cache.insert(g, id, tile_of(100));
  EXPECT_EQ(cache.erase_generation(2), 10u);
  EXPECT_EQ(cache.find(2, 3), nullptr);
  EXPECT_NE(cache.find(1, 3), nullptr);
  const std::vector<std::uint64_t> live = {3};
  EXPECT_EQ(cache.retain(live), 10u);
  EXPECT_EQ(cache.find(1, 3), nullptr);
  EXPECT_NE(cache.find(3, 3), nullptr);
  EXPECT_EQ(cache.size(), 10u);
  EXPECT_EQ(cache.bytes(), 10 * (100 + NativeTileCache::kEntryOverhead));
  EXPECT_EQ(cache.invalidations.load(), 20u);
}

// ---------------------------------------------------------------------------------------------
// Through the router: a served archive, rewritten in place with another one's bytes.

std::string read_file(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

class TileCacheRouter : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new vts::test::TempDir("vts-tile-cache-test");
    build(*dir_ / "src_a.pmtiles", vts::CodecId::lossless);
    build(*dir_ / "src_b.pmtiles", vts::CodecId::bc1);
  }
  static void TearDownTestSuite() { delete dir_; }
  static void build(const fs::path& out, vts::CodecId codec) {
    vts::BuildOptions o;
    o.synthetic = vts::SyntheticSpec{600, 300, std::nullopt, 2};
    o.output = out;
    o.threads = 1;
    o.codec = codec;
    auto r = vts::build_synthetic_pyramid(o);
    ASSERT_TRUE(r.ok()) << r.error().to_string();
  }

  void SetUp() override {
    served_ = dir_->path() / "served" / "t.pmtiles";
    fs::create_directories(served_.parent_path());
    fs::copy_file(*dir_ / "src_a.pmtiles", served_, fs::copy_options::overwrite_existing);
    ASSERT_TRUE(registry_.load({served_}).ok());
    config_.tile_cache = std::make_shared<NativeTileCache>(16 << 20);
  }

  vts::HttpResponse get(std::string_view target, std::string_view inm = {}) {
    req_.method = vts::HttpMethod::get;
    req_.target = target;
    req_.if_none_match = inm;
    return vts::route(req_, registry_, config_);
  }
  static std::string body(const vts::HttpResponse& r) {
    return std::string(reinterpret_cast<const char*>(r.view.data()), r.view.size());
  }
  // Overwrites the served file in place (same inode) with the other archive's bytes.
  void rewrite_in_place() {
    const std::string b = read_file(*dir_ / "src_b.pmtiles");
    std::ofstream f(served_, std::ios::binary | std::ios::trunc);
    f.write(b.data(), std::streamsize(b.size()));
  }
  // The tile as archive b holds it (its bytes as served by a registry of its own).
  std::string tile_of_b(std::string_view zxy) {
    vts::TilesetRegistry other;
    EXPECT_TRUE(other.load({*dir_ / "src_b.pmtiles"}).ok());
    req_.method = vts::HttpMethod::get;
    const std::string target = "/src_b/" + std::string(zxy);
    req_.target = target;
    req_.if_none_match = {};
    return body(vts::route(req_, other, vts::RouterConfig{}));
  }
  std::uint64_t hits() const { return config_.tile_cache->hits.load(); }

  static inline vts::test::TempDir* dir_ = nullptr;
  fs::path served_;
  vts::TilesetRegistry registry_;
  vts::RouterConfig config_;
  vts::HttpRequest req_;
};

TEST_F(TileCacheRouter, AHotTileIsAnsweredFromTheCacheWithTheSameBytesAndTag) {
  auto first = get("/t/2/1/1");
  ASSERT_EQ(first.status, 200);
  EXPECT_EQ(hits(), 0u);
  auto second = get("/t/2/1/1");
  ASSERT_EQ(second.status, 200);
  EXPECT_EQ(hits(), 1u);
  EXPECT_EQ(body(second), body(first));
  EXPECT_NE(second.keep, nullptr) << "the body is the cache's shared buffer, kept by the response";
  std::string etag;
  for (const auto& [k, v] : second.headers)
    if (k == "ETag") etag = v;
  ASSERT_FALSE(etag.empty());
  EXPECT_EQ(get("/t/2/1/1", etag).status, 304);
  EXPECT_EQ(hits(), 2u);
}

TEST_F(TileCacheRouter, AnArchiveRewrittenInPlaceIsNeverAnsweredFromTheCacheOnceReChecked) {
  config_.tile_cache_recheck = std::chrono::milliseconds(0);  // every hit re-checks
  const std::string old_tile = body(get("/t/2/1/1"));
  ASSERT_EQ(body(get("/t/2/1/1")), old_tile);
  ASSERT_EQ(hits(), 1u);
  rewrite_in_place();
  auto after = get("/t/2/1/1");
  EXPECT_NE(body(after), old_tile) << "a stale tile came from the cache";
  EXPECT_EQ(after.status, 503) << after.owned;
  EXPECT_EQ(hits(), 1u);
}

TEST_F(TileCacheRouter, AChangeAReadFindsStopsTheCacheAnsweringForTheArchiveAtOnce) {
  config_.tile_cache_recheck = std::chrono::hours(1);  // no periodic re-check in this test
  const std::string old_tile = body(get("/t/2/1/1"));
  ASSERT_EQ(body(get("/t/2/1/1")), old_tile);
  rewrite_in_place();
  EXPECT_EQ(get("/t/2/0/0").status, 503) << "a tile read from the file finds the change";
  auto after = get("/t/2/1/1");
  EXPECT_NE(body(after), old_tile) << "a stale tile came from the cache";
  EXPECT_EQ(after.status, 503) << after.owned;
}

TEST_F(TileCacheRouter, AReloadThatSeesTheFileChangedStopsTheCacheEvenWhileTheNewOneSettles) {
  config_.tile_cache_recheck = std::chrono::hours(1);
  const std::string old_tile = body(get("/t/2/1/1"));
  ASSERT_EQ(body(get("/t/2/1/1")), old_tile);
  rewrite_in_place();
  auto result = registry_.reload(false, std::chrono::hours(1));
  EXPECT_EQ(result.settling, 1);
  auto after = get("/t/2/1/1");
  EXPECT_NE(body(after), old_tile) << "a stale tile came from the cache";
  EXPECT_EQ(after.status, 503) << after.owned;
}

TEST_F(TileCacheRouter, TheArchiveAReloadOpensIsANewGenerationServedFromItsOwnBytes) {
  config_.tile_cache_recheck = std::chrono::hours(1);
  const std::string old_tile = body(get("/t/2/1/1"));
  ASSERT_EQ(body(get("/t/2/1/1")), old_tile);
  const std::uint64_t old_generation = registry_.find("t")->generation;
  rewrite_in_place();
  ASSERT_EQ(registry_.reload(false, {}).swapped, 1);
  EXPECT_NE(registry_.find("t")->generation, old_generation);
  const std::string want = tile_of_b("2/1/1");
  ASSERT_NE(want, old_tile);
  auto after = get("/t/2/1/1");
  ASSERT_EQ(after.status, 200);
  EXPECT_EQ(body(after), want);
  EXPECT_EQ(body(get("/t/2/1/1")), want) << "and from the cache once read";
}

}  // namespace
