// Plans of sharded builds (vts/builder/shard.hpp): the JSON round trip and its hash, the shards a
// plan picks (in Hilbert order, only sub-pyramids with tiles, the smallest level giving N), input
// fingerprints, the halo a shard reads, and incremental updates (the inputs a shard reads, the
// shards a changed input reaches, stale parts refused).
#include "vts/builder/shard.hpp"

#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "cascade.hpp"
#include "shard_geo.hpp"
#include "synthetic_options.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/test/temp_dir.hpp"

namespace vts {
namespace {

namespace fs = std::filesystem;
namespace OIIO = OIIO_NAMESPACE;

TEST(ShardPlan, JsonRoundTripsAndItsHashCoversEveryField) {
  BuildOptions o = test::synthetic_options(3000, 1700);
  o.codec = CodecId::bc1;
  o.encode.bc1 = Bc1Quality::high;
  o.downsample = DownsampleFilter::lanczos3;
  o.synthetic->region = TexelRect{100, 200, 900, 1000};
  o.synthetic->region_level = 2;
  o.name = "planet";
  auto plan = make_shard_plan(o, 3, 0);
  ASSERT_TRUE(plan) << plan.error().to_string();
  const std::string text = plan_to_json(*plan);
  auto back = plan_from_json(text);
  ASSERT_TRUE(back) << back.error().to_string();
  EXPECT_EQ(plan_to_json(*back), text);
  EXPECT_EQ(back->hash, plan->hash);
  EXPECT_EQ(back->split_level, 3);
  EXPECT_EQ(back->apex_level, std::min(3 + kDefaultApexLevels, plan->max_zoom));
  EXPECT_EQ(back->apex_level, plan->apex_level);
  // The apex level is part of the build: another one is another build hash.
  auto other = make_shard_plan(o, 3, 0, 0);
  ASSERT_TRUE(other);
  EXPECT_EQ(other->apex_level, 3);
  EXPECT_NE(other->build_hash, plan->build_hash);
  EXPECT_FALSE(make_shard_plan(o, 3, 0, -1));
  EXPECT_EQ(back->options.codec, CodecId::bc1);
  EXPECT_EQ(back->options.encode.bc1, Bc1Quality::high);
  EXPECT_EQ(back->options.downsample, DownsampleFilter::lanczos3);
  ASSERT_TRUE(back->options.synthetic && back->options.synthetic->region);
  EXPECT_EQ(*back->options.synthetic->region, (TexelRect{100, 200, 900, 1000}));
  EXPECT_EQ(back->options.name, "planet");
  EXPECT_EQ(back->shards.size(), plan->shards.size());
  // Any change to the content without a new hash is refused.
  std::string tampered = text;
  tampered.replace(tampered.find("\"planet\""), 8, "\"planes\"");
  auto bad = plan_from_json(tampered);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message.find("hash"), std::string::npos);
  EXPECT_FALSE(plan_from_json("{}"));
  EXPECT_FALSE(plan_from_json("not json"));
}

TEST(ShardPlan, ShardsAreTheSplitLevelTilesInHilbertOrder) {
  // 3000x1700 at T = 256: levels 0..4, level 3 is 6x4 tiles.
  auto plan = make_shard_plan(test::synthetic_options(3000, 1700), 3, 0);
  ASSERT_TRUE(plan);
  ASSERT_EQ(plan->shards.size(), 24u);
  for (std::size_t i = 1; i < plan->shards.size(); ++i) {
    const TileId a = plan->shards[i - 1], b = plan->shards[i];
    EXPECT_LT(archive::zxy_to_tile_id(a.z, a.x, a.y), archive::zxy_to_tile_id(b.z, b.x, b.y));
  }
  // Not row-major: the Hilbert curve starts down the first column.
  EXPECT_EQ(plan->shards[1].x, 0u);
  EXPECT_EQ(plan->shards[1].y, 1u);
}

TEST(ShardPlan, ShardCountPicksTheSmallestLevelGivingThem) {
  const BuildOptions o = test::synthetic_options(3000, 1700);  // levels: 1, 2, 6, 24, 84 tiles
  struct ShardCase {
    std::uint64_t n;
    int level;
    std::size_t shards;
  };
  for (const ShardCase c : {ShardCase{1, 0, 1}, ShardCase{2, 1, 2}, ShardCase{4, 2, 6},
                            ShardCase{7, 3, 24}, ShardCase{25, 4, 84}, ShardCase{1000000, 4, 84}}) {
    auto plan = make_shard_plan(o, std::nullopt, c.n);
    ASSERT_TRUE(plan);
    EXPECT_EQ(plan->split_level, c.level) << c.n;
    EXPECT_EQ(plan->shards.size(), c.shards) << c.n;
  }
  EXPECT_FALSE(make_shard_plan(o, 5, 0));  // beyond the finest level
}

TEST(ShardPlan, SparseRegionKeepsOnlyShardsWithTiles) {
  BuildOptions o = test::synthetic_options(40000, 20000);  // levels 0..8
  o.synthetic->region = TexelRect{1000, 1000, 3000, 2500};
  o.synthetic->region_level = 2;
  auto plan = make_shard_plan(o, 4, 0);
  ASSERT_TRUE(plan);
  // Level 4 tiles cover 4096 finest texels: the region lies in tile (0, 0) only.
  ASSERT_EQ(plan->shards.size(), 1u);
  EXPECT_EQ(plan->shards[0], (TileId{4, 0, 0}));
  // Above the region level every tile has tiles below it.
  auto coarse = make_shard_plan(o, 1, 0);
  ASSERT_TRUE(coarse);
  EXPECT_EQ(coarse->shards.size(), 2u);
}

TEST(ShardPlan, FingerprintFollowsContentNotTheFile) {
  test::TempDir dir;
  const fs::path a = dir.path() / "a.bin", b = dir.path() / "b.bin";
  std::string bytes(5 << 20, 'x');
  for (std::size_t i = 0; i < bytes.size(); i += 4097) bytes[i] = static_cast<char>(i);
  std::ofstream(a, std::ios::binary) << bytes;
  fs::copy_file(a, b);
  auto fa = input_fingerprint(a), fb = input_fingerprint(b);
  ASSERT_TRUE(fa && fb);
  EXPECT_EQ(*fa, *fb);  // a copy (another mtime) has the same fingerprint
  // One sample at 1/64 of the way in the middle of the file, beyond the first and last MiB.
  bytes[(bytes.size() / 64) * 30 + 10] ^= 1;
  std::ofstream(b, std::ios::binary | std::ios::trunc) << bytes;
  auto fc = input_fingerprint(b);
  ASSERT_TRUE(fc);
  EXPECT_NE(*fa, *fc);
  EXPECT_FALSE(input_fingerprint(dir.path() / "missing.bin"));
}

TEST(ShardPlan, ShardReadsItsCorePlusTheHaloOfItsLevels) {
  test::TempDir dir;
  // A synthetic plan reads nothing; an image's shard reads its core plus the halo.
  const fs::path img = dir.path() / "img.png";
  {
    auto plan = make_shard_plan(test::synthetic_options(2048, 1024), 1, 0);
    ASSERT_TRUE(plan);
    ShardBuildOptions so;
    so.out_dir = dir.path() / "parts";
    so.threads = 1;
    auto r = build_shard(*plan, 0, so);
    ASSERT_TRUE(r) << r.error().to_string();
    EXPECT_EQ(r->texels_read, 0u);
    EXPECT_TRUE(fs::exists(so.out_dir / "shard-000000.part"));
    auto out = build_shard(*plan, 2, so);
    ASSERT_FALSE(out);
    EXPECT_NE(out.error().message.find("out of range"), std::string::npos);
  }
  const std::uint64_t W = 2048, H = 1024;
  {
    std::vector<std::uint8_t> px(W * H * 3, 128);
    auto o = OIIO::ImageOutput::create(img.string());
    ASSERT_TRUE(o);
    OIIO::ImageSpec spec(int(W), int(H), 3, OIIO::TypeDesc::UINT8);
    ASSERT_TRUE(o->open(img.string(), spec));
    ASSERT_TRUE(o->write_image(OIIO::TypeDesc::UINT8, px.data()));
    o->close();
  }
  for (DownsampleFilter f : {DownsampleFilter::box, DownsampleFilter::lanczos3})
    for (int k : {0, 1, 2}) {
      BuildOptions o;
      o.inputs = {img};
      o.downsample = f;
      auto plan = make_shard_plan(o, 1, 0, k);  // 2 shards of 1024 x 1024 finest texels
      ASSERT_TRUE(plan);
      ASSERT_EQ(plan->shards.size(), 2u);
      ASSERT_EQ(plan->max_zoom, 3);
      EXPECT_EQ(plan->apex_level, std::min(1 + k, 3));
      ShardBuildOptions so;
      so.out_dir = dir.path() / ("img_parts" + std::to_string(k));
      so.threads = 1;
      auto r = build_shard(*plan, 0, so);
      ASSERT_TRUE(r) << r.error().to_string();
      auto g = Geometry::create(W, H);
      ASSERT_TRUE(g);
      // Levels 3 down to the apex level A, whose tiles (borders too) are kept: as if level A - 1
      // were made. k = 0: A = 1, 3 levels; k = 1: A = 2, 2; k = 2: A = 3 (the max zoom), 1.
      const std::uint64_t halo = detail::stripe_halo(*g, 3 - plan->apex_level + 1, f);
      EXPECT_GE(halo, 4u);
      if (k > 0) {
        EXPECT_LT(halo, detail::stripe_halo(*g, 3, f));
      }
      // Shard 0 is the left half: its window reaches `halo` texels into the right half only.
      EXPECT_EQ(r->core_texels, 1024u * 1024u);
      EXPECT_EQ(r->texels_read, (1024u + halo) * 1024u);
      // Its attachment: its level-A tiles, 4^(A - 1) of them (2^(A - 1) square, the left half).
      auto info = archive::read_part_info(r->part);
      ASSERT_TRUE(info) << info.error().to_string();
      auto tiles = decode_apex_tiles(info->attachment);
      ASSERT_TRUE(tiles) << tiles.error().to_string();
      const std::uint32_t side = 1u << (plan->apex_level - 1);
      ASSERT_EQ(tiles->size(), std::size_t{side} * side);
      for (std::uint32_t i = 0; i < tiles->size(); ++i) {
        EXPECT_EQ((*tiles)[i].x, i % side);
        EXPECT_EQ((*tiles)[i].y, i / side);
      }
    }
}

TEST(ShardPlan, ApexTilesRoundTripAndBadAttachmentsAreCorrupt) {
  std::vector<ApexTile> tiles = {{3, 1, {1, 2, 3}}, {4, 1, {}}, {3, 2, {9}}};
  const std::vector<std::uint8_t> a = encode_apex_tiles(tiles);
  // u32 count, then per tile u32 x, u32 y, u64 length and the payload.
  ASSERT_EQ(a.size(), 4u + 3 * 16u + 4u);
  EXPECT_EQ(a[0], 3u);
  auto back = decode_apex_tiles(a);
  ASSERT_TRUE(back) << back.error().to_string();
  ASSERT_EQ(back->size(), 3u);
  EXPECT_EQ((*back)[0].x, 3u);
  EXPECT_EQ((*back)[2].y, 2u);
  EXPECT_EQ((*back)[0].payload, (std::vector<std::uint8_t>{1, 2, 3}));
  EXPECT_TRUE((*back)[1].payload.empty());
  EXPECT_TRUE(decode_apex_tiles(encode_apex_tiles({})));
  for (std::size_t cut : {std::size_t{0}, std::size_t{3}, std::size_t{10}, a.size() - 1}) {
    auto bad = decode_apex_tiles(std::vector<std::uint8_t>(a.begin(), a.begin() + cut));
    ASSERT_FALSE(bad) << cut;
    EXPECT_EQ(bad.error().code, ErrorCode::corrupt);
  }
  std::vector<std::uint8_t> more = a;
  more.push_back(0);
  auto extra = decode_apex_tiles(more);
  ASSERT_FALSE(extra);
  EXPECT_NE(extra.error().message.find("after its last tile"), std::string::npos);
}

void write_png(const fs::path& path, int w, int h, std::uint8_t value) {
  std::vector<std::uint8_t> px(std::size_t(w) * std::size_t(h) * 3, value);
  for (std::size_t i = 0; i < px.size(); i += 7) px[i] = static_cast<std::uint8_t>(i / 7);
  auto o = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(o);
  OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::UINT8);
  ASSERT_TRUE(o->open(path.string(), spec));
  ASSERT_TRUE(o->write_image(OIIO::TypeDesc::UINT8, px.data()));
  o->close();
}

