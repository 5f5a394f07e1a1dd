// The resampling table of `vts bench accuracy` on real GDAL builds: the pattern GeoTIFF holds the
// pattern at its pixel centres in its CRS, the score of a real build against the analytic pattern
// is at the 8-bit rounding floor for cubic on the smooth pattern, and a wrong reference (half a
// texel off, or the other pattern) or a worse method scores clearly worse, so the table's low
// figures are not an artefact of comparing the warper with itself.
#include <gdal.h>
#include <gtest/gtest.h>
#include <ogr_srs_api.h>

#include <cmath>
#include <string>
#include <vector>

#include "resampling_detail.hpp"
#include "vts/accuracy/accuracy.hpp"
#include "vts/builder/builder.hpp"
#include "vts/test/temp_dir.hpp"

namespace vts::accuracy {
namespace {

namespace fs = std::filesystem;
using detail::PatternRaster;
using detail::WarpPattern;

// 64 x 64 pixels of 3200 m at 9 E 45 N in UTM 32N: what the table builds, smaller.
PatternRaster small_raster(WarpPattern p) {
  PatternRaster r;
  r.pixel = 3200;
  r.width = r.height = 64;
  r.x0 = 500000 - 32 * r.pixel;
  r.y0 = 4985000 + 32 * r.pixel;
  r.pattern = p;
  return r;
}

fs::path build(const PatternRaster& r, Resampling m, const test::TempDir& dir) {
  const fs::path tif = dir / (std::string(detail::warp_pattern_name(r.pattern)) + ".tif");
  EXPECT_TRUE(detail::write_pattern_geotiff(r, tif));
  BuildOptions o;
  o.inputs = {tif};
  o.tiling = Tiling::world_crs84_quad;
  o.max_level = 6;
  o.value_range = std::pair{0.0, 255.0};
  o.resampling = m;
  o.output = dir / (std::string(resampling_name(m)) + ".pmtiles");
  auto built = build_pyramid(o);
  EXPECT_TRUE(built) << (built ? "" : built.error().message);
  return o.output;
}

TEST(AccuracyResampling, GeotiffHoldsThePatternAtPixelCentres) {
  test::TempDir dir;
  const PatternRaster r = small_raster(WarpPattern::fine);
  const fs::path tif = dir / "p.tif";
  ASSERT_TRUE(detail::write_pattern_geotiff(r, tif));
  GDALDatasetH ds = GDALOpen(tif.c_str(), GA_ReadOnly);
  ASSERT_NE(ds, nullptr);
  double gt[6];
  ASSERT_EQ(GDALGetGeoTransform(ds, gt), CE_None);
  EXPECT_DOUBLE_EQ(gt[0], r.x0);
  EXPECT_DOUBLE_EQ(gt[3], r.y0);
  EXPECT_DOUBLE_EQ(gt[1], r.pixel);
  EXPECT_DOUBLE_EQ(gt[5], -r.pixel);
  OGRSpatialReferenceH srs = GDALGetSpatialRef(ds);
  ASSERT_NE(srs, nullptr);
  EXPECT_STREQ(OSRGetAuthorityCode(srs, nullptr), "32632");
  EXPECT_EQ(GDALGetRasterDataType(GDALGetRasterBand(ds, 1)), GDT_Float32);
  std::vector<float> px(std::size_t(r.width) * r.height);
  ASSERT_EQ(GDALRasterIO(GDALGetRasterBand(ds, 1), GF_Read, 0, 0, r.width, r.height, px.data(),
                         r.width, r.height, GDT_Float32, 0, 0),
            CE_None);
  GDALClose(ds);
  double lo = 255, hi = 0;
  for (int j = 0; j < r.height; ++j)
    for (int i = 0; i < r.width; ++i) {
      const double v = px[std::size_t(j) * r.width + i];
      EXPECT_NEAR(v, r.value(r.x0 + (i + 0.5) * r.pixel, r.y0 - (j + 0.5) * r.pixel), 1e-4);
      lo = std::min(lo, v), hi = std::max(hi, v);
    }
  // The fine pattern swings over most of its 47.5 .. 207.5 range within 64 pixels.
  EXPECT_GT(lo, 47);
  EXPECT_LT(hi, 208);
  EXPECT_GT(hi - lo, 120);
}

TEST(AccuracyResampling, ScoreIsAtTheRoundingFloorAndCatchesAWrongReference) {
  test::TempDir dir;
  const PatternRaster smooth = small_raster(WarpPattern::smooth);
  const fs::path cubic = build(smooth, Resampling::cubic, dir);
  auto right = detail::score_warp(cubic, smooth, 4);
  ASSERT_TRUE(right) << right.error().message;
  EXPECT_GT(right->texels, 1000u);
  // Rounding to 8 bits alone is 1/sqrt(12) = 0.289 RMS, 0.5 max.
  EXPECT_GT(right->rms(), 0.25);
  EXPECT_LT(right->rms(), 0.4);
  EXPECT_LT(right->max_abs, 1.0);
  EXPECT_LT(std::fabs(right->bias()), 0.05);

  // The same build against references that are wrong: half a texel east, half a texel south, the
  // other pattern. Each is many times worse.
  for (const TexelPoint off : {TexelPoint{0.5, 0}, TexelPoint{0, 0.5}}) {
    auto shifted = detail::score_warp(cubic, smooth, 4, off);
    ASSERT_TRUE(shifted);
    EXPECT_GT(shifted->rms(), 5 * right->rms()) << off.x << "," << off.y;
  }
  auto other = detail::score_warp(cubic, small_raster(WarpPattern::fine), 4);
  ASSERT_TRUE(other);
  EXPECT_GT(other->rms(), 30);

  // near, against the right reference, is worse than cubic by an order of magnitude.
  const fs::path near = build(smooth, Resampling::nearest, dir);
  auto n = detail::score_warp(near, smooth, 4);
  ASSERT_TRUE(n);
  EXPECT_GT(n->rms(), 10 * right->rms());
}

TEST(AccuracyResampling, ScoreRefusesWhatItCannotScore) {
  test::TempDir dir;
  const PatternRaster smooth = small_raster(WarpPattern::smooth);
  auto missing = detail::score_warp(dir / "missing.pmtiles", smooth, 4);
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().code, ErrorCode::not_found);

