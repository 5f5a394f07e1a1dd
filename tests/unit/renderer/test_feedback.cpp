#include "vts/renderer/feedback.hpp"

#include "pyramid_helpers.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <vector>

namespace vts::renderer {
namespace {

using testing::pyramid;
using testing::tile;

// A feedback buffer built pixel by pixel, packed as the shader will.
struct Buffer {
  std::vector<std::uint32_t> words;
  void add(int level, std::uint32_t x, std::uint32_t y, int count = 1, std::uint32_t frac = 0) {
    for (int i = 0; i < count; ++i) {
      std::uint32_t w[2];
      FeedbackPixel::pack(level, x, y, frac, w);
      words.insert(words.end(), {w[0], w[1]});
    }
  }
  void background(int count) {
    for (int i = 0; i < count; ++i) words.insert(words.end(), {FeedbackPixel::kEmpty, 0u});
  }
};

TEST(Feedback, DeduplicatesPixelsIntoCoverageCounts) {
  FeedbackProcessor fp(pyramid(4, 16, 16));
  Buffer b;
  b.add(4, 5, 6, 10);
  b.background(3);
  b.add(4, 5, 6, 5);
  b.add(4, 7, 6, 2);
  auto r = fp.process(b.words, 0.0);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(fp.last_stats().pixels, 20u);
  EXPECT_EQ(fp.last_stats().empty, 3u);
  EXPECT_EQ(fp.last_stats().direct, 2u);
  std::vector<TileRequest> direct;
  for (const auto& q : *r)
    if (q.direct) direct.push_back(q);
  const std::vector<TileRequest> want = {{tile(4, 5, 6), 15, true}, {tile(4, 7, 6), 2, true}};
  EXPECT_EQ(direct, want);
}

TEST(Feedback, AddsEveryAncestorWithTheCoverageItBacksUp) {
  FeedbackProcessor fp(pyramid(3, 8, 8));
  Buffer b;
  b.add(3, 5, 2, 4);  // under 2/2/1, 1/1/0
  b.add(3, 0, 7, 1);  // under 2/0/3, 1/0/1
  b.add(2, 2, 1, 3);  // directly wants an ancestor of 3/5/2: counted once, not twice, above
  auto r = fp.process(b.words, 0.0);
  ASSERT_TRUE(r.ok());
  const std::vector<TileRequest> want = {
      {tile(0, 0, 0), 8, false}, {tile(1, 1, 0), 7, false}, {tile(1, 0, 1), 1, false},
      {tile(2, 2, 1), 7, true},  {tile(2, 0, 3), 1, false}, {tile(3, 5, 2), 4, true},
      {tile(3, 0, 7), 1, true},
  };
  EXPECT_EQ(*r, want);
}

TEST(Feedback, SortsCoarseLevelsFirstThenLargerCoverageThenRowAndColumn) {
  FeedbackProcessor fp(pyramid(2, 4, 4));
  Buffer b;
  b.add(2, 3, 3, 2);
  b.add(2, 0, 0, 2);
  b.add(2, 1, 0, 9);
  b.add(1, 1, 0, 1);
  auto r = fp.process(b.words, 0.0);
  ASSERT_TRUE(r.ok());
  const std::vector<TileRequest> want = {
      {tile(0, 0, 0), 14, false}, {tile(1, 0, 0), 11, false}, {tile(1, 1, 1), 2, false},
      {tile(1, 1, 0), 1, true},   {tile(2, 1, 0), 9, true},   {tile(2, 0, 0), 2, true},
      {tile(2, 3, 3), 2, true},
  };
  EXPECT_EQ(*r, want);
}

TEST(Feedback, BiasCoarsensTheRequestedLevel) {
  FeedbackProcessor fp(pyramid(6, 64, 64));
  // Integer bias: two levels coarser, coordinates halved twice.
  EXPECT_EQ(fp.requested_tile(0, 0, 0.0), tile(0, 0, 0));
  std::uint32_t w[2];
  FeedbackPixel::pack(6, 45, 22, 0, w);
  EXPECT_EQ(fp.requested_tile(w[0], w[1], 0.0), tile(6, 45, 22));
  EXPECT_EQ(fp.requested_tile(w[0], w[1], 2.0), tile(4, 11, 5));
  EXPECT_EQ(fp.requested_tile(w[0], w[1], 100.0), tile(0, 0, 0));
  // Half a level: a fragment exactly at level 6 still wants level 6 ...
  EXPECT_EQ(fp.requested_tile(w[0], w[1], 0.5), tile(6, 45, 22));
  // ... one already 0.6 of a level towards level 5 goes to 5.
  FeedbackPixel::pack(6, 45, 22, 154, w);
  EXPECT_EQ(fp.requested_tile(w[0], w[1], 0.0), tile(6, 45, 22));
  EXPECT_EQ(fp.requested_tile(w[0], w[1], 0.5), tile(5, 22, 11));
  // Through process(): bias applies before deduplication, so four siblings become one parent.
  Buffer b;
  b.add(6, 10, 10);
  b.add(6, 11, 10);
  b.add(6, 10, 11);
  b.add(6, 11, 11);
  auto r = fp.process(b.words, 1.0);
  ASSERT_TRUE(r.ok());
  ASSERT_EQ(r->size(), 6u);
  EXPECT_EQ(r->back(), (TileRequest{tile(5, 5, 5), 4, true}));
}

TEST(Feedback, DropsTilesOutsideThePyramidAndClampsLevelsAboveIt) {
  // 10 x 6 finest tiles at level 4: level 3 has 5 x 3, level 2 has 3 x 2.
  FeedbackProcessor fp(pyramid(4, 10, 6));
  Buffer b;
  b.add(4, 10, 0, 3);  // column 10 does not exist
  b.add(3, 0, 3, 2);   // row 3 of level 3 does not exist
  b.add(7, 72, 40);    // level 7 > max: clamped to level 4 -> 4/9/5, which exists
  b.add(6, 40, 24);    // -> 4/10/6: outside
  auto r = fp.process(b.words, 0.0);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(fp.last_stats().dropped, 6u);
  EXPECT_EQ(fp.last_stats().direct, 1u);
  ASSERT_FALSE(r->empty());
  EXPECT_EQ(r->back(), (TileRequest{tile(4, 9, 5), 1, true}));
  EXPECT_EQ(r->size(), 5u);  // and its four ancestors
}

TEST(Feedback, RejectsABufferThatIsNotWordPairs) {
  FeedbackProcessor fp(pyramid(2, 4, 4));
  std::vector<std::uint32_t> odd = {0, 0, 0};
  EXPECT_FALSE(fp.process(odd, 0.0).ok());
}

TEST(Feedback, PyramidFromGeometryMatchesTheArchiveTileCounts) {
  auto g = Geometry::create(86400, 43200, 256, 4);
  ASSERT_TRUE(g.ok());
  auto p = Pyramid::from_geometry(*g);
  ASSERT_TRUE(p.ok());
  ASSERT_EQ(p->max_level(), g->max_zoom());
  for (int z = 0; z <= g->max_zoom(); ++z) {
    EXPECT_EQ(p->tiles_x(z), g->tiles_x(z)) << z;
    EXPECT_EQ(p->tiles_y(z), g->tiles_y(z)) << z;
  }
  auto too_deep = Geometry::create(std::uint64_t{1} << 32, 4, 256, 4);  // 24 levels + root
  ASSERT_TRUE(too_deep.ok());
  EXPECT_FALSE(Pyramid::from_geometry(*too_deep).ok());
}

}  // namespace
}  // namespace vts::renderer
