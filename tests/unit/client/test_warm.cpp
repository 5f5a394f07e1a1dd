// The warm engine (warm_cache) in process, over archives built here and a real disk cache: what
// it counts, and that the cache then holds every tile it walked, pinned, byte for byte.
#include "vts/client/warm.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "vts/builder/builder.hpp"
#include "vts/client/disk_cache.hpp"
#include "vts/client/saved_source.hpp"
#include "vts/client/source.hpp"
#include "vts/test/temp_dir.hpp"

namespace fs = std::filesystem;
using namespace vts::client;
using vts::TileId;

namespace {

// A private temporary folder (vts::test::TempDir) whose path the tests name `d.path`.
struct WarmDir : vts::test::TempDir {
  WarmDir() : TempDir("vts-warm-test"), path(TempDir::path()) {}
  const fs::path path;
};

// 1000 x 600 texels, 256-texel tiles: levels 0-2. With a region, levels >= 1 hold only the tiles
// over it.
fs::path build_warm_archive(const fs::path& out,
                            std::optional<vts::TexelRect> region = std::nullopt) {
  vts::BuildOptions o;
  o.synthetic = vts::SyntheticSpec{1000, 600, region, 1};
  o.output = out;
  o.threads = 1;
  auto r = vts::build_synthetic_pyramid(o);
  EXPECT_TRUE(r.ok()) << r.error().to_string();
  return out;
}

std::shared_ptr<TileSource> open_warm_source(const fs::path& archive) {
  auto s = open_source(archive.string());
  EXPECT_TRUE(s.ok()) << s.error().to_string();
  return s.ok() ? std::shared_ptr<TileSource>(std::move(*s)) : nullptr;
}

WarmOptions options(std::shared_ptr<TileSource> source, const fs::path& cache_dir) {
  WarmOptions o;
  o.source = std::move(source);
  o.cache_dir = cache_dir;
  o.cache_bytes = 256ull << 20;
  o.last_level = o.source->info().info.geometry.max_zoom();
  o.concurrency = 4;
  return o;
}

// Every tile of levels first..last, by the geometry's own tile counts.
std::vector<TileId> every_tile(const vts::Geometry& g, int first, int last) {
  std::vector<TileId> out;
  for (int z = first; z <= last; ++z)
    for (std::uint32_t y = 0; y < g.tiles_y(z); ++y)
      for (std::uint32_t x = 0; x < g.tiles_x(z); ++x) out.push_back(TileId{std::uint8_t(z), x, y});
  return out;
}

// The source's answer for `id`: a local source answers inside TileSource::fetch().
SourceTile fetch_tile(TileSource& source, TileId id) {
  SourceTile got;
  SourceRequest r;
  r.id = id;
  source.fetch(r, [&](SourceTile&& t) { got = std::move(t); });
  return got;
}

TEST(Warm, StoresEveryTileOfALocalArchivePinnedAndByteForByte) {
  WarmDir d;
  auto source = open_warm_source(build_warm_archive(d.path / "dense.pmtiles"));
  ASSERT_TRUE(source);
  const vts::Geometry& g = source->info().info.geometry;
  ASSERT_EQ(g.max_zoom(), 2);
  const std::vector<TileId> tiles = every_tile(g, 0, 2);

  auto report = warm_cache(options(source, d.path / "cache"));
  ASSERT_TRUE(report.ok()) << report.error().to_string();
  EXPECT_EQ(report->tiles_total, tiles.size());
  EXPECT_EQ(report->network, tiles.size());
  EXPECT_EQ(report->cached, 0u);
  EXPECT_EQ(report->absent, 0u);
  EXPECT_EQ(report->failed, 0u);
  EXPECT_TRUE(report->first_errors.empty());
  EXPECT_FALSE(report->disk_error);
  EXPECT_TRUE(report->complete());
  EXPECT_EQ(report->cache.tiles, tiles.size());
  EXPECT_EQ(report->cache.pinned_tiles, tiles.size());

  DiskCacheOptions dco;
  dco.dir = d.path / "cache";
  auto disk = DiskCache::open(dco);
  ASSERT_TRUE(disk.ok()) << disk.error().to_string();
  std::uint64_t bytes = 0;
  for (TileId id : tiles) {
    auto held = (*disk)->get(source->info().key, id);
    ASSERT_TRUE(held.ok()) << held.error().to_string();
    ASSERT_TRUE(held->has_value()) << "tile " << id.to_string() << " is not in the cache";
    EXPECT_TRUE((*held)->pinned) << id.to_string();
    const SourceTile want = fetch_tile(*source, id);
    EXPECT_EQ((*held)->payload, want.payload) << id.to_string();
    bytes += want.payload.size();
  }
  EXPECT_EQ(report->bytes_network, bytes);
}

TEST(Warm, ASecondRunFindsEveryTileAlreadyCachedAndFetchesNothing) {
  WarmDir d;
  auto source = open_warm_source(build_warm_archive(d.path / "dense.pmtiles"));
  ASSERT_TRUE(source);
  auto first = warm_cache(options(source, d.path / "cache"));
  ASSERT_TRUE(first.ok()) << first.error().to_string();

  auto second = warm_cache(options(source, d.path / "cache"));
  ASSERT_TRUE(second.ok()) << second.error().to_string();
  EXPECT_EQ(second->tiles_total, first->tiles_total);
  EXPECT_EQ(second->cached, first->tiles_total);
  EXPECT_EQ(second->network, 0u);
  EXPECT_EQ(second->bytes_network, 0u);
  EXPECT_EQ(second->bytes_cached, first->bytes_network);
  EXPECT_TRUE(second->complete());
}

TEST(Warm, TilesASparseArchiveLacksCountAsAbsentAndTheRunIsComplete) {
  WarmDir d;
  // Levels 1 and 2 hold only the tiles over the top-left 256 x 256 texels.
  auto source = open_warm_source(
      build_warm_archive(d.path / "sparse.pmtiles", vts::TexelRect{0, 0, 256, 256}));
  ASSERT_TRUE(source);
  const vts::Geometry& g = source->info().info.geometry;
  auto report = warm_cache(options(source, d.path / "cache"));
  ASSERT_TRUE(report.ok()) << report.error().to_string();
  EXPECT_EQ(report->tiles_total, every_tile(g, 0, 2).size());
  EXPECT_EQ(report->network, 3u);  // 0/0/0, 1/0/0, 2/0/0
  EXPECT_EQ(report->absent, report->tiles_total - 3);
  EXPECT_EQ(report->failed, 0u);
  EXPECT_TRUE(report->complete());
  EXPECT_EQ(report->cache.tiles, 3u);
}

TEST(Warm, LevelsAndARegionBoundTheTilesWalked) {
  WarmDir d;
  auto source = open_warm_source(build_warm_archive(d.path / "dense.pmtiles"));
  ASSERT_TRUE(source);
  WarmOptions o = options(source, d.path / "cache");
  o.first_level = 1;
  o.last_level = 2;
  o.region = vts::TexelRect{0, 0, 300, 200};  // level 2: tiles x 0-1, y 0; level 1: tile 0/0
  EXPECT_EQ(warm_tile_count(source->info().info.geometry, 1, 2, *o.region), 3u);
  auto report = warm_cache(o);
  ASSERT_TRUE(report.ok()) << report.error().to_string();
  EXPECT_EQ(report->tiles_total, 3u);
  EXPECT_EQ(report->network, 3u);
  EXPECT_TRUE(report->complete());

  DiskCacheOptions dco;
  dco.dir = d.path / "cache";
  auto disk = DiskCache::open(dco);
  ASSERT_TRUE(disk.ok()) << disk.error().to_string();
  const std::string& key = source->info().key;
  for (TileId id : {TileId{1, 0, 0}, TileId{2, 0, 0}, TileId{2, 1, 0}}) {
    auto has = (*disk)->contains(key, id);
    ASSERT_TRUE(has.ok());
    EXPECT_TRUE(*has) << id.to_string();
  }
  for (TileId id : {TileId{0, 0, 0}, TileId{2, 2, 0}, TileId{2, 0, 1}}) {
    auto has = (*disk)->contains(key, id);
    ASSERT_TRUE(has.ok());
    EXPECT_FALSE(*has) << id.to_string() << " is outside the levels or the region";
  }
}

TEST(Warm, FailedTilesAreCountedAndTheRunStopsAfterMaxErrors) {
  WarmDir d;
  auto local = open_warm_source(build_warm_archive(d.path / "dense.pmtiles"));
  ASSERT_TRUE(local);
  // The offline source fails every fetch, as an unreachable upstream does.
  std::shared_ptr<TileSource> offline = offline_source(local->info());
  WarmOptions o = options(offline, d.path / "cache");
  o.concurrency = 1;
  o.max_errors = 3;
  auto report = warm_cache(o);
  ASSERT_TRUE(report.ok()) << report.error().to_string();
  EXPECT_TRUE(report->too_many_errors);
  EXPECT_EQ(report->failed, 3u);
  EXPECT_EQ(report->network + report->cached + report->absent, 0u);
  EXPECT_LT(report->done(), report->tiles_total);
  ASSERT_EQ(report->first_errors.size(), 3u);
  EXPECT_EQ(report->first_errors[0].rfind("tile 0/0/0: ", 0), 0u) << report->first_errors[0];
  EXPECT_FALSE(report->complete());
}

TEST(Warm, AStopRequestedBeforeTheStartFailsCancelledAndLeavesNoCacheFolder) {
  WarmDir d;
  auto source = open_warm_source(build_warm_archive(d.path / "dense.pmtiles"));
  ASSERT_TRUE(source);
  std::atomic<bool> stop{true};
  WarmOptions o = options(source, d.path / "cache");
  o.stop = &stop;
  auto report = warm_cache(o);
  ASSERT_FALSE(report.ok());
  EXPECT_EQ(report.error().code, vts::ErrorCode::cancelled);
  EXPECT_FALSE(fs::exists(d.path / "cache"));
}

TEST(Warm, RemembersTheSourceInTheCacheFolderWhenAsked) {
  WarmDir d;
  auto source = open_warm_source(build_warm_archive(d.path / "dense.pmtiles"));
  ASSERT_TRUE(source);
  WarmOptions o = options(source, d.path / "cache");
  o.remember_as = "http://example.invalid/dense";
  auto report = warm_cache(o);
  ASSERT_TRUE(report.ok()) << report.error().to_string();
  auto saved = load_source_info(d.path / "cache", "http://example.invalid/dense");
  ASSERT_TRUE(saved.ok()) << saved.error().to_string();
  EXPECT_EQ(saved->key, source->info().key);
}

TEST(Warm, ASavedSourceNestedDeeperThanAnyWeWriteIsRefusedNamingTheFile) {
  // The cache folder may be shared or damaged: its metadata was dumped recursively once read, and
  // 100,000 levels overflowed the stack.
  WarmDir d;
  auto source = open_warm_source(build_warm_archive(d.path / "dense.pmtiles"));
  ASSERT_TRUE(source);
  WarmOptions o = options(source, d.path / "cache");
  o.remember_as = "http://example.invalid/dense";
  ASSERT_TRUE(warm_cache(o).ok());
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(d.path / "cache" / "sources")) files.push_back(e);
  ASSERT_EQ(files.size(), 1u);
  std::string text;
  {
    std::ifstream in(files[0]);
    text.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  const std::string key = "\"metadata\": {";
  const std::size_t at = text.find(key);
  ASSERT_NE(at, std::string::npos) << text;
  text.insert(at + key.size(),
              "\"x\": " + std::string(100000, '[') + std::string(100000, ']') + ",");
  std::ofstream(files[0]) << text;
  auto saved = load_source_info(d.path / "cache", "http://example.invalid/dense");
  ASSERT_FALSE(saved.ok());
  EXPECT_EQ(saved.error().code, vts::ErrorCode::corrupt);
  EXPECT_NE(saved.error().message.find(files[0].string()), std::string::npos)
      << saved.error().message;
  EXPECT_NE(saved.error().message.find("deeper than 64 levels"), std::string::npos)
      << saved.error().message;
}

TEST(Warm, ReportsProgressUpToTheTotalOnTheCallingThread) {
  WarmDir d;
  auto source = open_warm_source(build_warm_archive(d.path / "dense.pmtiles"));
  ASSERT_TRUE(source);
  WarmOptions o = options(source, d.path / "cache");
  std::vector<WarmProgress> seen;
  const auto caller = std::this_thread::get_id();
  bool other_thread = false;
  o.progress = [&](const WarmProgress& p) {
    other_thread |= std::this_thread::get_id() != caller;
    seen.push_back(p);
  };
  auto report = warm_cache(o);
  ASSERT_TRUE(report.ok()) << report.error().to_string();
  ASSERT_FALSE(seen.empty());
  EXPECT_FALSE(other_thread);
  for (std::size_t i = 0; i < seen.size(); ++i) {
    EXPECT_EQ(seen[i].total, report->tiles_total);
    EXPECT_LE(seen[i].done, seen[i].total);
    if (i > 0) {
      EXPECT_GE(seen[i].done, seen[i - 1].done);
    }
  }
}

TEST(Warm, TheJsonReportCarriesTheCountsAndTheRequest) {
  WarmDir d;
  auto source = open_warm_source(build_warm_archive(d.path / "dense.pmtiles"));
  ASSERT_TRUE(source);
  WarmOptions o = options(source, d.path / "cache");
  o.region = vts::TexelRect{0, 0, 300, 200};
  auto report = warm_cache(o);
  ASSERT_TRUE(report.ok()) << report.error().to_string();
  const nlohmann::json j = warm_report_json(o, *report);
  EXPECT_EQ(j["source"], source->info().key);
  EXPECT_EQ(j["cache_dir"], (d.path / "cache").string());
  EXPECT_EQ(j["levels"], nlohmann::json({0, 2}));
  EXPECT_EQ(j["region"], nlohmann::json({0, 0, 300, 200}));
  EXPECT_EQ(j["tiles_total"], report->tiles_total);
  EXPECT_EQ(j["from_network"], report->network);
  EXPECT_EQ(j["already_cached"], 0);
  EXPECT_EQ(j["not_done"], 0);
  EXPECT_EQ(j["complete"], true);
  EXPECT_EQ(j["interrupted"], false);
  EXPECT_TRUE(j["disk_error"].is_null());
  EXPECT_EQ(j["cache"]["pinned_tiles"], report->tiles_total);
}

}  // namespace