  BuildOptions o;
  o.synthetic = SyntheticSpec{300, 200};
  o.output = dir / "plain.pmtiles";
  ASSERT_TRUE(build_pyramid(o));
  auto plain = detail::score_warp(o.output, smooth, 4);
  ASSERT_FALSE(plain);
  EXPECT_EQ(plain.error().code, ErrorCode::invalid_argument);
  EXPECT_NE(plain.error().message.find("not georeferenced"), std::string::npos);

  // A margin wider than the raster leaves nothing to compare: an error, not a perfect score.
  const fs::path cubic = build(smooth, Resampling::cubic, dir);
  auto none = detail::score_warp(cubic, smooth, 40);
  ASSERT_FALSE(none);
  EXPECT_EQ(none.error().code, ErrorCode::invalid_argument);
}

TEST(AccuracyResampling, QuickTableRanksTheMethods) {
  test::TempDir dir;
  AccuracyContext ctx;
  ctx.work_dir = dir.path();
  ctx.quick = true;
  auto t = resampling_table(ctx);
  ASSERT_TRUE(t) << t.error().message;
  EXPECT_EQ(t->id, "resampling");
  ASSERT_EQ(t->rows.size(), 12u);  // 2 patterns x 4 methods, then cubic at -et 0 and 0.125 each
  ASSERT_EQ(t->columns[2].key, "rms_error");
  auto rms = [&](std::size_t row) { return std::get<double>(t->rows[row][2]); };
  auto label = [&](std::size_t row) {
    return std::get<std::string>(t->rows[row][0]) + " " + std::get<std::string>(t->rows[row][1]);
  };
  EXPECT_EQ(label(0), "smooth near");
  EXPECT_EQ(label(3), "smooth lanczos");
  EXPECT_EQ(label(4), "fine near");
  EXPECT_EQ(label(7), "fine lanczos");
  // Smooth: every interpolating kernel beats near, cubic and lanczos are near the rounding floor.
  EXPECT_LT(rms(1), rms(0));
  EXPECT_LT(rms(2), rms(1));
  EXPECT_LT(rms(3), rms(1));
  EXPECT_LT(rms(2), 0.4);
  // Fine (near Nyquist): the longer the kernel, the better.
  EXPECT_LT(rms(5), rms(4));
  EXPECT_LT(rms(6), rms(5));
  EXPECT_LT(rms(7), rms(6));
  for (const auto& row : t->rows) EXPECT_GT(std::get<double>(row[7]), 0);  // build seconds
  // The transformer: rows 8..11 are smooth cubic exact, smooth cubic 0.125, fine exact, fine 0.125.
  ASSERT_EQ(t->columns[9].key, "warp_error");
  auto et = [&](std::size_t row) { return std::get<double>(t->rows[row][9]); };
  EXPECT_EQ(et(2), 0.01);
  EXPECT_EQ(label(8), "smooth cubic");
  EXPECT_EQ(et(8), 0.0);
  EXPECT_EQ(et(9), 0.125);
  // The default's error is the exact transformer's (on the smooth pattern it is the 8-bit floor);
  // gdalwarp's default 0.125 px is clearly worse.
  EXPECT_LT(rms(2), rms(8) * 1.05);
  EXPECT_GT(rms(9), rms(2) * 1.5);
  // Nothing was left in the work directory.
  EXPECT_TRUE(fs::is_empty(dir.path()));
}

}  // namespace
}  // namespace vts::accuracy
