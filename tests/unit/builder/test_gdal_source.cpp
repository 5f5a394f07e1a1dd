// GdalSource on small real GeoTIFFs written here through GDAL: texels land where their
// georeference says, the level follows the finest input, footprints are the inputs' extents, and
// what the build cannot take is refused by name.
#include "gdal_source.hpp"

#include <gdal.h>
#include <gdal_utils.h>
#include <gtest/gtest.h>
#include <ogr_srs_api.h>

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "vts/builder/builder.hpp"
#include "vts/test/temp_dir.hpp"

namespace vts {
namespace {

namespace fs = std::filesystem;
using detail::GdalSource;
using detail::GdalSourceOptions;

// Writes a w x h GeoTIFF in EPSG:`epsg` (default 4326) with its top-left corner at (west, north)
// and `deg` CRS units per pixel; band b of pixel (x, y) is value(x, y, b).
template <class F>
void write_geotiff(const fs::path& path, int w, int h, int bands, GDALDataType type, double west,
                   double north, double deg, F value, int epsg = 4326) {
  GDALAllRegister();
  GDALDriverH drv = GDALGetDriverByName("GTiff");
  GDALDatasetH ds = GDALCreate(drv, path.c_str(), w, h, bands, type, nullptr);
  ASSERT_NE(ds, nullptr);
  double gt[6] = {west, deg, 0, north, 0, -deg};
  GDALSetGeoTransform(ds, gt);
  OGRSpatialReferenceH srs = OSRNewSpatialReference(nullptr);
  OSRImportFromEPSG(srs, epsg);
  GDALSetSpatialRef(ds, srs);
  OSRDestroySpatialReference(srs);
  std::vector<double> row(static_cast<std::size_t>(w));
  for (int b = 1; b <= bands; ++b)
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) row[static_cast<std::size_t>(x)] = value(x, y, b);
      ASSERT_EQ(GDALRasterIO(GDALGetRasterBand(ds, b), GF_Write, 0, y, w, 1, row.data(), w, 1,
                             GDT_Float64, 0, 0),
                CE_None);
    }
  GDALClose(ds);
}

GdalSourceOptions options(int tile_size, std::optional<int> level = std::nullopt) {
  GdalSourceOptions o;
  o.tiling = Tiling::world_crs84_quad;
  o.tile_size = static_cast<std::uint32_t>(tile_size);
  o.border = 0;
  o.max_level = level;
  o.resampling = Resampling::nearest;
  return o;
}

int code(int x, int y, int b) {
  return (x * 7 + y * 13 + b * 50) % 256;
}

TEST(GdalSource, WholeWorldAtItsOwnResolutionIsTheInputExactly) {
  vts::test::TempDir dir;
  const fs::path p = dir.path() / "world.tif";
  // 16 x 8 pixels of 22.5 degrees: WorldCRS84Quad level 2 with T = 4 (16 x 8 texels).
  write_geotiff(p, 16, 8, 3, GDT_Byte, -180, 90, 22.5, code);
  ASSERT_TRUE(detail::gdal_is_georeferenced(p));
  auto s = GdalSource::open({p}, options(4));
  ASSERT_TRUE(s) << s.error().message;
  EXPECT_EQ((*s)->max_level(), 2);
  ASSERT_EQ((*s)->width(), 16u);
  ASSERT_EQ((*s)->height(), 8u);
  EXPECT_EQ((*s)->bounds(), (LonLatBounds{-180, -90, 180, 90}));
  std::vector<std::uint8_t> rows(16 * 8 * 4);
  ASSERT_TRUE((*s)->read_window(0, 16, 0, 8, rows.data()));
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 16; ++x)
      for (int b = 0; b < 4; ++b)
        ASSERT_EQ(rows[std::size_t((y * 16 + x) * 4 + b)], b == 3 ? 255 : code(x, y, b + 1))
            << x << "," << y << " band " << b;
}

