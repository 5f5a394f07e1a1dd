#include "vts/imaging/web_mercator.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <numbers>
#include <set>

#include "vts/base/srgb.hpp"

namespace vts {
namespace {

// The synthetic source: WorldCRS84Quad, T = 4, border 1, levels 0..4 (level 4 is 64 x 32 texels).
// Texel (c, r) of level L is R = 4c, G = 8r, B = 50L + 5, opaque: interpolated in sRGB codes, R / 4
// and G / 8 give back the source position to 1/8 and 1/16 texel (rounding to a code).
constexpr std::uint32_t kT = 4;
constexpr int kMaxZ = 4;

TilesetInfo crs84_info(LonLatBounds bounds = {-180, -90, 180, 90}) {
  TilesetInfo info;
  info.geometry = *tiling_geometry(Tiling::world_crs84_quad, kMaxZ - 1, kT, 1);
  info.georeference = Georeference{Tiling::world_crs84_quad, bounds, {0, 0, 0}};
  return info;
}

using Paint = std::function<void(std::uint64_t c, std::uint64_t r, int level, std::uint8_t* t)>;

void position_paint(std::uint64_t c, std::uint64_t r, int level, std::uint8_t* t) {
  t[0] = static_cast<std::uint8_t>(4 * c);
  t[1] = static_cast<std::uint8_t>(8 * r);
  t[2] = static_cast<std::uint8_t>(50 * level + 5);
  t[3] = 255;
}

// A fetch building stored tiles in memory (borders clamped as the builder does), counting calls.
struct Source {
  const Geometry& g;
  Paint paint = position_paint;
  std::function<bool(TileId)> present = [](TileId) { return true; };
  std::map<TileId, int> calls;

