#include "vts/renderer/page_table.hpp"

#include "pyramid_helpers.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <map>
#include <random>
#include <set>
#include <tuple>
#include <vector>

namespace vts::renderer {
namespace {

using testing::pyramid;
using testing::tile;

ClipmapPageTable table(const Pyramid& p, std::uint32_t window) {
  auto t = ClipmapPageTable::create(p, {window});
  EXPECT_TRUE(t.ok());
  return std::move(t).value();
}

// The page table's contract computed the slow, obvious way: walk up from the tile until a mapped
// tile is found.
std::uint32_t brute_force(const std::map<TileId, std::uint32_t>& resident, TileId t) {
  for (int z = t.z; z >= 0; --z) {
    const TileId a = tile(z, t.x >> (t.z - z), t.y >> (t.z - z));
    auto it = resident.find(a);
    if (it != resident.end()) return PageEntry::pack(it->second, z);
  }
  return 0;
}

// Checks every cell of every window against the brute force, and that the window is where the
// origins say (clipped to the level's tiles) and nowhere else.
void expect_invariant(const ClipmapPageTable& pt, const std::map<TileId, std::uint32_t>& resident) {
  const Pyramid& p = pt.pyramid();
  const std::uint32_t w = pt.window();
  for (int z = 0; z <= p.max_level(); ++z) {
    auto layer = pt.layer(z);
    ASSERT_EQ(layer.size(), std::size_t(w) * w);
    for (std::uint32_t y = 0; y < p.tiles_y(z); ++y) {
      for (std::uint32_t x = 0; x < p.tiles_x(z); ++x) {
        const TileId t = tile(z, x, y);
        const bool inside = x >= pt.origin_x(z) && x < pt.origin_x(z) + w && y >= pt.origin_y(z) &&
                            y < pt.origin_y(z) + w;
        ASSERT_EQ(pt.contains(t), inside) << t.to_string();
        const std::uint32_t want = brute_force(resident, t);
        ASSERT_EQ(pt.resolve(t), PageEntry::unpack(want)) << t.to_string();
        if (!inside) continue;
        ASSERT_EQ(layer[(y % w) * w + (x % w)], want) << t.to_string();
        ASSERT_EQ(pt.entry(t), PageEntry::unpack(want)) << t.to_string();
      }
    }
  }
}

using Cell = std::tuple<int, std::uint32_t, std::uint32_t>;  // layer, row, column

std::vector<std::uint32_t> snapshot(const ClipmapPageTable& pt) {
  std::vector<std::uint32_t> all;
  for (int z = 0; z < kMaxLevels; ++z) {
    auto l = pt.layer(z);
    all.insert(all.end(), l.begin(), l.end());
  }
  return all;
}

// Dirty spans must name exactly the cells that differ between two snapshots, as maximal runs.
void expect_dirty_matches(const std::vector<DirtySpan>& spans,
                          const std::vector<std::uint32_t>& before,
                          const std::vector<std::uint32_t>& after, std::uint32_t w) {
  std::set<Cell> changed, reported;
  for (std::size_t i = 0; i < after.size(); ++i)
    if (before[i] != after[i]) {
      changed.insert({int(i / (w * w)), std::uint32_t(i / w % w), std::uint32_t(i % w)});
    }
  for (std::size_t i = 0; i < spans.size(); ++i) {
    const DirtySpan& s = spans[i];
    ASSERT_LT(s.x0, s.x1);
    for (std::uint32_t x = s.x0; x < s.x1; ++x)
      ASSERT_TRUE(reported.insert({s.layer, s.row, x}).second) << "cell reported twice";
    if (i > 0 && spans[i - 1].layer == s.layer && spans[i - 1].row == s.row) {
      ASSERT_LT(spans[i - 1].x1, s.x0) << "adjacent runs not merged";
    }
  }
  EXPECT_EQ(reported, changed);
}

TEST(PageTable, MemoryIsTheSameForA2To15AndA2To25WidePyramid) {
  // 2^15 and 2^25 texels wide with 256-texel tiles: 2^7 and 2^17 tiles per side.
  const auto small = table(pyramid(7, 1u << 7, 1u << 6), 64);
  const auto planet = table(pyramid(17, 1u << 17, 1u << 16), 64);
  EXPECT_EQ(small.gpu_bytes(), planet.gpu_bytes());
  EXPECT_EQ(planet.gpu_bytes(), std::uint64_t{24} * 64 * 64 * 4);
  EXPECT_EQ(ClipmapPageTable::gpu_bytes(64), 393216u);
  for (int z = 0; z < kMaxLevels; ++z) {
    EXPECT_EQ(small.layer(z).size(), 64u * 64u);
    EXPECT_EQ(planet.layer(z).size(), 64u * 64u);
  }
  EXPECT_TRUE(small.layer(kMaxLevels).empty());
}

TEST(PageTable, EntryPacksValidBitLevelAndSlot) {
  EXPECT_EQ(PageEntry::pack(5, 3), 0x80000000u | (3u << 26) | 5u);
  EXPECT_EQ(PageEntry::unpack(PageEntry::pack(PageEntry::kMaxSlot, 23)),
            (PageEntry{PageEntry::kMaxSlot, 23}));
  EXPECT_FALSE(PageEntry::unpack(0).has_value());
}

TEST(PageTable, RejectsBadWindowsAndTilesOutsideThePyramid) {
  const Pyramid p = pyramid(4, 10, 6);
  EXPECT_FALSE(ClipmapPageTable::create(p, {48}).ok());
  EXPECT_FALSE(ClipmapPageTable::create(p, {0}).ok());
  auto pt = table(p, 8);
  ASSERT_TRUE(pt.map(tile(0, 0, 0), 0).ok());
  EXPECT_FALSE(pt.map(tile(4, 10, 0), 1).ok());  // column 10 does not exist at the finest level
  EXPECT_FALSE(pt.map(tile(5, 0, 0), 1).ok());   // beyond the max level
  EXPECT_FALSE(pt.map(tile(1, 0, 0), PageEntry::kMaxSlot + 1).ok());
  EXPECT_EQ(pt.mapped_count(), 1u);
}

TEST(PageTable, RootIsMappedFirstAndUnmappedLast) {
  auto pt = table(pyramid(3, 8, 8), 4);
  EXPECT_FALSE(pt.map(tile(1, 1, 0), 1).ok());
  EXPECT_FALSE(pt.entry(tile(1, 1, 0)).has_value());
  ASSERT_TRUE(pt.map(tile(0, 0, 0), 0).ok());
  // Once the root is resident every cell of every window resolves.
  for (int z = 0; z <= 3; ++z)
    for (std::uint32_t y = 0; y < 4; ++y)
      for (std::uint32_t x = 0; x < 4 && x < (1u << z); ++x)
        if (y < (1u << z)) {
          EXPECT_EQ(pt.entry(tile(z, x, y)), (PageEntry{0, 0}));
        }
  ASSERT_TRUE(pt.map(tile(1, 1, 0), 1).ok());
  EXPECT_FALSE(pt.unmap(tile(0, 0, 0)).ok());
  EXPECT_EQ(pt.entry(tile(3, 3, 0)), (PageEntry{0, 0}));
  EXPECT_EQ(pt.entry(tile(2, 2, 1)), (PageEntry{1, 1}));
  ASSERT_TRUE(pt.unmap(tile(1, 1, 0)).ok());
  ASSERT_TRUE(pt.unmap(tile(0, 0, 0)).ok());
  EXPECT_FALSE(pt.entry(tile(2, 2, 1)).has_value());
}

TEST(PageTable, LevelsThatFitTheWindowAreCoveredEntirelyAndNeverMove) {
  auto pt = table(pyramid(6, 40, 64), 16);  // levels 0-4 fit in 16 x 16
  for (int z = 0; z <= 4; ++z) {
    pt.recenter(z, 1000, 1000);
    EXPECT_EQ(pt.origin_x(z), 0u);
    EXPECT_EQ(pt.origin_y(z), 0u);
    EXPECT_TRUE(pt.contains(tile(z, pt.pyramid().tiles_x(z) - 1, pt.pyramid().tiles_y(z) - 1)));
  }
  // Level 6 is 40 x 64 tiles: the origin is clamped to [0, 24] x [0, 48].
  pt.recenter(6, 1000, 1000);
  EXPECT_EQ(pt.origin_x(6), 24u);
  EXPECT_EQ(pt.origin_y(6), 48u);
  pt.recenter(6, 3, 30);
  EXPECT_EQ(pt.origin_x(6), 0u);
  EXPECT_EQ(pt.origin_y(6), 22u);
  EXPECT_FALSE(pt.contains(tile(6, 16, 22)));
  EXPECT_TRUE(pt.contains(tile(6, 15, 37)));
}

TEST(PageTable, MappingAndUnmappingKeepsEveryEntryTheNearestResidentAncestor) {
  // Non-square, non-power-of-two pyramid; windows small enough that levels 5-7 are clipped.
  const Pyramid p = pyramid(7, 100, 70);
  auto pt = table(p, 16);
  std::mt19937 rng(1234);
  std::map<TileId, std::uint32_t> resident;
  ASSERT_TRUE(pt.map(tile(0, 0, 0), 0).ok());
  resident[tile(0, 0, 0)] = 0;
  expect_invariant(pt, resident);
  auto before = snapshot(pt);
  (void)pt.take_dirty();
  before = snapshot(pt);

  const auto random_tile = [&](int z) {
    return tile(z, std::uniform_int_distribution<std::uint32_t>(0, p.tiles_x(z) - 1)(rng),
                std::uniform_int_distribution<std::uint32_t>(0, p.tiles_y(z) - 1)(rng));
  };
  for (int step = 0; step < 400; ++step) {
    const int op = std::uniform_int_distribution<int>(0, 9)(rng);
    const int z = std::uniform_int_distribution<int>(1, 7)(rng);
    if (op < 5) {
      // Bias towards tiles near the windows so that mapping actually writes cells.
      TileId t = random_tile(z);
      if (op < 3) {
        t.x = std::min(pt.origin_x(z) + (t.x % 16), p.tiles_x(z) - 1);
        t.y = std::min(pt.origin_y(z) + (t.y % 16), p.tiles_y(z) - 1);
      }
      const std::uint32_t slot = std::uniform_int_distribution<std::uint32_t>(1, 5000)(rng);
      ASSERT_TRUE(pt.map(t, slot).ok());
      resident[t] = slot;
    } else if (op < 8) {
      if (resident.size() > 1) {
        auto it = std::next(resident.begin(), std::uniform_int_distribution<std::size_t>(
                                                  1, resident.size() - 1)(rng));
        ASSERT_TRUE(pt.unmap(it->first).ok());
        resident.erase(it);
      }
    } else {
      const TileId c = random_tile(z);
      pt.recenter(z, c.x, c.y);
    }
    expect_invariant(pt, resident);
    if (step % 7 == 0) {
      const auto after = snapshot(pt);
      expect_dirty_matches(pt.take_dirty(), before, after, 16);
      before = after;
    }
  }
}

TEST(PageTable, DirtyTrackingReportsOnlyCellsThatChanged) {
  auto pt = table(pyramid(5, 32, 32), 8);
  EXPECT_TRUE(pt.take_dirty().empty());
  ASSERT_TRUE(pt.map(tile(0, 0, 0), 7).ok());
  // Every in-window cell of levels 0-5 now points at the root: 1 + 4 + 16 + 64*3 cells.
  std::size_t cells = 0;
  for (const DirtySpan& s : pt.take_dirty()) cells += s.x1 - s.x0;
  EXPECT_EQ(cells, 1u + 4u + 16u + 64u * 3u);
  // Map and unmap a tile between two takes: the GPU copy is already right.
  ASSERT_TRUE(pt.map(tile(3, 2, 2), 9).ok());
  ASSERT_TRUE(pt.unmap(tile(3, 2, 2)).ok());
  EXPECT_TRUE(pt.take_dirty().empty());
  // A level-4 tile changes itself at level 4 and its 2x2 children at level 5, and nothing else.
  ASSERT_TRUE(pt.map(tile(4, 1, 1), 3).ok());
  const std::vector<DirtySpan> want = {{4, 1, 1, 2}, {5, 2, 2, 4}, {5, 3, 2, 4}};
  EXPECT_EQ(pt.take_dirty(), want);
}

TEST(PageTable, RecenteringFillsEnteringTilesFromTheResidentSet) {
  const Pyramid p = pyramid(8, 256, 256);
  auto pt = table(p, 8);
  std::map<TileId, std::uint32_t> resident;
  ASSERT_TRUE(pt.map(tile(0, 0, 0), 0).ok());
  resident[tile(0, 0, 0)] = 0;
  // Map tiles far from level 8's window: their descendants are not in it yet.
  for (std::uint32_t i = 0; i < 6; ++i) {
    const TileId t = tile(5, 20 + i, 20);
    ASSERT_TRUE(pt.map(t, 10 + i).ok());
    resident[t] = 10 + i;
  }
  ASSERT_TRUE(pt.map(tile(8, 170, 163), 99).ok());
  resident[tile(8, 170, 163)] = 99;
  EXPECT_FALSE(pt.contains(tile(8, 170, 163)));
  for (std::uint32_t c = 150; c < 200; c += 3) {
    pt.recenter(8, c, c);
    pt.recenter(7, c / 2, c / 2);
    expect_invariant(pt, resident);
  }
  pt.recenter(8, 170, 163);
  EXPECT_EQ(pt.entry(tile(8, 170, 163)), (PageEntry{99, 8}));
  EXPECT_EQ(pt.entry(tile(8, 168, 163)), (PageEntry{11, 5}));  // under 5/21/20
}

}  // namespace
}  // namespace vts::renderer
