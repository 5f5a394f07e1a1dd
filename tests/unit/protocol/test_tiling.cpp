#include "vts/protocol/tiling.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>

namespace vts {
namespace {

constexpr Tiling kCrs84 = Tiling::world_crs84_quad;
constexpr Tiling kMerc = Tiling::web_mercator_quad;

Geometry scheme(Tiling t, int tms_max, std::uint32_t tile = 256) {
  auto g = tiling_geometry(t, tms_max, tile, 4);
  EXPECT_TRUE(g.ok()) << (g.ok() ? "" : g.error().to_string());
  return *g;
}

TEST(Tiling, NamesRoundTripInOgcSpellingAndParseCaseInsensitively) {
  for (Tiling t : {Tiling::none, kCrs84, kMerc}) EXPECT_EQ(*parse_tiling(tiling_name(t)), t);
  EXPECT_EQ(tiling_name(kCrs84), "WorldCRS84Quad");
  EXPECT_EQ(tiling_name(kMerc), "WebMercatorQuad");
  EXPECT_EQ(*parse_tiling("webmercatorquad"), kMerc);
  auto bad = parse_tiling("EPSG:4326");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().code, ErrorCode::invalid_argument);
  EXPECT_NE(bad.error().message.find("WorldCRS84Quad"), std::string::npos);
  EXPECT_EQ(tiling_crs(kCrs84), "OGC:CRS84");
  EXPECT_EQ(tiling_crs(kMerc), "EPSG:3857");
}

TEST(Tiling, WorldCrs84QuadIsTheTopHalfOfTheNextLevel) {
  const Geometry g = scheme(kCrs84, 2);  // TMS levels 0..2
  EXPECT_EQ(g.width(), 2048u);
  EXPECT_EQ(g.height(), 1024u);
  EXPECT_EQ(g.max_zoom(), 3);
  EXPECT_EQ(level_from_tms(kCrs84, 0), 1);
  EXPECT_EQ(tms_level(kCrs84, 1), 0);
  EXPECT_EQ(tms_level(kCrs84, 0), -1);
  EXPECT_TRUE(check_tiling_geometry(kCrs84, g).ok());
  // TMS level 0 is 2 x 1 tiles: our level 1.
  EXPECT_EQ(g.tiles_x(1), 2u);
  EXPECT_EQ(g.tiles_y(1), 1u);
}

TEST(Tiling, WebMercatorQuadLevelsAreOurs) {
  const Geometry g = scheme(kMerc, 3);
  EXPECT_EQ(g.width(), 2048u);
  EXPECT_EQ(g.height(), 2048u);
  EXPECT_EQ(g.max_zoom(), 3);
  EXPECT_EQ(tms_level(kMerc, 3), 3);
  EXPECT_EQ(level_from_tms(kMerc, 3), 3);
}

TEST(Tiling, GeometryThatIsNotTheSchemesGridIsRefusedSayingWhy) {
  auto odd = Geometry::create(2000, 1000, 256, 4);
  Status s = check_tiling_geometry(kCrs84, *odd);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("2048x1024"), std::string::npos) << s.error().message;
  EXPECT_FALSE(check_tiling_geometry(kMerc, *Geometry::create(2048, 1024, 256, 4)).ok());
  EXPECT_FALSE(check_tiling_geometry(kCrs84, *Geometry::create(256, 128, 256, 4)).ok());
  EXPECT_TRUE(check_tiling_geometry(Tiling::none, *odd).ok());
  EXPECT_FALSE(tiling_geometry(Tiling::none, 1, 256, 4).ok());
  EXPECT_FALSE(tiling_geometry(kMerc, -1, 256, 4).ok());
  EXPECT_FALSE(tiling_geometry(kCrs84, Geometry::kMaxZoom, 256, 4).ok());
}

TEST(Tiling, CellSizesAndScaleDenominatorsAreOgcs) {
  EXPECT_DOUBLE_EQ(level_scale_denominator(kMerc, 256, 0), 559082264.0287178);
  EXPECT_DOUBLE_EQ(level_cell_size(kMerc, 256, 0), 156543.03392804097);
  // WorldCRS84Quad TMS level 0 is our level 1.
  EXPECT_DOUBLE_EQ(level_scale_denominator(kCrs84, 256, 1), 279541132.0143589);
  EXPECT_DOUBLE_EQ(level_cell_size(kCrs84, 256, 1), 0.703125);
  EXPECT_NEAR(level_cell_size(kMerc, 256, 17), 1.194, 0.0005);
  EXPECT_DOUBLE_EQ(level_cell_size(kMerc, 512, 16), level_cell_size(kMerc, 256, 17));
}