// A 2x2 --grid of 512 x 512 cells (a 1024 x 1024 image), split at level 2: 16 shards of 256².
struct GridPlan {
  test::TempDir dir;
  BuildOptions options;
  GridPlan() {
    for (int i = 0; i < 4; ++i) {
      const fs::path p = dir.path() / ("cell" + std::to_string(i) + ".png");
      write_png(p, 512, 512, static_cast<std::uint8_t>(40 * i));
      options.inputs.push_back(p);
    }
    options.grid_columns = options.grid_rows = 2;
  }
};

TEST(ShardUpdate, InputsAreTheGridCellsAShardsWindowMeets) {
  GridPlan grid;
  auto plan = make_shard_plan(grid.options, 2, 0);
  ASSERT_TRUE(plan) << plan.error().to_string();
  ASSERT_EQ(plan->shards.size(), 16u);
  EXPECT_EQ(plan->column_widths, (std::vector<std::uint64_t>{512, 512}));
  EXPECT_EQ(input_rect(*plan, 3), (TexelRect{512, 512, 1024, 1024}));
  auto back = plan_from_json(plan_to_json(*plan));
  ASSERT_TRUE(back);
  EXPECT_EQ(back->row_heights, plan->row_heights);
  EXPECT_EQ(back->build_hash, plan->build_hash);
  for (std::size_t s = 0; s < plan->shards.size(); ++s) {
    const TileId t = plan->shards[s];
    // A shard's window reaches its core's neighbours by the halo (< 256): a shard at tile column
    // 1 or 2 meets both columns of cells, at 0 or 3 one.
    std::vector<std::size_t> want;
    for (std::size_t r = 0; r < 2; ++r)
      for (std::size_t c = 0; c < 2; ++c) {
        const bool col = c == 0 ? t.x <= 2 : t.x >= 1, row = r == 0 ? t.y <= 2 : t.y >= 1;
        if (col && row) want.push_back(r * 2 + c);
      }
    EXPECT_EQ(shard_inputs(*plan, s), want) << int(t.x) << "," << int(t.y);
  }
  // Cell 0 (top left) reaches the 3 x 3 shards at tile columns and rows 0..2: not all 16.
  const std::vector<std::size_t> hit = affected_shards(*plan, {0});
  ASSERT_EQ(hit.size(), 9u);
  for (std::size_t s : hit) EXPECT_TRUE(plan->shards[s].x <= 2 && plan->shards[s].y <= 2);
  EXPECT_TRUE(affected_shards(*plan, {}).empty());
}

