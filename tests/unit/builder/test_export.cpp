#include "vts/builder/export.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "vts/archive/pmtiles.hpp"
#include "vts/imaging/web_mercator.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/test/temp_dir.hpp"

namespace vts {
namespace {

namespace fs = std::filesystem;
using TempDir = vts::test::TempDir;

// A 600x300 image, T = 256, B = 4: level 0 one tile, level 1 2x1, level 2 3x2. Tile 2/1/0 is
// absent (sparse), 2/2/1 wholly transparent, 2/0/1 and 2/1/1 the same colour (same output).
constexpr TileId kAbsent{2, 1, 0}, kClear{2, 2, 1}, kTwinA{2, 0, 1}, kTwinB{2, 1, 1};

TileImage stored_tile(const Geometry& g, TileId id) {
  TileImage img;
  img.width = img.height = g.stored_size();
  img.pixels.resize(std::size_t{img.width} * img.height * 4);
  const bool twin = id == kTwinA || id == kTwinB;
  for (std::size_t i = 0; i < img.pixels.size(); i += 4) {
    const std::size_t t = i / 4;
    img.pixels[i] = static_cast<std::uint8_t>(twin ? 7 : id.z * 40 + (t % 7));
    img.pixels[i + 1] = static_cast<std::uint8_t>(twin ? 9 : id.x * 50 + (t % 13));
    img.pixels[i + 2] = static_cast<std::uint8_t>(twin ? 11 : id.y * 60);
    img.pixels[i + 3] = id == kClear ? 0 : 255;
  }
  return img;
}

struct Source {
  TilesetInfo info;
  fs::path path;
  std::shared_ptr<archive::Reader> reader;
};

// Writes the archive with our own writer and codec: what `vts build` would have written.
Source make_source(const TempDir& dir, std::optional<Georeference> geo = {}, std::uint64_t w = 600,
                   std::uint64_t h = 300) {
  Source s;
  s.info.geometry = Geometry::create(w, h, 256, 4).value();
  s.info.name = "t";
  s.info.description = "test tiles";
  s.info.sparse = true;
  s.info.georeference = geo;
  s.path = dir / "src.pmtiles";
  archive::WriterOptions o;
  o.path = s.path;
  auto writer = archive::Writer::create(o).value();
  const Geometry& g = s.info.geometry;
  for (int z = 0; z <= g.max_zoom(); ++z)
    for (std::uint32_t y = 0; y < g.tiles_y(z); ++y)
      for (std::uint32_t x = 0; x < g.tiles_x(z); ++x) {
        const TileId id{static_cast<std::uint8_t>(z), x, y};
        if (id == kAbsent) continue;
        auto payload = encode_lossless(stored_tile(g, id)).value();
        EXPECT_TRUE(writer->add_tile(id, payload));
      }
  EXPECT_TRUE(writer->finish(s.info.to_json()));
  s.reader = archive::Reader::open(s.path).value();
  return s;
}

std::set<std::string> listing(const fs::path& dir) {
  std::set<std::string> names;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    names.insert(fs::relative(e.path(), dir).string());
  return names;
}

TEST(Export, PngArchiveHoldsEveryVisibleTileEqualToItsContentAndSkipsClearOnes) {
  TempDir dir;
  Source src = make_source(dir);
  ExportOptions o;
  o.output = dir / "web.pmtiles";
  o.format = imaging::WebFormat::png;
  o.threads = 3;
  o.source_name = "src.pmtiles";
  auto r = export_web_tiles(*src.reader, src.info, o);
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ(r->source_tiles, 8u);
  EXPECT_EQ(r->tiles_written, 7u);
  EXPECT_EQ(r->tiles_skipped, 1u);
  EXPECT_EQ(r->unique_tiles, 6u);  // the twins are stored once

  auto out = archive::Reader::open(o.output).value();
  const archive::Header& h = out->header();
  EXPECT_EQ(h.tile_type, archive::TileType::png);
  EXPECT_EQ(h.tile_compression, archive::Compression::none);
  EXPECT_EQ(h.internal_compression, archive::Compression::gzip);
  EXPECT_EQ(h.min_zoom, 0);
  EXPECT_EQ(h.max_zoom, 2);
  EXPECT_EQ(h.addressed_tiles, 7u);
  EXPECT_EQ(h.tile_contents, 6u);
  const LonLatBounds b = export_bounds(src.info);
  EXPECT_EQ(b.west, -180.0);  // the image's top-left is the Web Mercator square's
  EXPECT_NEAR(h.min_lon_e7, b.west * 1e7, 1);
  EXPECT_NEAR(h.max_lat_e7, b.north * 1e7, 1);
  EXPECT_NEAR(h.max_lon_e7, b.east * 1e7, 1);
  EXPECT_NEAR(h.min_lat_e7, b.south * 1e7, 1);
  EXPECT_LT(b.east, 180.0);

  const Geometry& g = src.info.geometry;
  for (int z = 0; z <= g.max_zoom(); ++z)
    for (std::uint32_t y = 0; y < g.tiles_y(z); ++y)
      for (std::uint32_t x = 0; x < g.tiles_x(z); ++x) {
        const TileId id{static_cast<std::uint8_t>(z), x, y};
        auto bytes = out->get(id);
        if (id == kAbsent || id == kClear) {
          EXPECT_FALSE(bytes) << id.to_string();
          continue;
        }
        ASSERT_TRUE(bytes) << id.to_string();
        auto decoded = imaging::decode_web_image(*bytes).value();
        auto want = imaging::tile_content(stored_tile(g, id), g, id).value();
        EXPECT_EQ(decoded.width, 256u);
        EXPECT_EQ(decoded.pixels, want.pixels) << id.to_string();
      }

  auto meta = nlohmann::json::parse(out->metadata_json());
  EXPECT_EQ(meta["name"], "t");
  EXPECT_EQ(meta["description"], "test tiles");
  EXPECT_EQ(meta["format"], "png");
  EXPECT_EQ(meta["tileSize"], 256);
  EXPECT_EQ(meta["maxzoom"], 2);
  EXPECT_EQ(meta["vtstream_source"]["archive"], "src.pmtiles");
  EXPECT_EQ(meta["vtstream_source"]["version"], src.reader->version());
}

TEST(Export, XyzFolderHoldsTheSameTilesAsTheArchive) {
  TempDir dir;
  Source src = make_source(dir);
  ExportOptions o;
  o.format = imaging::WebFormat::webp;
  o.output = dir / "web.pmtiles";
  ASSERT_TRUE(export_web_tiles(*src.reader, src.info, o));
  o.layout = ExportLayout::xyz;
  o.output = dir / "site";
  auto r = export_web_tiles(*src.reader, src.info, o);
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ(r->tiles_written, 7u);
  // Missing parent folders are created.
  o.output = dir / "www" / "maps" / "site";
  r = export_web_tiles(*src.reader, src.info, o);
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ(listing(dir / "www" / "maps" / "site"), listing(dir / "site"));
  fs::remove_all(dir / "www");
  auto archive = archive::Reader::open(dir / "web.pmtiles").value();
  std::set<std::string> from_archive{"metadata.json"};
  ASSERT_TRUE(archive->for_each_entry([&](const archive::Entry& e) {
    for (std::uint32_t i = 0; i < e.run_length; ++i) {
      const TileId id = archive::tile_id_to_zxy(e.tile_id + i).value();
      from_archive.insert(std::to_string(id.z));
      from_archive.insert(std::to_string(id.z) + "/" + std::to_string(id.x));
      const std::string f = id.to_string() + ".webp";
      from_archive.insert(f);
      std::ifstream in(dir / "site" / f, std::ios::binary);
      std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), {});
      EXPECT_EQ(bytes, archive->get(id).value()) << f;
    }
    return true;
  }));
  EXPECT_EQ(listing(dir / "site"), from_archive);
  // Nothing else was left beside it (no temporary folder).
  EXPECT_EQ(listing(dir.path()).count(".site.partial"), 0u);
  for (const auto& name : listing(dir.path())) EXPECT_EQ(name.find("partial"), std::string::npos);
}

