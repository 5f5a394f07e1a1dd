#include "vts/client/ram_cache.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

namespace vts::client {
namespace {

TileKey key(std::uint32_t x, std::uint32_t y = 0, std::uint8_t z = 10, std::string ts = "ts") {
  return TileKey{std::move(ts), TileId{z, x, y}};
}

// A tile whose payload is `size` bytes derived from `seed`.
std::shared_ptr<const CachedTile> tile(std::size_t size, std::uint32_t seed = 0,
                                       std::string etag = "") {
  auto t = std::make_shared<CachedTile>();
  t->payload.resize(size);
  for (std::size_t i = 0; i < size; ++i) t->payload[i] = static_cast<std::uint8_t>(seed * 31 + i);
  t->etag = std::move(etag);
  t->validated_unix = seed;
  return t;
}

// Cost of a tile with payload `size` and no etag under key("ts"-style) keys.
std::size_t cost(std::size_t size) {
  return size + 2 + RamCache::kEntryOverhead;
}

TEST(RamCache, ReturnsTheStoredTileAndCountsHitsAndMisses) {
  RamCache cache(1 << 20);
  auto t = tile(100, 7, "\"abc\"");
  EXPECT_TRUE(cache.put(key(1), t));
  auto got = cache.get(key(1));
  ASSERT_NE(got, nullptr);
  EXPECT_EQ(got.get(), t.get());  // the same object, not a copy
  EXPECT_EQ(got->etag, "\"abc\"");
  EXPECT_EQ(cache.get(key(2)), nullptr);
  EXPECT_EQ(cache.get(key(1, 0, 10, "other")), nullptr);
  const RamCacheStats s = cache.stats();
  EXPECT_EQ(s.hits, 1u);
  EXPECT_EQ(s.misses, 2u);
  EXPECT_EQ(s.entries, 1u);
  EXPECT_EQ(s.max_bytes, 1u << 20);
}

TEST(RamCache, ChargesPayloadEtagKeyAndAFixedOverhead) {
  RamCache cache(1 << 20);
  ASSERT_TRUE(cache.put(key(1, 0, 10, "tileset"), tile(1000, 1, "etag12")));
  EXPECT_EQ(cache.stats().bytes, 1000u + 6u + 7u + RamCache::kEntryOverhead);
  EXPECT_EQ(RamCache::entry_cost(key(1, 0, 10, "tileset"), *tile(1000, 1, "etag12")),
            1000u + 6u + 7u + RamCache::kEntryOverhead);
  // Replacing an entry replaces its cost.
  ASSERT_TRUE(cache.put(key(1, 0, 10, "tileset"), tile(10)));
  EXPECT_EQ(cache.stats().bytes, 10u + 7u + RamCache::kEntryOverhead);
  EXPECT_EQ(cache.stats().entries, 1u);
}

TEST(RamCache, EvictsLeastRecentlyUsedFirst) {
  // One shard holding exactly three 1000-byte tiles.
  RamCache cache(3 * cost(1000), 1);
  for (std::uint32_t i = 0; i < 3; ++i) ASSERT_TRUE(cache.put(key(i), tile(1000, i)));
  ASSERT_NE(cache.get(key(0)), nullptr);  // 0 becomes the most recent: 1 is now the oldest
  ASSERT_TRUE(cache.put(key(3), tile(1000, 3)));
  EXPECT_EQ(cache.get(key(1)), nullptr);
  EXPECT_NE(cache.get(key(0)), nullptr);
  EXPECT_NE(cache.get(key(2)), nullptr);
  EXPECT_NE(cache.get(key(3)), nullptr);
  EXPECT_EQ(cache.stats().evictions, 1u);
  EXPECT_EQ(cache.stats().entries, 3u);
}

TEST(RamCache, NeverExceedsItsByteBudget) {
  const std::size_t budget = 64 * 1024;
  RamCache cache(budget, 4);
  for (std::uint32_t i = 0; i < 2000; ++i) {
    (void)cache.put(key(i % 300, i / 300), tile(100 + (i * 7919) % 4000, i));
    ASSERT_LE(cache.stats().bytes, budget) << "after put " << i;
  }
  const RamCacheStats s = cache.stats();
  EXPECT_GT(s.evictions, 0u);
  EXPECT_GT(s.bytes, budget / 2);  // and it is used, not emptied
}

TEST(RamCache, PinnedEntriesAreNeverEvictedButCountTowardsBytes) {
  RamCache cache(3 * cost(1000), 1);
  ASSERT_TRUE(cache.put(key(0), tile(1000), /*pinned=*/true));
  for (std::uint32_t i = 1; i < 50; ++i) (void)cache.put(key(i), tile(1000, i));
  EXPECT_NE(cache.get(key(0)), nullptr);
  const RamCacheStats s = cache.stats();
  EXPECT_EQ(s.pinned_bytes, cost(1000));
  EXPECT_LE(s.bytes, 3 * cost(1000));
  EXPECT_EQ(s.entries, 3u);
}

TEST(RamCache, PinnedEntriesMayFillTheBudgetAndThenNewTilesDoNotStay) {
  RamCache cache(2 * cost(1000), 1);
  ASSERT_TRUE(cache.put(key(0), tile(1000), true));
  ASSERT_TRUE(cache.put(key(1), tile(1000), true));
  EXPECT_FALSE(cache.put(key(2), tile(1000)));  // stored, then evicted at once: nothing else to
  EXPECT_EQ(cache.get(key(2)), nullptr);
  EXPECT_EQ(cache.stats().bytes, 2 * cost(1000));
  EXPECT_EQ(cache.stats().evictions, 1u);
}

TEST(RamCache, UnpinningMakesAnEntryEvictableAgain) {
  RamCache cache(2 * cost(1000), 1);
  ASSERT_TRUE(cache.put(key(0), tile(1000), true));
  ASSERT_TRUE(cache.put(key(1), tile(1000)));
  EXPECT_TRUE(cache.set_pinned(key(0), false));
  EXPECT_EQ(cache.stats().pinned_bytes, 0u);
  // key(0) was made the most recent on unpinning; key(1) goes first, then key(0).
  ASSERT_TRUE(cache.put(key(2), tile(1000)));
  EXPECT_EQ(cache.get(key(1)), nullptr);
  EXPECT_NE(cache.get(key(0)), nullptr);
  EXPECT_FALSE(cache.set_pinned(key(99), true));
}

TEST(RamCache, PinningAnEntryProtectsIt) {
  RamCache cache(2 * cost(1000), 1);
  ASSERT_TRUE(cache.put(key(0), tile(1000)));
  ASSERT_TRUE(cache.put(key(1), tile(1000)));
  EXPECT_TRUE(cache.set_pinned(key(0), true));
  EXPECT_EQ(cache.stats().pinned_bytes, cost(1000));
  for (std::uint32_t i = 2; i < 10; ++i) (void)cache.put(key(i), tile(1000));
  EXPECT_NE(cache.get(key(0)), nullptr);
}

TEST(RamCache, ReplacingAPinnedTileKeepsThePin) {
  RamCache cache(2 * cost(1000), 1);
  ASSERT_TRUE(cache.put(key(0), tile(1000, 1), true));
  ASSERT_TRUE(cache.put(key(0), tile(1000, 2)));  // a refresh
  EXPECT_EQ(cache.stats().pinned_bytes, cost(1000));
  for (std::uint32_t i = 1; i < 10; ++i) (void)cache.put(key(i), tile(1000));
  auto got = cache.get(key(0));
  ASSERT_NE(got, nullptr);
  EXPECT_EQ(got->validated_unix, 2);
}

TEST(RamCache, DoesNotStoreAnEntryLargerThanAShardAndDropsTheOlderVersion) {
  const std::size_t shard_budget = 10000;
  RamCache cache(4 * shard_budget, 4);
  ASSERT_TRUE(cache.put(key(0), tile(100, 1)));
  EXPECT_FALSE(cache.put(key(0), tile(shard_budget, 2)));  // cost > budget once overhead is added
  EXPECT_EQ(cache.get(key(0)), nullptr);                   // not the stale small version
  EXPECT_EQ(cache.stats().bytes, 0u);
  EXPECT_EQ(cache.stats().entries, 0u);
  EXPECT_TRUE(cache.put(key(0), tile(shard_budget - cost(0), 3)));  // exactly the budget fits
}

TEST(RamCache, EraseDropsPinnedAndUnpinnedEntries) {
  RamCache cache(1 << 20);
  ASSERT_TRUE(cache.put(key(0), tile(10), true));
  ASSERT_TRUE(cache.put(key(1), tile(10)));
  cache.erase(key(0));
  cache.erase(key(1));
  cache.erase(key(2));
  EXPECT_EQ(cache.get(key(0)), nullptr);
  EXPECT_EQ(cache.get(key(1)), nullptr);
  const RamCacheStats s = cache.stats();
  EXPECT_EQ(s.bytes, 0u);
  EXPECT_EQ(s.entries, 0u);
  EXPECT_EQ(s.pinned_bytes, 0u);
  EXPECT_EQ(s.evictions, 0u);
}

TEST(RamCache, AHandedOutTileOutlivesItsEviction) {
  RamCache cache(cost(1000), 1);
  ASSERT_TRUE(cache.put(key(0), tile(1000, 5)));
  auto held = cache.get(key(0));
  ASSERT_TRUE(cache.put(key(1), tile(1000, 6)));  // evicts key(0)
  EXPECT_EQ(cache.get(key(0)), nullptr);
  ASSERT_EQ(held->payload.size(), 1000u);
  EXPECT_EQ(held->payload[1], static_cast<std::uint8_t>(5 * 31 + 1));
}

TEST(RamCache, SpreadsOneRowOfTilesOverTheShards) {
  // 16 shards of room for 2 tiles each: if one row of tiles (only x varies) landed in one shard,
  // only 2 of them would stay.
  RamCache cache(16 * 2 * cost(100), 16);
  for (std::uint32_t x = 0; x < 32; ++x) (void)cache.put(key(x, 5), tile(100));
  EXPECT_GE(cache.stats().entries, 16u);
}

TEST(RamCache, StaysConsistentUnderConcurrentUseFromSeveralThreads) {
  const std::size_t budget = 256 * 1024;
  RamCache cache(budget, 8);
  constexpr int kThreads = 4;
  constexpr int kOps = 20000;
  std::atomic<int> wrong{0};
  std::atomic<std::uint64_t> gets{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      std::uint32_t state = 12345u + t;
      for (int i = 0; i < kOps; ++i) {
        state = state * 1664525u + 1013904223u;
        const std::uint32_t x = (state >> 8) % 500;
        const TileKey k = key(x);
        switch ((state >> 4) % 8) {
          case 0:
          case 1:
            (void)cache.put(k, tile(50 + x * 3, x));
            break;
          case 2:
            cache.erase(k);
            break;
          case 3:
            (void)cache.set_pinned(k, false);
            break;
          default: {
            ++gets;
            auto got = cache.get(k);
            // A tile found under a key is always that key's tile.
            if (got && (got->validated_unix != x || got->payload.size() != 50 + x * 3)) ++wrong;
          }
        }
      }
    });
  }
  for (auto& th : threads) th.join();
  EXPECT_EQ(wrong.load(), 0);
  const RamCacheStats s = cache.stats();
  EXPECT_EQ(s.hits + s.misses, gets.load());
  EXPECT_LE(s.bytes, budget);
  EXPECT_EQ(s.pinned_bytes, 0u);
  // The counters agree with the content: every key's cost summed over what is still there.
  std::uint64_t bytes = 0, entries = 0;
  for (std::uint32_t x = 0; x < 500; ++x) {
    if (cache.get(key(x))) {
      bytes += cost(50 + x * 3);
      ++entries;
    }
  }
  EXPECT_EQ(s.bytes, bytes);
  EXPECT_EQ(s.entries, entries);
}

}  // namespace
}  // namespace vts::client