TEST(Tiling, LonLatRoundTripsThroughTexelsWithin1e9Degrees) {
  for (Tiling t : {kCrs84, kMerc}) {
    const LonLatBounds ext = scheme_extent(t);
    for (int z : {0, 5, 17, 26}) {
      for (double lon = -180; lon <= 180; lon += 7.3) {
        for (double lat = ext.south; lat <= ext.north; lat += 3.7) {
          const LonLat back = texel_to_lonlat(t, 256, z, lonlat_to_texel(t, 256, z, {lon, lat}));
          EXPECT_NEAR(back.lon, lon, 1e-9) << tiling_name(t) << " z" << z;
          EXPECT_NEAR(back.lat, lat, 1e-9) << tiling_name(t) << " z" << z;
        }
      }
    }
  }
  // Corners map to the level's corners.
  const TexelPoint nw = lonlat_to_texel(kMerc, 256, 1, {-180, kWebMercatorMaxLat});
  EXPECT_NEAR(nw.x, 0, 1e-9);
  EXPECT_NEAR(nw.y, 0, 1e-9);
  const TexelPoint se = lonlat_to_texel(kCrs84, 256, 1, {180, -90});
  EXPECT_DOUBLE_EQ(se.x, 512);
  EXPECT_DOUBLE_EQ(se.y, 256);
}

TEST(Tiling, TheTileCoveringParisIsTheOneWebMapsUse) {
  const LonLat paris{2.3522, 48.8566};
  const TexelPoint m = lonlat_to_texel(kMerc, 256, 10, paris);
  EXPECT_EQ(std::floor(m.x / 256), 518);  // OpenStreetMap's 10/518/352
  EXPECT_EQ(std::floor(m.y / 256), 352);
  const TexelPoint c = lonlat_to_texel(kCrs84, 256, 10, paris);
  EXPECT_EQ(std::floor(c.x / 256), 518);  // TMS level 9, col 518, row 117
  EXPECT_EQ(std::floor(c.y / 256), 117);
  const LonLatBounds b = tile_bounds_degrees(kMerc, 256, TileId{10, 518, 352});
  EXPECT_LE(b.west, paris.lon);
  EXPECT_GE(b.east, paris.lon);
  EXPECT_LE(b.south, paris.lat);
  EXPECT_GE(b.north, paris.lat);
  EXPECT_NEAR(b.west, 2.109375, 1e-12);
  EXPECT_NEAR(b.east, 2.4609375, 1e-12);
}

TEST(Tiling, TileBoundsInDegreesAndMetres) {
  const LonLatBounds root = tile_bounds_degrees(kMerc, 256, TileId{0, 0, 0});
  EXPECT_DOUBLE_EQ(root.west, -180);
  EXPECT_DOUBLE_EQ(root.east, 180);
  EXPECT_NEAR(root.north, kWebMercatorMaxLat, 1e-12);
  EXPECT_NEAR(root.south, -kWebMercatorMaxLat, 1e-12);
  const CrsBounds m = tile_bounds_crs(kMerc, 256, TileId{1, 1, 0});
  EXPECT_DOUBLE_EQ(m.min_x, 0);
  EXPECT_DOUBLE_EQ(m.max_x, kWebMercatorHalfSide);
  EXPECT_DOUBLE_EQ(m.min_y, 0);
  EXPECT_DOUBLE_EQ(m.max_y, kWebMercatorHalfSide);
  // WorldCRS84Quad TMS 0/0/1 = our 1/1/0: the eastern hemisphere.
  const LonLatBounds east = tile_bounds_degrees(kCrs84, 256, TileId{1, 1, 0});
  EXPECT_EQ(east, (LonLatBounds{0, -90, 180, 90}));
  const CrsBounds d = tile_bounds_crs(kCrs84, 256, TileId{1, 1, 0});
  EXPECT_DOUBLE_EQ(d.min_y, -90);
}

TEST(Tiling, FootprintTilesPerLevel) {
  const Geometry g = scheme(kCrs84, 2);  // our levels 0..3, 45 degrees per tile at level 3
  const LonLatBounds europe{-10, 35, 30, 60};
  EXPECT_EQ(footprint_tiles(kCrs84, g, 3, europe), (TileRect{3, 0, 5, 2}));
  EXPECT_EQ(footprint_tiles(kCrs84, g, 2, europe), (TileRect{1, 0, 3, 1}));
  EXPECT_EQ(footprint_tiles(kCrs84, g, 1, europe), (TileRect{0, 0, 2, 1}));
  EXPECT_EQ(footprint_tiles(kCrs84, g, 0, europe), (TileRect{0, 0, 1, 1}));
  EXPECT_EQ(footprint_tile_count(kCrs84, g, europe), 9u);
  EXPECT_EQ(footprint_tile_count(kCrs84, g, scheme_extent(kCrs84)), g.total_tile_count());
  const Geometry m = scheme(kMerc, 4);
  EXPECT_EQ(footprint_tile_count(kMerc, m, scheme_extent(kMerc)), m.total_tile_count());
}