TEST(Export, RefusalsLeaveNoOutput) {
  TempDir dir;
  Source src = make_source(dir);
  ExportOptions o;
  o.output = dir / "web.pmtiles";
  o.encode.webp_quality = 101;
  auto r = export_web_tiles(*src.reader, src.info, o);
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().code, ErrorCode::invalid_argument);

  o.encode = {};
  o.tiling = Tiling::web_mercator_quad;
  r = export_web_tiles(*src.reader, src.info, o);
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().code, ErrorCode::invalid_argument);
  EXPECT_NE(r.error().message.find("plain image"), std::string::npos) << r.error().message;

  o.tiling = Tiling::none;
  o.layout = ExportLayout::xyz;
  o.output = dir / "full";
  fs::create_directory(o.output);
  std::ofstream(o.output / "keep") << "x";
  r = export_web_tiles(*src.reader, src.info, o);
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().code, ErrorCode::invalid_argument);
  EXPECT_EQ(listing(o.output), std::set<std::string>{"keep"});

  EXPECT_EQ(listing(dir.path()), (std::set<std::string>{"src.pmtiles", "full", "full/keep"}));
}

TEST(Export, CancelledExportLeavesNothing) {
  TempDir dir;
  Source src = make_source(dir);
  std::atomic<bool> cancel{true};
  for (ExportLayout layout : {ExportLayout::pmtiles, ExportLayout::xyz}) {
    ExportOptions o;
    o.output = dir / "out";
    o.layout = layout;
    o.cancel = &cancel;
    auto r = export_web_tiles(*src.reader, src.info, o);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::cancelled);
    EXPECT_EQ(listing(dir.path()), std::set<std::string>{"src.pmtiles"});
  }
}