TEST(GdalSource, AWindowOfColumnsIsThoseColumnsOfTheWholeRows) {
  vts::test::TempDir dir;
  const fs::path p = dir.path() / "world.tif";
  write_geotiff(p, 16, 8, 3, GDT_Byte, -180, 90, 22.5, code);
  auto s = GdalSource::open({p}, options(4));
  ASSERT_TRUE(s) << s.error().message;
  std::vector<std::uint8_t> whole(16 * 8 * 4), part(5 * 6 * 4);
  ASSERT_TRUE((*s)->read_window(0, 16, 0, 8, whole.data()));
  ASSERT_TRUE((*s)->read_window(7, 12, 1, 6, part.data()));
  for (int y = 0; y < 6; ++y)
    for (int x = 0; x < 5; ++x)
      for (int b = 0; b < 4; ++b)
        ASSERT_EQ(part[std::size_t((y * 5 + x) * 4 + b)],
                  whole[std::size_t(((y + 1) * 16 + x + 7) * 4 + b)])
            << x << "," << y << " band " << b;
}

TEST(GdalSource, AnInputCoversOnlyItsExtentAndTheLevelFollowsItsPixels) {
  vts::test::TempDir dir;
  const fs::path p = dir.path() / "piece.tif";
  // 20 x 10 pixels of 4.5 degrees from (0, 45): level rule picks 22.5 / 2^k <= 4.5 -> 5.625 is
  // too coarse, 2.8125 (level 5 with T = 4: 128 texels around) is the first.
  write_geotiff(p, 20, 10, 1, GDT_Byte, 0, 45, 4.5, [](int, int, int) { return 200; });
  auto s = GdalSource::open({p}, options(4));
  ASSERT_TRUE(s) << s.error().message;
  EXPECT_EQ((*s)->max_level(), 5);
  EXPECT_EQ((*s)->bounds(), (LonLatBounds{0, 0, 90, 45}));
  const std::uint64_t w = (*s)->width();
  ASSERT_EQ(w, 128u);
  std::vector<std::uint8_t> rows(w * 64 * 4);
  ASSERT_TRUE((*s)->read_window(0, w, 0, 64, rows.data()));
  // Texels of 2.8125 degrees: the piece spans columns 64..96 and rows 16..32.
  for (std::uint64_t y = 0; y < 64; ++y)
    for (std::uint64_t x = 0; x < w; ++x) {
      const bool inside = x >= 64 && x < 96 && y >= 16 && y < 32;
      const std::uint8_t* t = &rows[(y * w + x) * 4];
      ASSERT_EQ(t[3], inside ? 255 : 0) << x << "," << y;
      if (inside) {
        ASSERT_EQ(t[0], 200);
      }
    }
}