TEST(ShardUpdate, APlainImageReachesEveryShardAndSyntheticNone) {
  GridPlan grid;
  BuildOptions o;
  o.inputs = {grid.options.inputs[0]};
  auto plan = make_shard_plan(o, 1, 0);  // 512 x 512: 4 shards
  ASSERT_TRUE(plan);
  EXPECT_EQ(affected_shards(*plan, {0}).size(), plan->shards.size());
  auto synth = make_shard_plan(test::synthetic_options(2048, 1024), 2, 0);
  ASSERT_TRUE(synth);
  EXPECT_TRUE(shard_inputs(*synth, 0).empty());
  auto u = update_shard_plan(*synth, {});
  ASSERT_TRUE(u);
  EXPECT_TRUE(u->shards.empty());
  EXPECT_FALSE(u->apex);
  EXPECT_FALSE(update_shard_plan(*synth, {grid.options.inputs[0]}));
}

TEST(ShardUpdate, UpdateListsTheShardsOfTheChangedInputAndRefusesAnotherBuild) {
  GridPlan grid;
  auto plan = make_shard_plan(grid.options, 2, 0);
  ASSERT_TRUE(plan);
  auto same = update_shard_plan(*plan, {});
  ASSERT_TRUE(same) << same.error().to_string();
  EXPECT_TRUE(same->changed_inputs.empty() && same->shards.empty() && !same->apex);
  EXPECT_EQ(same->plan.hash, plan->hash);
  write_png(grid.options.inputs[3], 512, 512, 250);  // the bottom right cell changes
  auto u = update_shard_plan(*plan, {});
  ASSERT_TRUE(u) << u.error().to_string();
  EXPECT_EQ(u->changed_inputs, (std::vector<std::size_t>{3}));
  EXPECT_EQ(u->shards, affected_shards(*plan, {3}));
  EXPECT_EQ(u->shards.size(), 9u);
  EXPECT_TRUE(u->apex);
  EXPECT_EQ(u->plan.build_hash, plan->build_hash);
  EXPECT_NE(u->plan.hash, plan->hash);
  EXPECT_EQ(u->plan.shards, plan->shards);
  // Another count of inputs, or a cell of another size, is refused naming it.
  auto few = update_shard_plan(*plan, {grid.options.inputs[0]});
  ASSERT_FALSE(few);
  EXPECT_NE(few.error().message.find("1 inputs given, the plan has 4"), std::string::npos);
  for (int i = 0; i < 2; ++i)  // the whole left column narrower: another image width
    write_png(grid.options.inputs[std::size_t(i) * 2], 500, 512, 1);
  auto narrow = update_shard_plan(*plan, {});
  ASSERT_FALSE(narrow);
  EXPECT_NE(narrow.error().message.find("1012x1024"), std::string::npos) << narrow.error().message;
}

