// Image tilesets of third-party servers (source.hpp: ImageLayout, image_source_info,
// image_tile_exists) and open_source()'s refusals of a template it cannot lay out. Fetching
// real tiles is tests/integration/loadtest_targets.sh's (nginx over gdal2tiles folders).
#include <gtest/gtest.h>

#include <span>
#include <string>
#include <vector>

#include "image_layout.hpp"
#include "vts/client/image_tiles.hpp"
#include "vts/client/source.hpp"
#include "vts/imaging/web_image.hpp"

using vts::ErrorCode;
using vts::TileId;
using vts::client::image_source_info;
using vts::client::image_tile_exists;
using vts::client::ImageLayout;

namespace {

ImageLayout layout(int min_zoom, int max_zoom) {
  ImageLayout l;
  l.tiles = "http://127.0.0.1:9/{z}/{x}/{y}.png";
  l.min_zoom = min_zoom;
  l.max_zoom = max_zoom;
  l.format = "png";
  return l;
}

TEST(ImageTileset, IsABorderlessWebMercatorPyramidOfTheZoomRange) {
  auto info = image_source_info(layout(0, 3), "k", "{}");
  ASSERT_TRUE(info) << info.error().to_string();
  EXPECT_EQ(info->image_format, "png");
  EXPECT_EQ(info->info.geometry.tile_size(), 256u);
  EXPECT_EQ(info->info.geometry.border(), 0u);
  EXPECT_EQ(info->info.geometry.max_zoom(), 3);
  EXPECT_EQ(info->info.geometry.width(), 2048u);
  ASSERT_TRUE(info->info.georeference);
  EXPECT_EQ(info->info.georeference->tiling, vts::Tiling::web_mercator_quad);
  EXPECT_EQ(info->key, "k");
  for (std::uint32_t x = 0; x < 8; ++x)
    for (std::uint32_t y = 0; y < 8; ++y) EXPECT_TRUE(image_tile_exists(*info, TileId{3, x, y}));
  EXPECT_FALSE(image_tile_exists(*info, TileId{4, 0, 0}));
}

TEST(ImageTileset, TilesOutsideTheZoomRangeOrTheBoundsDoNotExist) {
  ImageLayout l = layout(1, 3);
  l.bounds = {0, 0, 90, 60};  // z1: (1,0); z2: (2,1); z3: x 4-5, y 2-3
  auto info = image_source_info(l, "k", "{}");
  ASSERT_TRUE(info) << info.error().to_string();
  EXPECT_FALSE(image_tile_exists(*info, TileId{0, 0, 0}));  // below the min zoom
  EXPECT_TRUE(image_tile_exists(*info, TileId{1, 1, 0}));
  EXPECT_FALSE(image_tile_exists(*info, TileId{1, 0, 0}));
  EXPECT_TRUE(image_tile_exists(*info, TileId{2, 2, 1}));
  EXPECT_FALSE(image_tile_exists(*info, TileId{2, 2, 2}));
  int n = 0;
  for (std::uint32_t x = 0; x < 8; ++x)
    for (std::uint32_t y = 0; y < 8; ++y) n += image_tile_exists(*info, TileId{3, x, y});
  EXPECT_EQ(n, 4);
  EXPECT_TRUE(image_tile_exists(*info, TileId{3, 5, 3}));
}

TEST(ImageTileset, RefusesALayoutItCannotUseNamingWhatIsWrong) {
  const auto refused = [](const ImageLayout& l, const std::string& word) {
    auto info = image_source_info(l, "k", "{}");
    ASSERT_FALSE(info);
    EXPECT_EQ(info.error().code, ErrorCode::invalid_argument);
    EXPECT_NE(info.error().message.find(word), std::string::npos) << info.error().message;
  };
  refused(layout(0, -1), "--zoom");
  refused(layout(3, 2), "zoom range");
  refused(layout(0, 25), "zoom range");
  ImageLayout l = layout(0, 3);
  l.bounds = {10, 0, 5, 10};
  refused(l, "bounds");
  l.bounds = {0, 86, 10, 89};  // beyond Web Mercator's latitudes
  refused(l, "Web Mercator");
  l = layout(0, 3);
  l.tile_size = 300;
  refused(l, "tile size");
}

// A third-party TileJSON is untrusted input: a field of the wrong type or a number no int holds is
// an error naming it, never an exception or a wrapped value.
TEST(ImageTileset, AHostileTileJsonIsRefusedNamingTheField) {
  const auto read = [](const std::string& extra) {
    const std::string doc = R"({"tiles": ["http://127.0.0.1:9/{z}/{x}/{y}.png"])" + extra + "}";
    return vts::client::read_image_tilejson(
        std::span(reinterpret_cast<const std::uint8_t*>(doc.data()), doc.size()), "t.json", {});
  };
  auto scheme = read(R"(, "scheme": 5)");
  ASSERT_FALSE(scheme);
  EXPECT_NE(scheme.error().message.find("\"scheme\""), std::string::npos);
  for (const char* field :
       {R"(, "minzoom": -1e300)", R"(, "maxzoom": -1e300)", R"(, "tileSize": 1e20)"}) {
    auto l = read(field);
    ASSERT_TRUE(l) << field << ": " << l.error().to_string();
    EXPECT_FALSE(image_source_info(*l, "k", "{}")) << field << " is refused as a layout";
  }
  auto huge = read(R"(, "maxzoom": 1e300)");
  ASSERT_TRUE(huge);
  EXPECT_EQ(huge->max_zoom, 24) << "clamped to the deepest addressed level";
  EXPECT_TRUE(image_source_info(*huge, "k", "{}"));
}

// A stock archive whose PNG/JPEG/WebP tiles are compressed again (gzip) is no web map's: refused
// at open, not a decode error on every tile.
TEST(ImageTileset, AStockArchiveOfRecompressedImagesIsUnsupported) {
  vts::archive::Header h;
  h.tile_type = vts::archive::TileType::png;
  h.max_zoom = 3;
  h.min_lon_e7 = -1800000000;
  h.max_lon_e7 = 1800000000;
  h.min_lat_e7 = -800000000;
  h.max_lat_e7 = 800000000;
  h.tile_compression = vts::archive::Compression::none;
  EXPECT_TRUE(vts::client::stock_archive_info(h, "{}", "a.pmtiles", {}));
  h.tile_compression = vts::archive::Compression::gzip;
  auto gz = vts::client::stock_archive_info(h, "{}", "a.pmtiles", {});
  ASSERT_FALSE(gz);
  EXPECT_EQ(gz.error().code, ErrorCode::unsupported);
  EXPECT_NE(gz.error().message.find("tile compression 2"), std::string::npos) << gz.error().message;
}

TEST(ImageTileset, OpenSourceTakesATemplateOnlyWithItsZoomRange) {
  auto no_zoom = vts::client::open_source("http://127.0.0.1:9/{z}/{x}/{y}.png");
  ASSERT_FALSE(no_zoom);
  EXPECT_EQ(no_zoom.error().code, ErrorCode::invalid_argument);
  EXPECT_NE(no_zoom.error().message.find("--zoom"), std::string::npos);

  auto no_y = vts::client::open_source("http://127.0.0.1:9/{z}/{x}.png");
  ASSERT_FALSE(no_y);
  EXPECT_NE(no_y.error().message.find("{y}"), std::string::npos) << no_y.error().message;

  vts::client::SourceOptions o;
  o.max_zoom = 2;
  // Opening a template costs no request: nothing listens on port 9.
  auto opened = vts::client::open_source("http://127.0.0.1:9/t/{z}/{x}/{-y}.jpg?k=1", o);
  ASSERT_TRUE(opened) << opened.error().to_string();
  EXPECT_EQ((*opened)->info().image_format, "jpeg");
  EXPECT_EQ((*opened)->info().key, "http://127.0.0.1:9/t/{z}/{x}/{-y}.jpg");
  EXPECT_EQ((*opened)->info().info.geometry.max_zoom(), 2);
  EXPECT_FALSE((*opened)->local());
}

}  // namespace