TEST(GdalSource, RefusesWhatTheBuildCannotTake) {
  vts::test::TempDir dir;
  const fs::path u16 = dir.path() / "deep.tif";
  write_geotiff(u16, 16, 8, 1, GDT_UInt16, -180, 90, 22.5,
                [](int x, int, int) { return 1000 + x * 10; });
  auto s = GdalSource::open({u16}, options(4));
  ASSERT_FALSE(s);
  EXPECT_EQ(s.error().code, ErrorCode::invalid_argument);
  EXPECT_NE(s.error().message.find("deep.tif"), std::string::npos) << s.error().message;
  EXPECT_NE(s.error().message.find("1000"), std::string::npos) << s.error().message;
  EXPECT_NE(s.error().message.find("1150"), std::string::npos) << s.error().message;
  EXPECT_NE(s.error().message.find("--range"), std::string::npos) << s.error().message;

  GdalSourceOptions ranged = options(4);
  ranged.value_ranges = {{1000.0, 1150.0}};
  auto r = GdalSource::open({u16}, ranged);
  ASSERT_TRUE(r) << r.error().message;
  std::vector<std::uint8_t> rows(16 * 8 * 4);
  ASSERT_TRUE((*r)->read_window(0, 16, 0, 8, rows.data()));
  EXPECT_EQ(rows[0], 0);         // 1000 -> 0
  EXPECT_EQ(rows[15 * 4], 255);  // 1150 -> 255
  EXPECT_EQ(rows[5 * 4], 85);    // 1050 -> 85

  auto wide = GdalSource::open({u16}, [] {
    GdalSourceOptions o = options(256, 23);  // 2^31 texels around: beyond GDAL's int
    o.value_ranges = {{0.0, 1.0}};
    return o;
  }());
  ASSERT_FALSE(wide);
  EXPECT_EQ(wide.error().code, ErrorCode::too_large);
  EXPECT_NE(wide.error().message.find("1073741824"), std::string::npos) << wide.error().message;

  const fs::path plain = dir.path() / "plain.txt";
  {
    std::FILE* f = std::fopen(plain.c_str(), "w");
    std::fputs("not a raster\n", f);
    std::fclose(f);
  }
  EXPECT_FALSE(detail::gdal_is_georeferenced(plain));
  auto t = GdalSource::open({plain}, options(4));
  ASSERT_FALSE(t);
  EXPECT_NE(t.error().message.find("plain.txt"), std::string::npos) << t.error().message;
}

// Marks band `b` of a GeoTIFF as alpha.
void tag_alpha(const fs::path& path, int b) {
  GDALDatasetH ds = GDALOpen(path.c_str(), GA_Update);
  ASSERT_NE(ds, nullptr);
  GDALSetRasterColorInterpretation(GDALGetRasterBand(ds, b), GCI_AlphaBand);
  GDALClose(ds);
}

std::vector<std::uint8_t> read_all(GdalSource& s) {
  std::vector<std::uint8_t> rows(s.width() * s.height() * 4);
  EXPECT_TRUE(s.read_window(0, s.width(), 0, std::uint32_t(s.height()), rows.data()));
  return rows;
}

TEST(GdalSource, BandsPicksThoseOfAMultispectralInput) {
  vts::test::TempDir dir;
  const fs::path p = dir.path() / "six.tif";
  write_geotiff(p, 16, 8, 6, GDT_Byte, -180, 90, 22.5, code);
  auto refused = GdalSource::open({p}, options(4));
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("six.tif: 6 bands"), std::string::npos);
  EXPECT_NE(refused.error().message.find("--bands"), std::string::npos);

  GdalSourceOptions o = options(4);
  o.bands = {4, 3, 2};
  auto s = GdalSource::open({p}, o);
  ASSERT_TRUE(s) << s.error().message;
  const auto rows = read_all(**s);
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 16; ++x) {
      const std::uint8_t* t = &rows[std::size_t((y * 16 + x) * 4)];
      ASSERT_EQ(t[0], code(x, y, 4));
      ASSERT_EQ(t[1], code(x, y, 3));
      ASSERT_EQ(t[2], code(x, y, 2));
      ASSERT_EQ(t[3], 255);
    }

  o.bands = {5};  // grey
  auto grey = GdalSource::open({p}, o);
  ASSERT_TRUE(grey) << grey.error().message;
  const auto g = read_all(**grey);
  EXPECT_EQ(g[(3 * 16 + 5) * 4], code(5, 3, 5));
  EXPECT_EQ(g[(3 * 16 + 5) * 4 + 2], code(5, 3, 5));

  o.bands = {1, 7, 2};
  auto beyond = GdalSource::open({p}, o);
  ASSERT_FALSE(beyond);
  EXPECT_EQ(beyond.error().code, ErrorCode::invalid_argument);
  EXPECT_NE(beyond.error().message.find("six.tif: has 6 bands; --bands asks for band 7"),
            std::string::npos)
      << beyond.error().message;
}