TEST(ShardUpdate, PartsOfChangedInputsAreStaleForTheApexAndTheMerge) {
  GridPlan grid;
  auto plan = make_shard_plan(grid.options, 2, 0);
  ASSERT_TRUE(plan);
  ShardBuildOptions so;
  so.out_dir = grid.dir.path() / "parts";
  so.threads = 1;
  for (std::size_t s = 0; s < plan->shards.size(); ++s) ASSERT_TRUE(build_shard(*plan, s, so));
  ASSERT_TRUE(build_apex(*plan, so));
  const fs::path out = grid.dir.path() / "out.pmtiles";
  ASSERT_TRUE(merge_plan(*plan, so.out_dir, out, nullptr, nullptr));
  write_png(grid.options.inputs[0], 512, 512, 7);
  auto u = update_shard_plan(*plan, {});
  ASSERT_TRUE(u);
  ASSERT_FALSE(u->shards.empty());
  const std::size_t first = u->shards.front();
  auto apex = build_apex(u->plan, so);
  ASSERT_FALSE(apex);
  EXPECT_NE(apex.error().message.find("stale"), std::string::npos) << apex.error().message;
  for (std::size_t s : u->shards)
    if (s != first) {
      ASSERT_TRUE(build_shard(u->plan, s, so));
    }
  auto merged = merge_plan(u->plan, so.out_dir, out, nullptr, nullptr);
  ASSERT_FALSE(merged);
  EXPECT_NE(merged.error().message.find(
                shard_part_name(first) + " is stale: input " + grid.options.inputs[0].string() +
                " changed since it was built; rebuild shard " + std::to_string(first)),
            std::string::npos)
      << merged.error().message;
  ASSERT_TRUE(build_shard(u->plan, first, so));
  // Every shard is fresh; the apex is not.
  merged = merge_plan(u->plan, so.out_dir, out, nullptr, nullptr);
  ASSERT_FALSE(merged);
  EXPECT_NE(merged.error().message.find("apex.part is stale"), std::string::npos)
      << merged.error().message;
  ASSERT_TRUE(build_apex(u->plan, so));
  EXPECT_TRUE(merge_plan(u->plan, so.out_dir, out, nullptr, nullptr));
}