namespace {

vts::TilesetInfo georeferenced(vts::Tiling t, std::uint64_t w, std::uint64_t h,
                               vts::LonLatBounds bounds) {
  vts::TilesetInfo info;
  info.geometry = *vts::Geometry::create(w, h, 256, 4);
  info.georeference = vts::Georeference{t, bounds, {}};
  return info;
}

}  // namespace

TEST(WarmBbox, TheRegionOfABoxIsTheFootprintOfTheBoxClippedToTheTilesetsBounds) {
  using vts::LonLatBounds;
  const auto t = vts::Tiling::world_crs84_quad;
  const LonLatBounds bounds{-10.5, 35.25, 30.125, 60.1};
  const auto info = georeferenced(t, 16384, 8192, bounds);
  // 16384 texels over 360 degrees: 45.5111 texels per degree, (0, 90) at the top-left.
  auto inside = vts::client::bbox_region(info, {0, 40, 10, 50});
  ASSERT_TRUE(inside) << inside.error().message;
  EXPECT_EQ(*inside, vts::footprint_texels(t, info.geometry, {0, 40, 10, 50}));
  EXPECT_EQ(inside->x0, 8192u);
  EXPECT_EQ(inside->y0, 1820u);  // floor((90 - 50) * 16384 / 360) = floor(1820.44)
  auto straddling = vts::client::bbox_region(info, {-20, 30, 0, 45});
  ASSERT_TRUE(straddling);
  EXPECT_EQ(*straddling, vts::footprint_texels(t, info.geometry, {-10.5, 35.25, 0, 45}));
  auto world = vts::client::bbox_region(info, {-180, -90, 180, 90});
  ASSERT_TRUE(world);
  EXPECT_EQ(*world, vts::footprint_texels(t, info.geometry, bounds));
  auto outside = vts::client::bbox_region(info, {100, 0, 110, 10});
  ASSERT_TRUE(outside);
  EXPECT_TRUE(outside->empty());
  EXPECT_EQ(vts::client::warm_tile_count(info.geometry, 0, info.geometry.max_zoom(), *outside), 0u);
}

TEST(WarmBbox, ABoxNeedsAGeoreferenceAndWestBeforeEastAndSouthBeforeNorth) {
  vts::TilesetInfo plain;
  plain.geometry = *vts::Geometry::create(600, 300, 256, 4);
  auto r = vts::client::bbox_region(plain, {0, 0, 1, 1});
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().code, vts::ErrorCode::invalid_argument);
  EXPECT_NE(r.error().message.find("georeference"), std::string::npos);
  const auto info =
      georeferenced(vts::Tiling::web_mercator_quad, 4096, 4096, {2.2, 48.8, 2.5, 48.95});
  EXPECT_FALSE(vts::client::bbox_region(info, {3, 48, 2, 49}));    // antimeridian / inverted
  EXPECT_FALSE(vts::client::bbox_region(info, {2, 49, 3, 48}));    // south above north
  EXPECT_FALSE(vts::client::bbox_region(info, {2, 48, 2, 49}));    // zero width
  EXPECT_FALSE(vts::client::bbox_region(info, {2, 48, NAN, 49}));  // not finite
  EXPECT_TRUE(vts::client::bbox_region(info, {2, 48, 3, 49}));
}