TEST(GdalSource, BandsKeepsTheInputsAlphaBand) {
  vts::test::TempDir dir;
  const fs::path p = dir.path() / "five.tif";
  // Band 5 is alpha: transparent in the west half.
  write_geotiff(p, 16, 8, 5, GDT_Byte, -180, 90, 22.5,
                [](int x, int y, int b) { return b == 5 ? (x < 8 ? 0 : 255) : code(x, y, b); });
  tag_alpha(p, 5);
  GdalSourceOptions o = options(4);
  o.bands = {3, 2, 1};
  auto s = GdalSource::open({p}, o);
  ASSERT_TRUE(s) << s.error().message;
  const auto rows = read_all(**s);
  for (int x = 0; x < 16; ++x) {
    const std::uint8_t* t = &rows[std::size_t((2 * 16 + x) * 4)];
    ASSERT_EQ(t[3], x < 8 ? 0 : 255) << x;
    if (x >= 8) {
      ASSERT_EQ(t[0], code(x, 2, 3));
    }
  }
}

TEST(GdalSource, ARangePerBandMapsEachBand) {
  vts::test::TempDir dir;
  const fs::path p = dir.path() / "deep3.tif";
  write_geotiff(p, 16, 8, 3, GDT_UInt16, -180, 90, 22.5,
                [](int x, int, int b) { return 1000 * b + x * 10; });
  GdalSourceOptions o = options(4);
  o.value_ranges = {{1000, 1150}, {2000, 2150}, {3000, 3150}};
  auto s = GdalSource::open({p}, o);
  ASSERT_TRUE(s) << s.error().message;
  const auto rows = read_all(**s);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(rows[std::size_t(k)], 0) << k;
    EXPECT_EQ(rows[std::size_t(15 * 4 + k)], 255) << k;
    EXPECT_EQ(rows[std::size_t(5 * 4 + k)], 85) << k;
  }
  EXPECT_TRUE((*s)->warnings().empty());
  o.value_ranges = {{0, 1}, {0, 1}};
  auto two = GdalSource::open({p}, o);
  ASSERT_FALSE(two);
  EXPECT_NE(two.error().message.find("deep3.tif: 2 value ranges"), std::string::npos)
      << two.error().message;
}

TEST(GdalSource, AutoRangeIsOneMappingForTheWholeMosaic) {
  vts::test::TempDir dir;
  // Two halves of the world with different values: 100..163 and 164..227, one pixel each.
  const fs::path a = dir.path() / "west.tif", b = dir.path() / "east.tif";
  write_geotiff(a, 8, 8, 1, GDT_UInt16, -180, 90, 22.5,
                [](int x, int y, int) { return 100 + x * 8 + y; });
  write_geotiff(b, 8, 8, 1, GDT_UInt16, 0, 90, 22.5,
                [](int x, int y, int) { return 164 + x * 8 + y; });
  GdalSourceOptions o = options(4);
  o.auto_range = true;
  auto s = GdalSource::open({a, b}, o);
  ASSERT_TRUE(s) << s.error().message;
  // 128 values, one each: 2 % (2.56 values) falls on the 3rd (102), 98 % (125.44) on the 126th.
  ASSERT_EQ((*s)->value_ranges().size(), 1u);
  EXPECT_EQ((*s)->value_ranges()[0], (std::pair<double, double>{102, 225}));
  const auto rows = read_all(**s);
  // West (x, y) = (0, 2) holds 102 -> 0; east (7, 5) holds 164 + 61 = 225 -> 255; east (0, 0)
  // holds 164 -> (164 - 102) * 255 / 123 = 128.5 -> 129 (rounded), by the same mapping.
  EXPECT_EQ(rows[(2 * 16 + 0) * 4], 0);
  EXPECT_EQ(rows[(5 * 16 + 15) * 4], 255);
  EXPECT_EQ(rows[(0 * 16 + 8) * 4], 129);
  EXPECT_TRUE((*s)->warnings().empty());
}