TEST(Tiling, FootprintOnTileEdgesTakesNoNeighbour) {
  // Exactly tile 2/2/1's area: at level 3 its four children, one tile at every coarser level.
  const Geometry g = scheme(kMerc, 3);
  const LonLatBounds b = tile_bounds_degrees(kMerc, 256, TileId{2, 2, 1});
  EXPECT_EQ(footprint_tiles(kMerc, g, 3, b), (TileRect{4, 2, 6, 4}));
  EXPECT_EQ(footprint_tiles(kMerc, g, 2, b), (TileRect{2, 1, 3, 2}));
  EXPECT_EQ(footprint_tile_count(kMerc, g, b), 4u + 1 + 1 + 1);
  // A point still touches one texel, hence one tile per level.
  EXPECT_EQ(footprint_tile_count(kMerc, g, {10, 10, 10, 10}), 4u);
}

TEST(Tiling, DefaultCenterIsTheMiddleAtTheLevelWhereTheFootprintSpansATile) {
  const Geometry g = scheme(kCrs84, 2);
  const LonLatLevel c = default_center(kCrs84, g, {-10, 35, 30, 60});
  EXPECT_DOUBLE_EQ(c.lon, 10);
  EXPECT_DOUBLE_EQ(c.lat, 47.5);
  EXPECT_EQ(c.level, 3);  // 40 degrees < 45 per tile at level 3: the finest level
  EXPECT_EQ(default_center(kCrs84, g, scheme_extent(kCrs84)).level, 0);
}

TEST(Tiling, TileMatrixSetJsonHasTheOgcFieldsForTheArchivesLevels) {
  const Geometry g = scheme(kCrs84, 2);
  const auto j = nlohmann::json::parse(tile_matrix_set_json(kCrs84, g, {-10, 35, 30, 60}));
  EXPECT_EQ(j["id"], "WorldCRS84Quad");
  EXPECT_EQ(j["uri"], "http://www.opengis.net/def/tilematrixset/OGC/1.0/WorldCRS84Quad");
  EXPECT_EQ(j["crs"], "http://www.opengis.net/def/crs/OGC/1.3/CRS84");
  EXPECT_EQ(j["orderedAxes"], nlohmann::json::array({"Lon", "Lat"}));
  ASSERT_EQ(j["tileMatrices"].size(), 3u);  // TMS 0..2 = our 1..3
  const auto& m0 = j["tileMatrices"][0];
  EXPECT_EQ(m0["id"], "0");
  EXPECT_DOUBLE_EQ(m0["scaleDenominator"].get<double>(), 279541132.0143589);
  EXPECT_DOUBLE_EQ(m0["cellSize"].get<double>(), 0.703125);
  EXPECT_EQ(m0["cornerOfOrigin"], "topLeft");
  EXPECT_EQ(m0["pointOfOrigin"], nlohmann::json::array({-180.0, 90.0}));
  EXPECT_EQ(m0["tileWidth"], 256);
  EXPECT_EQ(m0["matrixWidth"], 2);
  EXPECT_EQ(m0["matrixHeight"], 1);
  const auto& l2 = j["tileMatrixSetLimits"][2];
  EXPECT_EQ(l2["tileMatrix"], "2");
  EXPECT_EQ(l2["minTileCol"], 3);
  EXPECT_EQ(l2["maxTileCol"], 4);
  EXPECT_EQ(l2["minTileRow"], 0);
  EXPECT_EQ(l2["maxTileRow"], 1);

  const auto w = nlohmann::json::parse(
      tile_matrix_set_json(kMerc, scheme(kMerc, 1, 512), scheme_extent(kMerc)));
  EXPECT_FALSE(w.contains("uri"));  // 512-texel tiles are not the registered set
  EXPECT_EQ(w["orderedAxes"], nlohmann::json::array({"X", "Y"}));
  ASSERT_EQ(w["tileMatrices"].size(), 2u);
  EXPECT_EQ(w["tileMatrices"][0]["id"], "0");
  EXPECT_DOUBLE_EQ(w["tileMatrices"][0]["pointOfOrigin"][1].get<double>(), kWebMercatorHalfSide);
  EXPECT_EQ(w["tileMatrices"][1]["matrixHeight"], 2);
}

}  // namespace
}  // namespace vts
