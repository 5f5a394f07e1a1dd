#include "vts/protocol/geometry.hpp"

#include <gtest/gtest.h>

namespace vts {
namespace {

Geometry make(std::uint64_t w, std::uint64_t h, std::uint32_t t = 256, std::uint32_t b = 4) {
  auto g = Geometry::create(w, h, t, b);
  EXPECT_TRUE(g.ok()) << (g.ok() ? "" : g.error().to_string());
  return *g;
}

// Brute-force reference: level extents by repeated ceil-halving from the finest level.
void expect_consistent(const Geometry& g) {
  std::uint64_t w = g.width(), h = g.height();
  for (int z = g.max_zoom(); z >= 0; --z) {
    EXPECT_EQ(g.level_width(z), w) << "z=" << z;
    EXPECT_EQ(g.level_height(z), h) << "z=" << z;
    EXPECT_EQ(g.tiles_x(z), (w + g.tile_size() - 1) / g.tile_size());
    EXPECT_EQ(g.tiles_y(z), (h + g.tile_size() - 1) / g.tile_size());
    EXPECT_LE(g.tiles_x(z), 1ull << z);
    EXPECT_LE(g.tiles_y(z), 1ull << z);
    w = (w + 1) / 2;
    h = (h + 1) / 2;
  }
  EXPECT_EQ(g.tiles_x(0), 1u);
  EXPECT_EQ(g.tiles_y(0), 1u);
  // The finest level covers the image and the level above does not.
  const std::uint64_t extent = std::max(g.width(), g.height());
  EXPECT_GE(std::uint64_t{g.tile_size()} << g.max_zoom(), extent);
  if (g.max_zoom() > 0) {
    EXPECT_LT(std::uint64_t{g.tile_size()} << (g.max_zoom() - 1), extent);
  }
}

TEST(Geometry, SingleTexelImageIsOneRootTile) {
  Geometry g = make(1, 1);
  EXPECT_EQ(g.max_zoom(), 0);
  EXPECT_EQ(g.total_tile_count(), 1u);
  EXPECT_TRUE(g.exists({0, 0, 0}));
  EXPECT_EQ(g.content_rect({0, 0, 0}), (TexelRect{0, 0, 1, 1}));
  EXPECT_EQ(g.stored_size(), 264u);
  // Every border texel clamps to the single texel.
  EXPECT_EQ(g.stored_to_level_x({0, 0, 0}, 0), 0u);
  EXPECT_EQ(g.stored_to_level_x({0, 0, 0}, 263), 0u);
  expect_consistent(g);
}

TEST(Geometry, ImagesAroundOneTileNeedZeroOrOneExtraLevel) {
  EXPECT_EQ(make(255, 255).max_zoom(), 0);
  EXPECT_EQ(make(256, 256).max_zoom(), 0);
  Geometry g = make(257, 256);
  EXPECT_EQ(g.max_zoom(), 1);
  EXPECT_EQ(g.tiles_x(1), 2u);
  EXPECT_EQ(g.tiles_y(1), 1u);
  EXPECT_EQ(g.content_rect({1, 1, 0}), (TexelRect{256, 0, 257, 256}));
  EXPECT_EQ(g.level_width(0), 129u);
  EXPECT_EQ(g.level_height(0), 128u);
  EXPECT_FALSE(g.exists({1, 0, 1}));
  for (auto [w, h] : {std::pair{255, 255}, {256, 256}, {257, 257}, {257, 1}})
    expect_consistent(make(w, h));
}

TEST(Geometry, NonSquareNonPowerOfTwoImagesHaveExactLevelExtents) {
  Geometry a = make(10752, 9216);
  EXPECT_EQ(a.max_zoom(), 6);  // 42 tiles wide → 64 slots
  EXPECT_EQ(a.tiles_x(6), 42u);
  EXPECT_EQ(a.tiles_y(6), 36u);
  EXPECT_EQ(a.tile_count(6), 42u * 36u);
  expect_consistent(a);
  Geometry b = make(86400, 43200);
  EXPECT_EQ(b.max_zoom(), 9);  // 337.5 tiles → 512 slots
  EXPECT_EQ(b.tiles_x(9), 338u);
  EXPECT_EQ(b.tiles_y(9), 169u);
  EXPECT_EQ(b.level_width(0), 169u);
  EXPECT_EQ(b.level_height(0), 85u);
  expect_consistent(b);
}

TEST(Geometry, PlanetSizedVirtualTextureStaysExact) {
  Geometry g = make(1ull << 25, 1ull << 25);
  EXPECT_EQ(g.max_zoom(), 17);
  EXPECT_EQ(g.tiles_x(17), 1u << 17);
  EXPECT_EQ(g.tile_count(17), 1ull << 34);
  const TileId last{17, (1u << 17) - 1, (1u << 17) - 1};
  EXPECT_TRUE(g.exists(last));
  EXPECT_EQ(g.content_rect(last).x1, 1ull << 25);
  EXPECT_EQ(g.stored_to_level_x(last, g.stored_size() - 1), (1ull << 25) - 1);
  EXPECT_EQ(g.tile_of_texel(17, (1ull << 25) - 1, 0), (TileId{17, (1u << 17) - 1, 0}));
  expect_consistent(g);
}

TEST(Geometry, ParentAndChildrenAreInverse) {
  Geometry g = make(10752, 9216);
  for (int z = 0; z < g.max_zoom(); ++z)
    for (std::uint32_t y = 0; y < g.tiles_y(z); ++y)
      for (std::uint32_t x = 0; x < g.tiles_x(z); ++x) {
        const TileId t{static_cast<std::uint8_t>(z), x, y};
        const auto kids = g.children(t);
        EXPECT_FALSE(kids.empty());
        for (const TileId& c : kids) {
          EXPECT_TRUE(g.exists(c));
          EXPECT_EQ(g.parent(c), t);
        }
      }
  EXPECT_FALSE(g.parent({0, 0, 0}).has_value());
  EXPECT_TRUE(g.children({6, 0, 0}).empty());
  // Children at the ragged edge: only those over the image exist.
  Geometry h = make(257, 256);
  EXPECT_EQ(h.children({0, 0, 0}).size(), 2u);
}

TEST(Geometry, EveryExistingTileHoldsImageTexels) {
  Geometry g = make(86400, 43200);
  std::uint64_t total = 0;
  for (int z = 0; z <= g.max_zoom(); ++z) {
    total += g.tile_count(z);
    const TexelRect last =
        g.content_rect({static_cast<std::uint8_t>(z), g.tiles_x(z) - 1, g.tiles_y(z) - 1});
    EXPECT_FALSE(last.empty()) << "z=" << z;
    EXPECT_EQ(last.x1, g.level_width(z));
    EXPECT_EQ(last.y1, g.level_height(z));
  }
  EXPECT_EQ(total, g.total_tile_count());
}

TEST(Geometry, TexelToTileAndBackAtEveryLevel) {
  Geometry g = make(10752, 9216, 256, 4);
  for (int z = 0; z <= g.max_zoom(); ++z) {
    for (std::uint64_t px :
         {std::uint64_t{0}, std::uint64_t{255}, std::uint64_t{256}, g.level_width(z) - 1}) {
      if (px >= g.level_width(z)) continue;
      const TileId t = g.tile_of_texel(z, px, 0);
      const TexelRect r = g.content_rect(t);
      EXPECT_GE(px, r.x0);
      EXPECT_LT(px, r.x1);
      // Stored texel B + (px - x0) shows exactly px.
      EXPECT_EQ(g.stored_to_level_x(t, static_cast<std::uint32_t>(g.border() + px - r.x0)), px);
    }
  }
}

TEST(Geometry, BorderTexelsComeFromNeighboursAndClampAtTheEdge) {
  Geometry g = make(1000, 600, 256, 4);
  const TileId t{2, 1, 0};
  EXPECT_EQ(g.stored_to_level_x(t, 0), 252u);    // 4 texels into the left neighbour
  EXPECT_EQ(g.stored_to_level_x(t, 263), 515u);  // 4 texels into the right neighbour
  EXPECT_EQ(g.stored_to_level_y(t, 0), 0u);      // clamped at the top edge
  const TileId edge{2, 3, 2};
  EXPECT_EQ(g.stored_to_level_x(edge, 263), 999u);  // clamped at the right image edge
  EXPECT_EQ(g.stored_to_level_y(edge, 263), 599u);
}

TEST(Geometry, MapRectBetweenLevelsRoundsOutwardsWhenCoarsening) {
  Geometry g = make(1000, 600, 256, 4);
  const int mz = g.max_zoom();
  EXPECT_EQ(g.map_rect(mz, {1, 1, 3, 3}, mz - 1), (TexelRect{0, 0, 2, 2}));
  EXPECT_EQ(g.map_rect(mz - 1, {0, 0, 2, 2}, mz), (TexelRect{0, 0, 4, 4}));
  EXPECT_EQ(g.map_rect(mz - 1, {0, 0, 500, 300}, mz), (TexelRect{0, 0, 1000, 600}));
}

TEST(Geometry, RejectsInvalidParameters) {
  EXPECT_EQ(Geometry::create(0, 10).error().code, ErrorCode::invalid_argument);
  EXPECT_EQ(Geometry::create(10, 10, 100).error().code, ErrorCode::invalid_argument);
  EXPECT_EQ(Geometry::create(10, 10, 256, 129).error().code, ErrorCode::invalid_argument);
  EXPECT_EQ(Geometry::create(10, 10, 2).error().code, ErrorCode::invalid_argument);
  EXPECT_FALSE(Geometry::create(1ull << 40, 1, 256).ok());
}

TEST(TileIdText, ParsesAndRejects) {
  EXPECT_EQ(*parse_tile_id("3/2/7"), (TileId{3, 2, 7}));
  EXPECT_EQ(parse_tile_id("3/8/0").error().code, ErrorCode::invalid_argument);
  for (const char* bad : {"", "1/2", "1/2/3/4", "a/b/c", "-1/0/0", "1//0", "1/0/0 ", "40/0/0"})
    EXPECT_FALSE(parse_tile_id(bad).ok()) << bad;
  EXPECT_EQ((TileId{5, 3, 9}).to_string(), "5/3/9");
}

}  // namespace
}  // namespace vts