TEST(GdalSource, ValuesWithinAByteBuildAsTheyAreAndNarrowOnesAreWarnedAbout) {
  vts::test::TempDir dir;
  const fs::path u16 = dir.path() / "small16.tif", dark = dir.path() / "dark.tif",
                 unit = dir.path() / "unit.tif";
  write_geotiff(u16, 16, 8, 1, GDT_UInt16, -180, 90, 22.5,
                [](int x, int y, int) { return x * 13 + y; });  // 0 .. 202
  write_geotiff(dark, 16, 8, 3, GDT_Byte, -180, 90, 22.5,
                [](int x, int, int) { return x % 10; });  // 0 .. 9
  write_geotiff(unit, 16, 8, 1, GDT_Float32, -180, 90, 22.5,
                [](int x, int, int) { return x / 15.0; });  // 0 .. 1
  auto s = GdalSource::open({u16}, options(4));
  ASSERT_TRUE(s) << s.error().message;
  EXPECT_TRUE((*s)->warnings().empty());
  EXPECT_TRUE((*s)->value_ranges().empty());
  EXPECT_EQ(read_all(**s)[(3 * 16 + 5) * 4], 5 * 13 + 3);

  auto d = GdalSource::open({dark, unit}, options(4));
  ASSERT_TRUE(d) << d.error().message;
  ASSERT_EQ((*d)->warnings().size(), 2u);
  EXPECT_NE((*d)->warnings()[0].find((dir.path() / "dark.tif").string() + ": values 0 .. 9"),
            std::string::npos)
      << (*d)->warnings()[0];
  EXPECT_NE((*d)->warnings()[0].find("under 1/16"), std::string::npos);
  EXPECT_NE((*d)->warnings()[1].find("unit.tif: values 0 .. 1 "), std::string::npos)
      << (*d)->warnings()[1];

  // Many narrow inputs: the first kMaxWarnings are named, then how many more.
  std::vector<fs::path> many(GdalSource::kMaxWarnings + 2, dark);
  auto m = GdalSource::open(many, options(4));
  ASSERT_TRUE(m) << m.error().message;
  ASSERT_EQ((*m)->warnings().size(), GdalSource::kMaxWarnings + 1);
  EXPECT_EQ((*m)->warnings().back(), "... and 2 more inputs whose values use under 1/16 of 0..255");

  GdalSourceOptions ranged = options(4);
  ranged.value_ranges = {{0, 9}};
  auto r = GdalSource::open({dark}, ranged);
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_TRUE((*r)->warnings().empty());
  EXPECT_EQ(read_all(**r)[9 * 4], 255);
}

int open_descriptors() {
  int n = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator("/proc/self/fd")) ++n;
  return n;
}

TEST(GdalSource, KeepsAtMostMaxOpenInputsOpen) {
  vts::test::TempDir dir;
  // 32 pieces of 4 x 2 pixels tiling the world (8 columns x 4 rows), read with 3 open at most.
  std::vector<fs::path> pieces;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 8; ++c) {
      pieces.push_back(dir.path() / ("p" + std::to_string(r) + "_" + std::to_string(c) + ".tif"));
      write_geotiff(pieces.back(), 2, 2, 3, GDT_Byte, -180 + c * 45.0, 90 - r * 45.0, 22.5,
                    [&](int x, int y, int b) { return code(c * 2 + x, r * 2 + y, b); });
    }
  GdalSourceOptions few = options(4);
  few.max_open = 3;
  const int before = open_descriptors();
  auto s = GdalSource::open(pieces, few);
  ASSERT_TRUE(s) << s.error().message;
  EXPECT_LE(open_descriptors(), before + 3);
  const auto rows = read_all(**s);
  EXPECT_LE(open_descriptors(), before + 3);
  EXPECT_EQ((*s)->peak_open(), 3u);
  EXPECT_NE((*s)->description().find("... (32 inputs)"), std::string::npos) << (*s)->description();
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 16; ++x)
      for (int b = 0; b < 4; ++b)
        ASSERT_EQ(rows[std::size_t((y * 16 + x) * 4 + b)], b == 3 ? 255 : code(x, y, b + 1))
            << x << "," << y << " band " << b;
  s->reset();
  EXPECT_EQ(open_descriptors(), before);
}