  imaging::FetchStoredTile fetch() {
    return [this](TileId id) -> Result<std::optional<TileImage>> {
      ++calls[id];
      if (!g.exists(id) || !present(id)) return std::optional<TileImage>{};
      const std::uint32_t s = g.stored_size();
      TileImage im{s, s, PixelFormat::rgba8, std::vector<std::uint8_t>(std::size_t{s} * s * 4)};
      for (std::uint32_t sy = 0; sy < s; ++sy)
        for (std::uint32_t sx = 0; sx < s; ++sx)
          paint(g.stored_to_level_x(id, sx), g.stored_to_level_y(id, sy), id.z,
                &im.pixels[(std::size_t{sy} * s + sx) * 4]);
      return std::optional<TileImage>(std::move(im));
    };
  }
};

// Written out here rather than through tiling.hpp, so the test does not share the code it checks.
LonLat mercator_texel_centre(int z, std::uint32_t x, std::uint32_t y, std::uint32_t i,
                             std::uint32_t j) {
  const double n = std::ldexp(double(kT), z);
  const double px = (double(x) * kT + i + 0.5) / n, py = (double(y) * kT + j + 0.5) / n;
  return {px * 360.0 - 180.0,
          std::atan(std::sinh(std::numbers::pi * (1.0 - 2.0 * py))) * 180.0 / std::numbers::pi};
}

const std::uint8_t* texel(const TileImage& im, std::uint32_t i, std::uint32_t j) {
  return &im.pixels[(std::size_t{j} * im.width + i) * 4];
}

constexpr imaging::WebMercatorOptions kCodes{false};

TEST(WebMercator, SourceLevelIsTheZoomClampedToTheFinestLevel) {
  const Geometry g = crs84_info().geometry;
  EXPECT_EQ(imaging::web_mercator_source_level(g, 0), 0);
  EXPECT_EQ(imaging::web_mercator_source_level(g, 3), 3);
  EXPECT_EQ(imaging::web_mercator_source_level(g, 4), 4);
  EXPECT_EQ(imaging::web_mercator_source_level(g, 5), 4);
  EXPECT_EQ(imaging::web_mercator_source_level(g, 26), 4);
}

// Every output texel centre of every tile at zooms 0..6 (5 and 6 magnify the finest level 4): its
// longitude and latitude as the source texels read back are within 1/8 texel of the source level
// (1/8 of 360 / (2^L T) degrees), from the level min(z, 4), fetching only that level's tiles.
TEST(WebMercator, EveryOutputTexelCentreShowsItsLonLatFromTheRightLevel) {
  const TilesetInfo info = crs84_info();
  for (int z = 0; z <= 6; ++z) {
    const int level = std::min(z, kMaxZ);
    const double n = std::ldexp(double(kT), level);
    const double texel_deg = 360.0 / n;
    double worst_lon = 0, worst_lat = 0;
    int checked = 0;
    for (std::uint32_t y = 0; y < (1u << z); ++y) {
      for (std::uint32_t x = 0; x < (1u << z); ++x) {
        Source src{info.geometry};
        auto out = imaging::render_web_mercator_tile(info, z, x, y, src.fetch(), kCodes);
        ASSERT_TRUE(out.ok()) << out.error().to_string();
        ASSERT_TRUE(out->has_value());
        const TileImage& im = **out;
        ASSERT_EQ(im.width, kT);
        ASSERT_EQ(im.height, kT);
        for (const auto& [id, count] : src.calls) {
          EXPECT_EQ(count, 1) << id.to_string();
          EXPECT_EQ(id.z, level) << id.to_string();
          if (z <= kMaxZ) {
            EXPECT_EQ(id.x, x) << "z " << z << " reads one source column";
          }
        }
        for (std::uint32_t j = 0; j < kT; ++j) {
          for (std::uint32_t i = 0; i < kT; ++i) {
            const LonLat want = mercator_texel_centre(z, x, y, i, j);
            const std::uint8_t* t = texel(im, i, j);
            ASSERT_EQ(t[3], 255);
            ASSERT_EQ(t[2], 50 * level + 5) << "level of " << z << "/" << x << "/" << y;
            const double u = (want.lon + 180.0) / 360.0 * n - 0.5;
            if (u < 0 || u > n - 1) continue;  // blends across the antimeridian: another test
            const double v = (90.0 - want.lat) / 360.0 * n - 0.5;
            if (v < 0 || v > n / 2 - 1) continue;  // beyond the polar rows' centres: clamped
            const double lon = (t[0] / 4.0 + 0.5) * texel_deg - 180.0;
            const double lat = 90.0 - (t[1] / 8.0 + 0.5) * texel_deg;
            ++checked;
            worst_lon = std::max(worst_lon, std::abs(lon - want.lon) / texel_deg);
            worst_lat = std::max(worst_lat, std::abs(lat - want.lat) / texel_deg);
          }
        }
      }
    }
    // z 0 reads level 0, 2 rows: every Mercator row centre lies beyond one of the two centres.
    if (z > 0) {
      EXPECT_GE(checked, (1 << z) * (1 << z) * int{kT * kT} / 4) << "z " << z;
    }
    EXPECT_LE(worst_lon, 0.125 + 1e-9) << "z " << z;
    EXPECT_LE(worst_lat, 0.0625 + 1e-9) << "z " << z;
  }
}

TEST(WebMercator, ZoomZeroIsOneOpaqueTileFromPlusToMinus85Degrees) {
  const TilesetInfo info = crs84_info();
  Source src{info.geometry};
  auto out = imaging::render_web_mercator_tile(info, 0, 0, 0, src.fetch(), kCodes);
  ASSERT_TRUE(out.ok() && out->has_value());
  for (std::size_t k = 3; k < (*out)->pixels.size(); k += 4) EXPECT_EQ((*out)->pixels[k], 255);
  // The top row's centre: 1/8 of the way down the Mercator square, 79.17 degrees, is north of
  // level 0's first row centre (67.5 degrees): clamped to that row (G 0), as the bottom row to
  // the last (G 8).
  EXPECT_NEAR(mercator_texel_centre(0, 0, 0, 0, 0).lat, 79.17, 0.01);
  for (std::uint32_t i = 0; i < kT; ++i) {
    EXPECT_EQ(texel(**out, i, 0)[1], 0);
    EXPECT_EQ(texel(**out, i, kT - 1)[1], 8);
  }
  auto range = imaging::web_mercator_range(info);
  ASSERT_TRUE(range.ok());
  EXPECT_EQ(*range, (imaging::WebMercatorRange{
                        0, kMaxZ, {-180, -kWebMercatorMaxLat, 180, kWebMercatorMaxLat}}));
}

TEST(WebMercator, TileWhollyOutsideTheBoundsIsNothingAndFetchesNothing) {
  const TilesetInfo info = crs84_info({0, 0, 45, 40});
  Source src{info.geometry};
  // z 2 tiles are 90 degrees wide: x 1 ends at lon 0 (shares an edge only), x 3 starts at 90.
  for (std::uint32_t x : {0u, 1u, 3u}) {
    auto out = imaging::render_web_mercator_tile(info, 2, x, 1, src.fetch());
    ASSERT_TRUE(out.ok());
    EXPECT_FALSE(out->has_value()) << x;
  }
  auto south = imaging::render_web_mercator_tile(info, 2, 2, 2, src.fetch());  // lat 0..-66
  ASSERT_TRUE(south.ok());
  EXPECT_FALSE(south->has_value());
  EXPECT_TRUE(src.calls.empty());
  auto inside = imaging::render_web_mercator_tile(info, 2, 2, 1, src.fetch());
  ASSERT_TRUE(inside.ok());
  EXPECT_TRUE(inside->has_value());

  auto polar = imaging::web_mercator_range(crs84_info({-10, -90, 10, -86}));
  ASSERT_FALSE(polar.ok());
  EXPECT_EQ(polar.error().code, ErrorCode::invalid_argument);
  auto clipped = imaging::web_mercator_range(crs84_info({-10, -90, 10, 89}));
  ASSERT_TRUE(clipped.ok());
  EXPECT_EQ(clipped->bounds, (LonLatBounds{-10, -kWebMercatorMaxLat, 10, kWebMercatorMaxLat}));
}

// The source holds only its tiles with x >= 8 at level 4 (longitudes >= 0): output texels whose
// four source texels are all absent are transparent, those whose four are all present opaque.
TEST(WebMercator, AbsentSourceTilesAreTransparent) {
  const TilesetInfo info = crs84_info();
  const double n = std::ldexp(double(kT), kMaxZ);
  for (int z : {4, 5}) {
    int transparent = 0, opaque = 0;
    for (std::uint32_t x = 0; x < (1u << z); ++x) {
      Source src{info.geometry};
      src.present = [](TileId id) { return id.x >= 8; };
      auto out = imaging::render_web_mercator_tile(info, z, x, (1u << z) / 2, src.fetch(), kCodes);
      ASSERT_TRUE(out.ok() && out->has_value());
      for (std::uint32_t i = 0; i < kT; ++i) {
        const double u = (mercator_texel_centre(z, x, 0, i, 0).lon + 180.0) / 360.0 * n - 0.5;
        const std::uint8_t a = texel(**out, i, 0)[3];
        if (u + 1 < n / 2 && u > 0) {
          EXPECT_EQ(a, 0) << z << "/" << x << " " << i;
          ++transparent;
        }
        if (u >= n / 2 && u + 1 < n) {
          EXPECT_EQ(a, 255) << z << "/" << x << " " << i;
          ++opaque;
        }
      }
    }
    EXPECT_GT(transparent, 20);
    EXPECT_GT(opaque, 20);
  }
}

// Beside an absent tile, the transparent texels lower the alpha, never the colour: a uniform
// colour stays that colour at every partial alpha, in both blends.
TEST(WebMercator, AbsentNeighboursLowerAlphaNotColour) {
  const TilesetInfo info = crs84_info();
  for (bool linear : {true, false}) {
    int partial = 0;
    for (std::uint32_t x = 14; x < 18; ++x) {
      Source src{info.geometry};
      src.paint = [](std::uint64_t, std::uint64_t, int, std::uint8_t* t) {
        t[0] = 200, t[1] = 30, t[2] = 90, t[3] = 255;
      };
      src.present = [](TileId id) { return id.x >= 8; };
      auto out = imaging::render_web_mercator_tile(info, 5, x, 16, src.fetch(),
                                                   imaging::WebMercatorOptions{linear});
      ASSERT_TRUE(out.ok() && out->has_value());
      for (std::uint32_t i = 0; i < kT; ++i) {
        const std::uint8_t* t = texel(**out, i, 0);
        if (t[3] == 0) continue;
        partial += t[3] < 255;
        EXPECT_EQ(t[0], 200);
        EXPECT_EQ(t[1], 30);
        EXPECT_EQ(t[2], 90);
      }
    }
    EXPECT_GT(partial, 0) << "no texel straddles the edge of the absent tiles";
  }
}

// x = 0 and x = 2^z - 1 next to the antimeridian, y = 0 next to 85.05 degrees, up to the deepest
// zoom: every texel finite and opaque (no seam), and beyond max_zoom the texels west of the first
// source centre blend the last column (R 252) into the first (R 0) by their distance.
TEST(WebMercator, AntimeridianAndPoleEdgesAreSeamlessAtEveryZoom) {
  const TilesetInfo info = crs84_info();
  const double n = std::ldexp(double(kT), kMaxZ);
  for (int z : {0, 1, 4, 5, 9, 17, Geometry::kMaxZoom}) {
    const std::uint32_t last = static_cast<std::uint32_t>((std::uint64_t{1} << z) - 1);
    for (std::uint32_t x : {0u, last}) {
      for (std::uint32_t y : {0u, last}) {
        Source src{info.geometry};
        auto out = imaging::render_web_mercator_tile(info, z, x, y, src.fetch(), kCodes);
        ASSERT_TRUE(out.ok()) << out.error().to_string();
        ASSERT_TRUE(out->has_value());
        for (std::uint32_t j = 0; j < kT; ++j) {
          for (std::uint32_t i = 0; i < kT; ++i) {
            const std::uint8_t* t = texel(**out, i, j);
            EXPECT_EQ(t[3], 255) << z << "/" << x << "/" << y;
            const double u = (mercator_texel_centre(z, x, y, i, j).lon + 180.0) / 360.0 * n - 0.5;
            double want = 4 * u;  // inside the level
            if (u < 0) want = -u * 252;
            if (u > n - 1) want = (n - u) * 252;
            if (z >= kMaxZ) {
              EXPECT_NEAR(t[0], want, 0.5 + 1e-6) << z << "/" << x << "/" << y;
            }
          }
        }
      }
    }
  }
}

TEST(WebMercator, LinearLightBlendsDecodedColoursAndCodesBlendCodes) {
  const TilesetInfo info = crs84_info();
  Source src{info.geometry};
  src.paint = [](std::uint64_t c, std::uint64_t, int, std::uint8_t* t) {
    t[0] = t[1] = t[2] = c % 2 ? 255 : 0;
    t[3] = 255;
  };
  // z 5 magnifies level 4 by 2: output texel k's centre is at source u = k/2 - 1/4, so the weights
  // are 3/4 and 1/4 on a black and a white texel.
  for (bool linear : {true, false}) {
    auto out = imaging::render_web_mercator_tile(info, 5, 10, 16, src.fetch(),
                                                 imaging::WebMercatorOptions{linear});
    ASSERT_TRUE(out.ok() && out->has_value());
    for (std::uint32_t k = 0; k < kT; ++k) {
      const std::uint32_t global = 10 * kT + k;
      const double u = global / 2.0 - 0.25;
      const double frac = u - std::floor(u);
      const bool left_white = static_cast<std::uint64_t>(std::floor(u)) % 2 == 1;
      const double white = left_white ? 1 - frac : frac;
      const int want =
          linear ? encode_srgb8_exact(white) : static_cast<int>(std::lround(255 * white));
      EXPECT_EQ(texel(**out, k, 0)[0], want) << "linear " << linear << " k " << k;
    }
  }
  EXPECT_EQ(encode_srgb8_exact(0.25), 137);  // what linear light gives: brighter than 64
}

TEST(WebMercator, RefusesBadTilesNonCrs84TilesetsAndWrongFetches) {
  const TilesetInfo info = crs84_info();
  Source src{info.geometry};
  auto expect_invalid = [&](const TilesetInfo& i, int z, std::uint32_t x, std::uint32_t y) {
    auto out = imaging::render_web_mercator_tile(i, z, x, y, src.fetch());
    ASSERT_FALSE(out.ok()) << z << "/" << x << "/" << y;
    EXPECT_EQ(out.error().code, ErrorCode::invalid_argument) << out.error().to_string();
  };
  expect_invalid(info, -1, 0, 0);
  expect_invalid(info, Geometry::kMaxZoom + 1, 0, 0);
  expect_invalid(info, 0, 1, 0);
  expect_invalid(info, 0, 0, 1);
  expect_invalid(info, 3, 8, 0);
  expect_invalid(info, 3, 0, 8);
  TilesetInfo merc;
  merc.geometry = *tiling_geometry(Tiling::web_mercator_quad, 2, kT, 1);
  merc.georeference = Georeference{Tiling::web_mercator_quad, {-10, -10, 10, 10}, {0, 0, 0}};
  expect_invalid(merc, 0, 0, 0);
  TilesetInfo plain;
  expect_invalid(plain, 0, 0, 0);
  EXPECT_FALSE(imaging::web_mercator_range(merc).ok());
  EXPECT_TRUE(src.calls.empty());

  imaging::FetchStoredTile failing = [](TileId) -> Result<std::optional<TileImage>> {
    return make_error(ErrorCode::checksum, "tile 2/1/0 is damaged");
  };
  auto err = imaging::render_web_mercator_tile(info, 2, 1, 1, failing);
  ASSERT_FALSE(err.ok());
  EXPECT_EQ(err.error().code, ErrorCode::checksum);
  EXPECT_EQ(err.error().message, "tile 2/1/0 is damaged");

  imaging::FetchStoredTile small = [](TileId) -> Result<std::optional<TileImage>> {
    return std::optional<TileImage>(
        TileImage{4, 4, PixelFormat::rgba8, std::vector<std::uint8_t>(64, 255)});
  };
  auto wrong = imaging::render_web_mercator_tile(info, 2, 1, 1, small);
  ASSERT_FALSE(wrong.ok());
  EXPECT_EQ(wrong.error().code, ErrorCode::corrupt);
  EXPECT_NE(wrong.error().message.find("stored size 6x6"), std::string::npos)
      << wrong.error().message;
}

}  // namespace
}  // namespace vts
