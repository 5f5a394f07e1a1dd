// The windowed cascade (builder/src/cascade.hpp) against a whole-image reference: an image that is
// transparent outside a window, reduced level by level with downsample_image_rgba8 and cut into
// tiles with Geometry's clamp-to-edge, must give every tile of every level byte for byte when only
// the window's rows are pushed; and a column stripe with stripe_halo() must give its own tiles and
// its coarsest columns exactly although it sees none of its neighbours' texels.
#include "cascade.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <map>
#include <tuple>
#include <vector>

#include "build_plan.hpp"
#include "vts/builder/downsample.hpp"

namespace vts {
namespace {

using detail::Cascade;
using Rgba8 = std::vector<std::uint8_t>;

// A textured image, transparent outside `data`; partly translucent so alpha is exercised.
Rgba8 make_image(std::uint64_t w, std::uint64_t h, const TexelRect& data) {
  Rgba8 img(w * h * 4, 0);
  for (std::uint64_t y = data.y0; y < data.y1; ++y)
    for (std::uint64_t x = data.x0; x < data.x1; ++x) {
      std::uint8_t* p = img.data() + (y * w + x) * 4;
      p[0] = static_cast<std::uint8_t>((x * 37 + y * 11) % 256);
      p[1] = static_cast<std::uint8_t>((x * x + 3 * y) % 256);
      p[2] = static_cast<std::uint8_t>((x ^ y) * 5 % 256);
      p[3] = (x + y) % 7 == 0 ? 128 : 255;
    }
  return img;
}

// Every level of the whole image (index z).
std::vector<Rgba8> reference_levels(const Geometry& g, Rgba8 finest, DownsampleFilter f) {
  std::vector<Rgba8> levels(static_cast<std::size_t>(g.max_zoom()) + 1);
  levels.back() = std::move(finest);
  for (int z = g.max_zoom(); z > 0; --z)
    levels[static_cast<std::size_t>(z - 1)] = downsample_image_rgba8(
        levels[static_cast<std::size_t>(z)].data(), g.level_width(z), g.level_height(z), f);
  return levels;
}

Rgba8 reference_tile(const Geometry& g, const Rgba8& level, TileId id) {
  const std::uint32_t S = g.stored_size();
  Rgba8 t(std::size_t{S} * S * 4);
  for (std::uint32_t sy = 0; sy < S; ++sy)
    for (std::uint32_t sx = 0; sx < S; ++sx)
      std::memcpy(
          t.data() + (sy * S + sx) * 4,
          level.data() +
              (g.stored_to_level_y(id, sy) * g.level_width(id.z) + g.stored_to_level_x(id, sx)) * 4,
          4);
  return t;
}

using Tiles = std::map<std::tuple<int, std::uint32_t, std::uint32_t>, Rgba8>;

// Pushes the window's rows of `image` through a cascade of levels finest..coarsest.
Tiles run(const Geometry& g, const Rgba8& image, const std::vector<TexelRect>& windows,
          int coarsest, DownsampleFilter f, const std::vector<TileRect>& emit,
          std::map<std::uint64_t, Rgba8>* coarse_rows = nullptr) {
  Tiles tiles;
  const int finest = g.max_zoom();
  Cascade::RowSink rows;
  if (coarse_rows) {
    const std::uint64_t w = windows[static_cast<std::size_t>(coarsest)].width() * 4;
    rows = [&, w](std::uint64_t y, const std::uint8_t* row) {
      (*coarse_rows)[y] = Rgba8(row, row + w);
    };
  }
  Cascade c(
      g, finest, coarsest, windows, f, emit,
      [&](TileId id, TileImage&& img) {
        EXPECT_TRUE(tiles.emplace(std::tuple{int(id.z), id.x, id.y}, std::move(img.pixels)).second)
            << "tile cut twice";
      },
      rows);
  const TexelRect& w = windows.back();
  for (std::uint64_t y = w.y0; y < w.y1; ++y)
    c.push_row(image.data() + (y * g.level_width(finest) + w.x0) * 4);
  return tiles;
}

std::vector<TexelRect> derive(const Geometry& g, TexelRect finest, int coarsest,
                              DownsampleFilter f) {
  std::vector<TexelRect> w(static_cast<std::size_t>(g.max_zoom()) + 1);
  w.back() = finest;
  for (int z = g.max_zoom(); z > coarsest; --z)
    w[static_cast<std::size_t>(z - 1)] =
        detail::coarser_window(g, z, w[static_cast<std::size_t>(z)], f);
  return w;
}

std::vector<TileRect> all_tiles(const Geometry& g) {
  std::vector<TileRect> e;
  for (int z = 0; z <= g.max_zoom(); ++z) e.push_back({0, 0, g.tiles_x(z), g.tiles_y(z)});
  return e;
}

struct Case {
  std::uint64_t w, h;
  TexelRect data;
};

class WindowedCascade : public ::testing::TestWithParam<DownsampleFilter> {};

TEST_P(WindowedCascade, EveryTileOfEveryLevelEqualsTheWholeImageBuild) {
  const DownsampleFilter f = GetParam();
  for (const Case& k : {Case{300, 170, {70, 41, 191, 131}},       // inside, odd edges
                        Case{300, 170, {1, 1, 300, 170}},         // touching right and bottom
                        Case{257, 129, {0, 100, 9, 129}},         // a sliver in a corner
                        Case{512, 256, {256, 128, 257, 129}}}) {  // one texel
    SCOPED_TRACE(std::to_string(k.w) + "x" + std::to_string(k.h) + " data " +
                 std::to_string(k.data.x0) + "," + std::to_string(k.data.y0) + "," +
                 std::to_string(k.data.x1) + "," + std::to_string(k.data.y1));
    auto g = Geometry::create(k.w, k.h, 16, 2);
    ASSERT_TRUE(g);
    const Rgba8 image = make_image(k.w, k.h, k.data);
    const std::vector<Rgba8> ref = reference_levels(*g, image, f);
    const Tiles tiles = run(*g, image, derive(*g, k.data, 0, f), 0, f, all_tiles(*g));
    ASSERT_EQ(tiles.size(), g->total_tile_count());
    for (const auto& [key, pixels] : tiles) {
      const auto [z, x, y] = key;
      const TileId id{static_cast<std::uint8_t>(z), x, y};
      ASSERT_EQ(pixels, reference_tile(*g, ref[static_cast<std::size_t>(z)], id))
          << "tile " << z << "/" << x << "/" << y;
    }
  }
}

TEST_P(WindowedCascade, AStripeWithItsHaloIsExactInItsOwnColumns) {
  const DownsampleFilter f = GetParam();
  auto g = Geometry::create(1024, 200, 16, 2);
  ASSERT_TRUE(g);
  const TexelRect data{0, 0, 1024, 200};
  const Rgba8 image = make_image(1024, 200, data);
  const std::vector<Rgba8> ref = reference_levels(*g, image, f);
  const int s = 3, finest = g->max_zoom(), coarsest = finest - s;
  const std::uint64_t block = 16 << s, halo = detail::stripe_halo(*g, s, f);
  for (std::uint64_t j = 0; j < 1024 / block; ++j) {
    SCOPED_TRACE("stripe " + std::to_string(j) + ", halo " + std::to_string(halo));
    TexelRect w = data;
    w.x0 = j * block > halo ? j * block - halo : 0;
    w.x1 = std::min<std::uint64_t>(1024, (j + 1) * block + halo);
    std::vector<TileRect> emit(static_cast<std::size_t>(finest) + 1);
    for (int z = coarsest + 1; z <= finest; ++z) {
      const int shift = s - (finest - z);
      emit[static_cast<std::size_t>(z)] = {static_cast<std::uint32_t>(j << shift), 0,
                                           static_cast<std::uint32_t>((j + 1) << shift),
                                           g->tiles_y(z)};
    }
    const std::vector<TexelRect> windows = derive(*g, w, coarsest, f);
    std::map<std::uint64_t, Rgba8> rows;
    const Tiles tiles = run(*g, image, windows, coarsest, f, emit, &rows);
    for (const auto& [key, pixels] : tiles) {
      const auto [z, x, y] = key;
      ASSERT_EQ(pixels, reference_tile(*g, ref[static_cast<std::size_t>(z)],
                                       TileId{static_cast<std::uint8_t>(z), x, y}))
          << "tile " << z << "/" << x << "/" << y;
    }
    // Its columns of the coarsest level: [16 j, 16 (j + 1)).
    const TexelRect& cw = windows[static_cast<std::size_t>(coarsest)];
    ASSERT_EQ(rows.size(), cw.height());
    for (const auto& [y, row] : rows)
      for (std::uint64_t x = 16 * j; x < 16 * (j + 1); ++x)
        ASSERT_EQ(0, std::memcmp(row.data() + (x - cw.x0) * 4,
                                 ref[static_cast<std::size_t>(coarsest)].data() +
                                     (y * g->level_width(coarsest) + x) * 4,
                                 4))
            << "coarsest texel " << x << "," << y;
    // A shorter halo is not enough (the test can fail): one texel short for the box filter;
    // Lanczos-3's outer taps weigh so little that 8-bit rounding hides one texel, not half the
    // halo.
    if (j == 1) {
      const std::uint64_t cut = f == DownsampleFilter::box ? 1 : halo / 2;
      TexelRect narrow = w;
      narrow.x0 += cut;
      narrow.x1 -= cut;
      const Tiles wrong = run(*g, image, derive(*g, narrow, coarsest, f), coarsest, f, emit);
      bool differs = false;
      for (const auto& [key, pixels] : wrong) {
        const auto [z, x, y] = key;
        differs |= pixels != reference_tile(*g, ref[static_cast<std::size_t>(z)],
                                            TileId{static_cast<std::uint8_t>(z), x, y});
      }
      EXPECT_TRUE(differs) << "a halo " << cut << " texels short gives the same tiles";
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Filters, WindowedCascade,
                         ::testing::Values(DownsampleFilter::box, DownsampleFilter::lanczos3),
                         [](const auto& p) {
                           return std::string(downsample_filter_name(p.param));
                         });

TEST(BuildPlan, AWideFootprintIsCutIntoStripesAndItsScratchLevelsAgain) {
  auto g = Geometry::create(4096, 2048, 16, 2);
  ASSERT_TRUE(g);
  const std::vector<TileRect> emit = all_tiles(*g);
  auto one = detail::make_build_plan(*g, DownsampleFilter::box, {0, 0, 4096, 2048}, emit, 1 << 20);
  ASSERT_TRUE(one);
  EXPECT_EQ(one->passes.size(), 1u);
  EXPECT_EQ(one->tiles, g->total_tile_count());
  auto cut = detail::make_build_plan(*g, DownsampleFilter::box, {0, 0, 4096, 2048}, emit, 200);
  ASSERT_TRUE(cut) << cut.error().message;
  EXPECT_GT(cut->scratch.size(), 1u);  // the stripes' scratch is itself too wide once
  EXPECT_LE(cut->widest, 200u);
  EXPECT_EQ(cut->tiles, g->total_tile_count());  // every tile once
  auto tiny = detail::make_build_plan(*g, DownsampleFilter::lanczos3, {0, 0, 4096, 2048}, emit, 40);
  ASSERT_FALSE(tiny);
  EXPECT_EQ(tiny.error().code, ErrorCode::invalid_argument);
}

}  // namespace
}  // namespace vts