TEST(Export, DamagedSourceTileFailsNamingItAndLeavesNothing) {
  TempDir dir;
  TilesetInfo info;
  info.geometry = Geometry::create(600, 300, 256, 4).value();
  archive::WriterOptions wo;
  wo.path = dir / "src.pmtiles";
  auto writer = archive::Writer::create(wo).value();
  const std::vector<std::uint8_t> junk(100, 0x5a);
  ASSERT_TRUE(writer->add_tile({0, 0, 0}, junk));
  ASSERT_TRUE(writer->finish(info.to_json()));
  auto reader = archive::Reader::open(wo.path).value();
  ExportOptions o;
  o.output = dir / "web.pmtiles";
  auto r = export_web_tiles(*reader, info, o);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("tile 0/0/0"), std::string::npos) << r.error().message;
  EXPECT_EQ(listing(dir.path()), std::set<std::string>{"src.pmtiles"});
}

TEST(Export, GeoreferencedBoundsAndTilings) {
  TempDir dir;
  Georeference web{Tiling::web_mercator_quad, {-20, -10, 30, 40}, {5, 15, 1}};
  Source src = make_source(dir, web, 1024, 1024);
  ExportOptions o;
  o.output = dir / "web.pmtiles";
  o.tiling = Tiling::web_mercator_quad;  // native: accepted
  auto r = export_web_tiles(*src.reader, src.info, o);
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ(r->bounds, web.bounds);
  auto out = archive::Reader::open(o.output).value();
  EXPECT_EQ(out->header().min_lon_e7, -200000000);
  EXPECT_EQ(out->header().max_lat_e7, 400000000);
  EXPECT_EQ(out->header().center_zoom, 1);
}

// WebMercatorQuad from a WorldCRS84Quad archive: every tile over the footprint is
// render_web_mercator_tile()'s (tested against gdalwarp in the protocol's tests), fetched from the
// archive's real tiles, in PNG; zooms and bounds are web_mercator_range()'s.
TEST(Export, ReprojectsWorldCrs84QuadToWebMercatorQuad) {
  TempDir dir;
  Georeference crs84{Tiling::world_crs84_quad, {-30, -70, 60, 88}, {10, 10, 1}};
  Source src = make_source(dir, crs84, 1024, 512);  // our levels 0..2, 2/1/0 absent
  ExportOptions o;
  o.output = dir / "web.pmtiles";
  o.format = imaging::WebFormat::png;
  o.tiling = Tiling::web_mercator_quad;
  o.threads = 2;
  auto r = export_web_tiles(*src.reader, src.info, o);
  ASSERT_TRUE(r) << r.error().message;
  const imaging::WebMercatorRange range = imaging::web_mercator_range(src.info).value();
  EXPECT_EQ(r->bounds, range.bounds);
  EXPECT_LT(range.bounds.north, 85.06);  // clipped to Web Mercator
  auto out = archive::Reader::open(o.output).value();
  EXPECT_EQ(out->header().min_zoom, range.min_zoom);
  EXPECT_EQ(out->header().max_zoom, range.max_zoom);
  EXPECT_EQ(out->header().tile_type, archive::TileType::png);
  EXPECT_EQ(nlohmann::json::parse(out->metadata_json())["tiling"], "WebMercatorQuad");

  const imaging::FetchStoredTile fetch = [&](TileId id) -> Result<std::optional<TileImage>> {
    auto bytes = src.reader->get(id);
    if (!bytes) return std::optional<TileImage>{};
    return std::optional<TileImage>(decode_tile(*bytes).value());
  };
  std::uint64_t expected = 0;
  for (int z = range.min_zoom; z <= range.max_zoom; ++z)
    for (std::uint32_t y = 0; y < (1u << z); ++y)
      for (std::uint32_t x = 0; x < (1u << z); ++x) {
        const TileId id{static_cast<std::uint8_t>(z), x, y};
        auto want = imaging::render_web_mercator_tile(src.info, z, x, y, fetch).value();
        bool visible = false;
        if (want)
          for (std::size_t i = 3; i < want->pixels.size(); i += 4) visible |= want->pixels[i] != 0;
        auto got = out->get(id);
        ASSERT_EQ(bool(got), visible) << id.to_string();
        if (!visible) continue;
        ++expected;
        EXPECT_EQ(imaging::decode_web_image(*got).value().pixels, want->pixels) << id.to_string();
      }
  EXPECT_GT(expected, 5u);
  EXPECT_EQ(r->tiles_written, expected);
}

TEST(Export, MetadataCarriesTheSourceAttribution) {
  TilesetInfo info;
  info.name = "earth";
  const std::string json =
      export_metadata_json(info, R"({"attribution":"(c) NASA"})", "a.pmtiles", "0123456789abcdef",
                           imaging::WebFormat::jpeg, {-10, -5, 10, 5}, 0, 3, Tiling::none);
  auto j = nlohmann::json::parse(json);
  EXPECT_EQ(j["attribution"], "(c) NASA");
  EXPECT_EQ(j["format"], "jpg");
  EXPECT_EQ(j["bounds"], nlohmann::json({-10, -5, 10, 5}));
  EXPECT_EQ(j["minzoom"], 0);
  EXPECT_EQ(j["maxzoom"], 3);
  EXPECT_EQ(j["tiling"], "none");
  EXPECT_EQ(j["vtstream_source"]["version"], "0123456789abcdef");
}

}  // namespace
}  // namespace vts
