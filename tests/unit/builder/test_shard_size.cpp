// What a plan's parts and archive take on disk, estimated (vts/builder/shard.hpp,
// estimate_plan_size): tiles times docs/PLANET.md's measured bytes per tile, the rule
// deploy/batch/k8s/render.sh sizes its volume with (tests/integration/k8s_render.sh compares them).
#include <gtest/gtest.h>

#include "vts/builder/shard.hpp"

#include "synthetic_options.hpp"

namespace vts {
namespace {

TEST(ShardPlanSize, BytesPerTileFollowTheCodecAndTheMeasurements) {
  BuildOptions o = test::synthetic_options(3000, 1700);
  auto plan = make_shard_plan(o, 3, 0);
  ASSERT_TRUE(plan) << plan.error().message;
  EXPECT_EQ(estimate_plan_size_tile_bytes(*plan), 34'478u);  // measured at S = 264: T 256, B 4
  o.encode.filter = FilterChoice::none;
  plan = make_shard_plan(o, 3, 0);
  ASSERT_TRUE(plan);
  EXPECT_EQ(estimate_plan_size_tile_bytes(*plan), 66'475u);
  o.codec = CodecId::bc1;
  plan = make_shard_plan(o, 3, 0);
  ASSERT_TRUE(plan);
  EXPECT_EQ(estimate_plan_size_tile_bytes(*plan), 264u * 264u / 2);  // BC1's stored size
  o = test::synthetic_options(3000, 1700);
  o.tile_size = 512;
  o.border = 0;
  plan = make_shard_plan(o, 2, 0);
  ASSERT_TRUE(plan);
  // Scaled by the texels, rounded up: 34 478 * 512² / 264² = 129 681.
  EXPECT_EQ(estimate_plan_size_tile_bytes(*plan),
            (std::uint64_t{34'478} * 512 * 512 + 264 * 264 - 1) / (264 * 264));
}

TEST(ShardPlanSize, DensePlanCountsEveryTileOnce) {
  // Levels 0..4 have 1, 2, 6, 24 and 84 (12 x 7) tiles; split level 3, apex level 4.
  auto plan = make_shard_plan(test::synthetic_options(3000, 1700), 3, 0);
  ASSERT_TRUE(plan) << plan.error().message;
  ASSERT_EQ(plan->apex_level, 4);
  const PlanSizeEstimate e = estimate_plan_size(*plan);
  EXPECT_EQ(e.tile_bytes, 34'478u);
  EXPECT_EQ(e.apex, (1u + 2 + 6 + 24) * e.tile_bytes);
  EXPECT_EQ(e.archive, (1u + 2 + 6 + 24 + 84) * e.tile_bytes);
  // A shard's part: its level-4 tiles (at most 2 x 2, fewer at the image's edges) and, as its
  // attachment, the same tiles lossless again (the apex level is the finest here).
  EXPECT_EQ(e.shard_max, 2u * 4 * e.tile_bytes);
  std::uint64_t parts = 0;
  for (std::size_t i = 0; i < plan->shards.size(); ++i) {
    const std::uint64_t part = estimate_shard_part_bytes(*plan, i);
    EXPECT_GT(part, 0u) << "shard " << i;
    EXPECT_LE(part, e.shard_max) << "shard " << i;
    parts += part;
  }
  EXPECT_EQ(parts, 2u * 84 * e.tile_bytes);  // every finest tile once, plus its attachment copy
  EXPECT_EQ(estimate_shard_part_bytes(*plan, plan->shards.size()), 0u);  // no such shard
}

TEST(ShardPlanSize, ShardsMakingLevelZeroHaveNoApexAndNoAttachment) {
  auto plan = make_shard_plan(test::synthetic_options(3000, 1700), 0, 0, 0);
  ASSERT_TRUE(plan) << plan.error().message;
  ASSERT_EQ(plan->apex_level, 0);
  const PlanSizeEstimate e = estimate_plan_size(*plan);
  EXPECT_EQ(e.apex, 0u);
  EXPECT_EQ(e.archive, (1u + 2 + 6 + 24 + 84) * e.tile_bytes);
  EXPECT_EQ(e.shard_max, e.archive);  // one shard: the whole pyramid
}

TEST(ShardPlanSize, SparsePlanCountsOnlyItsShardsAndTheirAncestors) {
  BuildOptions o = test::synthetic_options(40000, 20000);  // levels 0..8
  const auto dense = make_shard_plan(o, 4, 0);
  o.synthetic->region = TexelRect{1000, 1000, 3000, 2500};
  o.synthetic->region_level = 2;  // in level 4's tile (0, 0) only (test_shard.cpp)
  const auto sparse = make_shard_plan(o, 4, 0);
  ASSERT_TRUE(dense && sparse);
  ASSERT_EQ(sparse->shards.size(), 1u);
  ASSERT_EQ(dense->shards.size(), 50u);
  const PlanSizeEstimate d = estimate_plan_size(*dense), s = estimate_plan_size(*sparse);
  ASSERT_EQ(sparse->apex_level, 6);
  // The apex: the shard's ancestors at levels 0..3 (one each) and its own tiles at levels 4 and 5
  // (1 + 4); the shard: its full sub-pyramid at levels 6..8 (16 + 64 + 256), inside the image.
  EXPECT_EQ(s.apex, (4u + 1 + 4) * s.tile_bytes);
  EXPECT_EQ(s.archive, (9u + 16 + 64 + 256) * s.tile_bytes);
  EXPECT_EQ(s.shard_max, (16u + 64 + 256 + 16) * s.tile_bytes);  // + its level-6 attachment
  EXPECT_LT(s.apex, d.apex);
  EXPECT_LT(s.archive, d.archive);
}

}  // namespace
}  // namespace vts