// A georeferenced plan: 4096 x 2048 WorldCRS84Quad texels (0.087890625 degrees each) and the
// inputs' extents in degrees.
ShardPlan geo_plan(std::vector<LonLatBounds> extents) {
  ShardPlan p;
  p.width = 4096;
  p.height = 2048;
  p.max_zoom = 4;
  GeoPlan g;
  g.georeference.tiling = Tiling::world_crs84_quad;
  g.georeference.bounds = {-180, -90, 180, 90};
  g.inputs = true;
  g.input_bounds = std::move(extents);
  for (std::size_t i = 0; i < g.input_bounds.size(); ++i)
    p.inputs.push_back({"in" + std::to_string(i) + ".tif", 1, "0"});
  p.geo = g;
  return p;
}

TEST(ShardGeo, AShardOpensOnlyTheInputsWhoseExtentMeetsItsWindowInTheirOrder) {
  // Texels (rounded out): lon 0..40 is x 2048..2504, lat 40..10 is y 568..911; the second
  // is the south-west corner, x 0..114, y 1934..2048.
  const ShardPlan plan = geo_plan({{0, 10, 40, 40}, {-180, -90, -170, -80}, {30, 0, 50, 20}});
  auto g = Geometry::create(4096, 2048, 256, 4);
  ASSERT_TRUE(g);
  using V = std::vector<std::size_t>;
  EXPECT_EQ(detail::plan_inputs_meeting(plan, *g, {0, 0, 4096, 2048}), (V{0, 1, 2}));
  EXPECT_EQ(detail::plan_inputs_meeting(plan, *g, {2000, 500, 2100, 600}), (V{0}));
  EXPECT_EQ(detail::plan_inputs_meeting(plan, *g, {0, 1900, 200, 2048}), (V{1}));
  // Where the first and the third overlap: both, the first first (later ones composite over it).
  EXPECT_EQ(detail::plan_inputs_meeting(plan, *g, {2400, 850, 2450, 900}), (V{0, 2}));
  // Windows that only touch an extent's edge do not meet it; none at all.
  EXPECT_EQ(detail::plan_inputs_meeting(plan, *g, {2000, 500, 2048, 569}), V{});
  EXPECT_EQ(detail::plan_inputs_meeting(plan, *g, {100, 100, 400, 400}), V{});
  // A plan of plain images opens all of them.
  ShardPlan plain = plan;
  plain.geo.reset();
  EXPECT_EQ(detail::plan_inputs_meeting(plain, *g, {100, 100, 400, 400}), (V{0, 1, 2}));
}

TEST(ShardGeo, TheGeoreferenceRoundTripsThroughThePlanJson) {
  BuildOptions o;
  o.synthetic = SyntheticSpec{16384, 8192, std::nullopt, 0};
  o.tiling = Tiling::world_crs84_quad;
  o.bounds = LonLatBounds{-10.5, 35.25, 30.125, 60.1};
  auto plan = make_shard_plan(o, 2, 0);
  ASSERT_TRUE(plan) << plan.error().to_string();
  ASSERT_TRUE(plan->geo);
  EXPECT_EQ(plan->geo->georeference.bounds, *o.bounds);
  EXPECT_FALSE(plan->geo->inputs);
  auto back = plan_from_json(plan_to_json(*plan));
  ASSERT_TRUE(back) << back.error().to_string();
  ASSERT_TRUE(back->geo);
  EXPECT_EQ(back->geo->georeference.bounds, plan->geo->georeference.bounds);
  EXPECT_EQ(back->geo->georeference.center, plan->geo->georeference.center);
  EXPECT_EQ(back->options.tiling, Tiling::world_crs84_quad);
  EXPECT_EQ(back->options.bounds, o.bounds);
  EXPECT_EQ(back->shards, plan->shards);
}

}  // namespace
}  // namespace vts
