#include "vts/renderer/slot_cache.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <map>
#include <random>
#include <set>

namespace vts::renderer {
namespace {

TileId tile(std::uint32_t x, int z = 5) {
  return TileId{static_cast<std::uint8_t>(z), x, 0};
}
const TileId kRoot{0, 0, 0};

TEST(SlotCache, UsesFreeSlotsBeforeEvictingAndKeepsAResidentTilesSlot) {
  SlotCache cache({.capacity = 3, .keep_frames = 1});
  cache.begin_frame(1);
  std::set<std::uint32_t> slots;
  for (std::uint32_t i = 0; i < 3; ++i) {
    auto a = cache.acquire(tile(i));
    ASSERT_TRUE(a.has_value());
    EXPECT_FALSE(a->evicted.has_value());
    slots.insert(a->slot);
  }
  EXPECT_EQ(slots, (std::set<std::uint32_t>{0, 1, 2}));
  auto again = cache.acquire(tile(1));
  ASSERT_TRUE(again.has_value());
  EXPECT_EQ(again->slot, *cache.slot_of(tile(1)));
  EXPECT_FALSE(again->evicted.has_value());
  EXPECT_EQ(cache.stats().evictions, 0u);
  EXPECT_EQ(cache.stats().resident, 3u);
}

TEST(SlotCache, NeverEvictsATileUsedInTheCurrentFrame) {
  SlotCache cache({.capacity = 2, .keep_frames = 0});
  cache.begin_frame(1);
  ASSERT_TRUE(cache.acquire(tile(0)));
  ASSERT_TRUE(cache.acquire(tile(1)));
  EXPECT_FALSE(cache.acquire(tile(2)).has_value());
  EXPECT_EQ(cache.stats().refusals, 1u);
  // Next frame, only tile 1 is touched: tile 0 goes, tile 1 stays.
  cache.begin_frame(2);
  EXPECT_TRUE(cache.touch(tile(1)));
  auto a = cache.acquire(tile(2));
  ASSERT_TRUE(a.has_value());
  EXPECT_EQ(a->evicted, tile(0));
  EXPECT_FALSE(cache.acquire(tile(3)).has_value());  // 1 and 2 are both used in frame 2
  EXPECT_TRUE(cache.slot_of(tile(1)).has_value());
  EXPECT_EQ(cache.stats().evictions, 1u);
  EXPECT_EQ(cache.stats().refusals, 2u);
}

TEST(SlotCache, KeepsTilesUnseenForFewerThanKeepFramesFrames) {
  SlotCache cache({.capacity = 2, .keep_frames = 3});
  cache.begin_frame(1);
  ASSERT_TRUE(cache.acquire(tile(0)));
  ASSERT_TRUE(cache.acquire(tile(1)));
  cache.begin_frame(2);
  cache.touch(tile(1));
  cache.begin_frame(3);
  EXPECT_FALSE(cache.acquire(tile(2)).has_value());  // tile 0 unseen for 2 frames < 3
  cache.begin_frame(4);
  auto a = cache.acquire(tile(2));  // tile 0 unseen for 3 frames: the least recently used goes
  ASSERT_TRUE(a.has_value());
  EXPECT_EQ(a->evicted, tile(0));
  EXPECT_EQ(cache.tile_in(a->slot), tile(2));
  EXPECT_FALSE(cache.acquire(tile(3)).has_value());  // tile 1 unseen for 2 frames
  cache.begin_frame(5);
  a = cache.acquire(tile(3));
  ASSERT_TRUE(a.has_value());
  EXPECT_EQ(a->evicted, tile(1));
}

TEST(SlotCache, NeverEvictsThePinnedRoot) {
  SlotCache cache({.capacity = 2, .keep_frames = 1});
  cache.begin_frame(1);
  ASSERT_TRUE(cache.acquire(kRoot));
  ASSERT_TRUE(cache.pin(kRoot));
  for (std::uint32_t i = 0; i < 20; ++i) {
    cache.begin_frame(10 + i * 10);
    auto a = cache.acquire(tile(i));
    ASSERT_TRUE(a.has_value());
    if (i > 0) {
      EXPECT_EQ(a->evicted, tile(i - 1));
    }
    EXPECT_TRUE(cache.slot_of(kRoot).has_value());
  }
  cache.begin_frame(1000);
  cache.touch(tile(19));
  EXPECT_FALSE(cache.acquire(tile(99)).has_value());  // only the pinned root is old enough
  EXPECT_EQ(cache.stats().pinned, 1u);
  ASSERT_TRUE(cache.unpin(kRoot));
  cache.begin_frame(1001);
  cache.touch(tile(19));
  auto a = cache.acquire(tile(99));
  ASSERT_TRUE(a.has_value());
  EXPECT_EQ(a->evicted, kRoot);
}

TEST(SlotCache, RandomisedEvictionsFollowTheRules) {
  // A model of the rules: the victim is the unpinned tile with the oldest last use, and only if
  // that use is at least max(1, keep_frames) frames ago.
  constexpr std::uint32_t kKeep = 2;
  SlotCache cache({.capacity = 16, .keep_frames = kKeep});
  std::map<TileId, std::uint64_t> last_used;  // resident, unpinned
  std::mt19937 rng(42);
  std::uint64_t frame = 1;
  cache.begin_frame(frame);
  ASSERT_TRUE(cache.acquire(kRoot));
  cache.pin(kRoot);
  for (int step = 0; step < 5000; ++step) {
    if (step % 10 == 0) cache.begin_frame(++frame);
    const TileId t = tile(std::uniform_int_distribution<std::uint32_t>(0, 40)(rng));
    if (std::uniform_int_distribution<int>(0, 2)(rng) == 0) {
      EXPECT_EQ(cache.touch(t), last_used.count(t) == 1);
      if (last_used.count(t)) last_used[t] = frame;
      continue;
    }
    auto a = cache.acquire(t);
    if (last_used.count(t)) {
      ASSERT_TRUE(a.has_value());
      EXPECT_FALSE(a->evicted.has_value());
      last_used[t] = frame;
      continue;
    }
    std::uint64_t oldest = ~std::uint64_t{0};
    for (auto& [id, used] : last_used) oldest = std::min(oldest, used);
    const bool free_slot = last_used.size() + 1 < 16;
    const bool may_evict = !last_used.empty() && frame - oldest >= kKeep;
    ASSERT_EQ(a.has_value(), free_slot || may_evict) << "step " << step;
    if (!a) continue;
    if (a->evicted) {
      ASSERT_FALSE(free_slot);
      ASSERT_NE(*a->evicted, kRoot);
      ASSERT_EQ(last_used.at(*a->evicted), oldest);
      ASSERT_GE(frame - oldest, kKeep);
      last_used.erase(*a->evicted);
    }
    last_used[t] = frame;
  }
  EXPECT_EQ(cache.stats().resident, last_used.size() + 1);
  EXPECT_GT(cache.stats().evictions, 0u);
  EXPECT_GT(cache.stats().refusals, 0u);
}

}  // namespace
}  // namespace vts::renderer