namespace {

std::vector<std::uint8_t> encoded(std::uint32_t size, vts::imaging::WebFormat format) {
  vts::TileImage img;
  img.width = img.height = size;
  img.pixels.assign(std::size_t{size} * size * 4, 200);
  auto bytes = vts::imaging::encode_web_image(img, format);
  EXPECT_TRUE(bytes) << bytes.error().to_string();
  return bytes ? *bytes : std::vector<std::uint8_t>{};
}

}  // namespace

TEST(ImageTile, DecodesWhatItsTilesetDeclaresAtTheTileSize) {
  auto png = vts::client::decode_image_tile(encoded(64, vts::imaging::WebFormat::png), "png", 64);
  ASSERT_TRUE(png) << png.error().to_string();
  EXPECT_EQ(png->width, 64u);
  EXPECT_EQ(png->pixels.size(), 64u * 64 * 4);
  // A template that does not say takes any of the three.
  EXPECT_TRUE(
      vts::client::decode_image_tile(encoded(64, vts::imaging::WebFormat::jpeg), "image", 64));
}

TEST(ImageTile, RefusesAnotherTypeThanDeclaredOrAnotherSizeNamingWhatItFound) {
  auto jpeg = vts::client::decode_image_tile(encoded(64, vts::imaging::WebFormat::jpeg), "png", 64);
  ASSERT_FALSE(jpeg);
  EXPECT_EQ(jpeg.error().code, vts::ErrorCode::corrupt);
  EXPECT_NE(jpeg.error().message.find("is a jpeg image"), std::string::npos)
      << jpeg.error().message;
  const std::vector<std::uint8_t> junk(100, 7);
  auto bad = vts::client::decode_image_tile(junk, "webp", 64);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message.find("not an image of a known type"), std::string::npos);
  auto small = vts::client::decode_image_tile(encoded(32, vts::imaging::WebFormat::png), "png", 64);
  ASSERT_FALSE(small);
  EXPECT_NE(small.error().message.find("32x32 pixels in a tileset of 64 px tiles"),
            std::string::npos)
      << small.error().message;
}