// The warper's approximate transformer (-et 0.125) interpolates within blocks of the warped VRT,
// which are the grid's, not the reader's: a UTM input (a curved mapping onto WorldCRS84Quad) read
// as one window or as odd pieces gives the same texels, so stripes and strips cannot change tiles.
TEST(GdalSource, TexelsDoNotDependOnTheWindowsThatReadThem) {
  vts::test::TempDir dir;
  const fs::path p = dir.path() / "utm.tif";
  write_geotiff(
      p, 300, 240, 3, GDT_Byte, 200000, 5300000, 2000,
      [](int x, int y, int b) { return (x * 5 + y * 3 * b + (x * y) % 17) % 256; }, 32632);
  GdalSourceOptions o = options(64, 8);  // 16384 x 8192 texels, 0.022 degrees: ~1.2 per pixel
  o.resampling = Resampling::cubic;
  auto s = GdalSource::open({p}, o);
  ASSERT_TRUE(s) << s.error().message;
  auto g = tiling_geometry(o.tiling, tms_level(o.tiling, 8), 64, 0);
  ASSERT_TRUE(g);
  const TexelRect r = footprint_texels(o.tiling, *g, (*s)->bounds());
  ASSERT_GT(r.width(), 300u);
  std::vector<std::uint8_t> whole(r.width() * r.height() * 4);
  ASSERT_TRUE((*s)->read_window(r.x0, r.x1, r.y0, std::uint32_t(r.height()), whole.data()));
  std::uint64_t opaque = 0;
  for (std::size_t i = 3; i < whole.size(); i += 4) opaque += whole[i] == 255;
  ASSERT_GT(opaque, r.width() * r.height() / 2);
  // Pieces: columns split at odd places, rows read 7 at a time.
  const std::uint64_t xs[] = {r.x0, r.x0 + 37, r.x0 + r.width() / 2 + 3, r.x1};
  for (int c = 0; c < 3; ++c) {
    const std::uint64_t w = xs[c + 1] - xs[c];
    std::vector<std::uint8_t> piece(w * 7 * 4);
    for (std::uint64_t y = r.y0; y < r.y1; y += 7) {
      const auto n = std::uint32_t(std::min<std::uint64_t>(7, r.y1 - y));
      ASSERT_TRUE((*s)->read_window(xs[c], xs[c + 1], y, n, piece.data()));
      for (std::uint32_t k = 0; k < n; ++k)
        ASSERT_EQ(
            0, std::memcmp(piece.data() + k * w * 4,
                           whole.data() + ((y + k - r.y0) * r.width() + (xs[c] - r.x0)) * 4, w * 4))
            << "row " << y + k << ", columns " << xs[c] << ".." << xs[c + 1];
    }
  }
}

// Readers on different threads read strips of kWarpBlockRows rows at multiples of it, so that no
// two compute the same block of a warped VRT: that is GDALWarp's block height for VRT output.
TEST(GdalSource, WarpedVrtBlocksAreKWarpBlockRowsHigh) {
  vts::test::TempDir dir;
  const fs::path p = dir.path() / "w.tif";
  write_geotiff(p, 64, 32, 1, GDT_Byte, -180, 90, 5.625, code);
  GDALDatasetH src = GDALOpen(p.c_str(), GA_ReadOnly);
  ASSERT_NE(src, nullptr);
  char of[] = "-of", vrt[] = "VRT", t[] = "-t_srs", srs[] = "EPSG:3857", ts[] = "-ts", n[] = "1024";
  char* argv[] = {of, vrt, t, srs, ts, n, n, nullptr};  // taller than a block
  GDALWarpAppOptions* wo = GDALWarpAppOptionsNew(argv, nullptr);
  GDALDatasetH warped = GDALWarp("", nullptr, 1, &src, wo, nullptr);
  GDALWarpAppOptionsFree(wo);
  ASSERT_NE(warped, nullptr);
  int bx = 0, by = 0;
  GDALGetBlockSize(GDALGetRasterBand(warped, 1), &bx, &by);
  EXPECT_EQ(std::uint32_t(by), detail::kWarpBlockRows);
  GDALClose(warped);
  GDALClose(src);
}

// Checking 10^4 inputs takes a while before the first tile: the build reports it.
TEST(GdalBuild, ReportsTheInputsItHasCheckedBeforeItsTiles) {
  vts::test::TempDir dir;
  BuildOptions o;
  for (int i = 0; i < 3; ++i) {
    o.inputs.push_back(dir.path() / ("p" + std::to_string(i) + ".tif"));
    write_geotiff(o.inputs.back(), 16, 8, 3, GDT_Byte, -180 + 90 * i, 90, 5.625, code);
  }
  o.output = dir.path() / "out.pmtiles";
  o.tile_size = 16;
  o.threads = 1;
  std::vector<std::pair<std::uint64_t, std::uint64_t>> checked;
  bool tiles_after_inputs = true;
  o.on_progress = [&](const BuildProgress& p) {
    if (p.inputs_total)
      checked.emplace_back(p.inputs_checked, p.inputs_total);
    else if (p.tiles_total == 0 || checked.empty())
      tiles_after_inputs = false;
  };
  auto r = build_pyramid(o);
  ASSERT_TRUE(r) << r.error().message;
  ASSERT_FALSE(checked.empty());
  EXPECT_EQ(checked.back(), (std::pair<std::uint64_t, std::uint64_t>{3, 3}));
  EXPECT_TRUE(tiles_after_inputs);
}

// A footprint wider than the window limit is built in column stripes through a scratch file, and
// the scratch level again when it is still too wide: the archive's content is the same as one
// pass over the footprint's whole width, for both downsampling filters.
TEST(GdalBuild, StripesGiveTheSameTilesAsOnePass) {
  vts::test::TempDir dir;
  const fs::path a = dir.path() / "a.tif", b = dir.path() / "b.tif";
  write_geotiff(a, 120, 60, 3, GDT_Byte, -170, 80, 1.5, code);
  write_geotiff(b, 90, 80, 3, GDT_Byte, 10, 50, 0.9,
                [](int x, int y, int band) { return (x * x + y * band * 3) % 256; });
  for (DownsampleFilter f : {DownsampleFilter::box, DownsampleFilter::lanczos3}) {
    std::string hash;
    for (std::uint64_t limit : {std::uint64_t{0}, std::uint64_t{70}}) {
      SCOPED_TRACE(std::string(downsample_filter_name(f)) + ", window " + std::to_string(limit));
      BuildOptions o;
      o.inputs = {a, b};
      o.tiling = Tiling::world_crs84_quad;
      o.tile_size = 16;
      o.border = 2;
      o.max_level = 6;  // 1024 x 512 texels
      o.resampling = Resampling::bilinear;
      o.downsample = f;
      o.max_window_width = limit;
      o.threads = 2;
      o.output = dir.path() / ("out" + std::to_string(limit) + ".pmtiles");
      auto r = build_pyramid(o);
      ASSERT_TRUE(r) << r.error().message;
      if (limit == 0) {
        EXPECT_EQ(r->passes, 1u);
        hash = r->info.content_hash;
      } else {
        EXPECT_GT(r->passes, 8u);
        EXPECT_LE(r->window_width, limit);
        EXPECT_EQ(r->info.content_hash, hash) << "stripes changed the tiles";
      }
      EXPECT_EQ(r->stats.addressed_tiles,
                footprint_tile_count(o.tiling, r->info.geometry, r->info.georeference->bounds));
    }
  }
}

}  // namespace
}  // namespace vts
