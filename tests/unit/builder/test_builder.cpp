#include "vts/builder/builder.hpp"

#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include "vts/archive/pmtiles.hpp"
#include "vts/builder/downsample.hpp"
#include "vts/builder/extract.hpp"
#include "vts/builder/synthetic.hpp"
#include "vts/test/temp_dir.hpp"

namespace vts {
namespace {

namespace fs = std::filesystem;
namespace OIIO = OIIO_NAMESPACE;

using TempDir = vts::test::TempDir;

struct Rgba {
  std::uint64_t w = 0, h = 0;
  std::vector<std::uint8_t> px;
  const std::uint8_t* at(std::uint64_t x, std::uint64_t y) const { return &px[(y * w + x) * 4]; }
};

// The source image as RGBA8, the way the builder is specified to see it (straight alpha: PNG
// texels as stored, not premultiplied by the reader).
Rgba read_source(const fs::path& p) {
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  auto in = OIIO::ImageInput::open(p.string(), &config);
  EXPECT_TRUE(in) << p;
  const auto& spec = in->spec();
  Rgba img;
  img.w = spec.width;
  img.h = spec.height;
  std::vector<std::uint8_t> raw(img.w * img.h * spec.nchannels);
  EXPECT_TRUE(in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::UINT8, raw.data()));
  img.px.resize(img.w * img.h * 4);
  for (std::uint64_t i = 0; i < img.w * img.h; ++i) {
    const std::uint8_t* s = &raw[i * spec.nchannels];
    std::uint8_t* d = &img.px[i * 4];
    if (spec.nchannels >= 3) {
      d[0] = s[0], d[1] = s[1], d[2] = s[2], d[3] = spec.nchannels >= 4 ? s[3] : 255;
    } else {
      d[0] = d[1] = d[2] = s[0];
      d[3] = spec.nchannels == 2 ? s[1] : 255;
    }
  }
  return img;
}

void write_image(const fs::path& p, std::uint64_t w, std::uint64_t h, int channels,
                 const std::vector<std::uint8_t>& data) {
  auto out = OIIO::ImageOutput::create(p.string());
  ASSERT_TRUE(out);
  OIIO::ImageSpec spec(static_cast<int>(w), static_cast<int>(h), channels, OIIO::TypeDesc::UINT8);
  ASSERT_TRUE(out->open(p.string(), spec));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, data.data()));
  out->close();
}

std::vector<std::uint8_t> noise(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::vector<std::uint8_t> v(n);
  for (auto& b : v) b = static_cast<std::uint8_t>(rng());
  return v;
}

struct Archive {
  std::shared_ptr<archive::Reader> reader;
  TilesetInfo info;

  static Archive open(const fs::path& p) {
    auto r = archive::Reader::open(p);
    EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().to_string());
    auto info = TilesetInfo::from_json((*r)->metadata_json());
    EXPECT_TRUE(info.ok()) << (info.ok() ? "" : info.error().to_string());
    return {*r, *info};
  }
  TileImage tile(TileId id) const {
    auto bytes = reader->get(id);
    EXPECT_TRUE(bytes.ok()) << id.to_string();
    auto img = decode_tile(*bytes);
    EXPECT_TRUE(img.ok()) << id.to_string();
    return *img;
  }
  // Level z stitched together from tile contents.
  Rgba level(int z) const {
    const Geometry& g = info.geometry;
    Rgba out{g.level_width(z), g.level_height(z), {}};
    out.px.resize(out.w * out.h * 4);
    const std::uint32_t S = g.stored_size(), B = g.border();
    for (std::uint32_t ty = 0; ty < g.tiles_y(z); ++ty)
      for (std::uint32_t tx = 0; tx < g.tiles_x(z); ++tx) {
        const TileId id{static_cast<std::uint8_t>(z), tx, ty};
        const TileImage t = tile(id);
        const TexelRect r = g.content_rect(id);
        for (std::uint64_t y = r.y0; y < r.y1; ++y)
          std::memcpy(&out.px[(y * out.w + r.x0) * 4], &t.pixels[((B + y - r.y0) * S + B) * 4],
                      r.width() * 4);
      }
    return out;
  }
};

BuildReport build(BuildOptions o) {
  auto r = build_pyramid(o);
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().to_string());
  return r.ok() ? *r : BuildReport{};
}

BuildOptions options_for(const fs::path& in, const fs::path& out) {
  BuildOptions o;
  o.inputs = {in};
  o.output = out;
  o.threads = 2;
  return o;
}

void expect_same(const Rgba& a, const Rgba& b, const std::string& what) {
  ASSERT_EQ(a.w, b.w) << what;
  ASSERT_EQ(a.h, b.h) << what;
  std::size_t diffs = 0, first = SIZE_MAX;
  for (std::size_t i = 0; i < a.px.size(); ++i)
    if (a.px[i] != b.px[i]) {
      ++diffs;
      if (first == SIZE_MAX) first = i;
    }
  EXPECT_EQ(diffs, 0u) << what << ": first difference at texel " << first / 4 << " ("
                       << (first / 4) % a.w << "," << (first / 4) / a.w << ")";
}

// Every stored texel of every tile equals the level texel at its clamped coordinates: borders are
// copies of the neighbours' content, clamped at the image edge.
void expect_borders_match(const Archive& a, int z, const Rgba& level) {
  const Geometry& g = a.info.geometry;
  const std::uint32_t S = g.stored_size();
  std::size_t bad = 0;
  for (std::uint32_t ty = 0; ty < g.tiles_y(z); ++ty)
    for (std::uint32_t tx = 0; tx < g.tiles_x(z); ++tx) {
      const TileId id{static_cast<std::uint8_t>(z), tx, ty};
      const TileImage t = a.tile(id);
      for (std::uint32_t sy = 0; sy < S; ++sy)
        for (std::uint32_t sx = 0; sx < S; ++sx)
          bad += std::memcmp(&t.pixels[(std::size_t{sy} * S + sx) * 4],
                             level.at(g.stored_to_level_x(id, sx), g.stored_to_level_y(id, sy)),
                             4) != 0;
    }
  EXPECT_EQ(bad, 0u) << "texels differing from the clamped level image at z=" << z;
}

// Double-precision reference of the 2x2 linear-light reduction.
Rgba reference_downsample(const Rgba& in) {
  Rgba out{(in.w + 1) / 2, (in.h + 1) / 2, {}};
  out.px.resize(out.w * out.h * 4);
  for (std::uint64_t y = 0; y < out.h; ++y)
    for (std::uint64_t x = 0; x < out.w; ++x) {
      const std::uint64_t xs[2] = {2 * x, std::min(2 * x + 1, in.w - 1)};
      const std::uint64_t ys[2] = {2 * y, std::min(2 * y + 1, in.h - 1)};
      for (int c = 0; c < 4; ++c) {
        double sum = 0;
        for (auto yy : ys)
          for (auto xx : xs) {
            const double v = in.at(xx, yy)[c] / 255.0;
            sum += c == 3 ? v : srgb_to_linear(v);
          }
        const double mean = sum / 4;
        const double enc = c == 3 ? mean : linear_to_srgb(mean);
        out.px[(y * out.w + x) * 4 + c] = static_cast<std::uint8_t>(std::lround(enc * 255.0));
      }
    }
  return out;
}

int max_abs_diff(const Rgba& a, const Rgba& b) {
  int m = 0;
  for (std::size_t i = 0; i < a.px.size(); ++i) m = std::max(m, std::abs(a.px[i] - b.px[i]));
  return m;
}

TEST(Builder, EarthImageRoundTripsLosslesslyAtTheFinestLevel) {
  TempDir dir;
  const fs::path earth = VTS_EARTH_JPG;
  ASSERT_TRUE(fs::exists(earth)) << "xplanet-images is not installed";
  const BuildReport r = build(options_for(earth, dir / "earth.pmtiles"));
  const Archive a = Archive::open(dir / "earth.pmtiles");
  EXPECT_EQ(a.info.geometry.width(), 2048u);
  EXPECT_EQ(a.info.geometry.height(), 1024u);
  EXPECT_EQ(a.info.geometry.max_zoom(), 3);
  EXPECT_EQ(r.stats.addressed_tiles, a.info.geometry.total_tile_count());
  const Rgba finest = a.level(3);
  expect_same(finest, read_source(earth), "finest level vs earth.jpg");
  expect_borders_match(a, 3, finest);
  for (int z = 3; z > 0; --z) {
    const Rgba child = a.level(z), parent = a.level(z - 1);
    EXPECT_LE(max_abs_diff(parent, reference_downsample(child)), 1) << "z=" << z - 1;
    expect_borders_match(a, z - 1, parent);
  }
}

class OddSizes : public ::testing::TestWithParam<std::tuple<int, int, int>> {};

TEST_P(OddSizes, FinestLevelBordersAndParentsAreExact) {
  const auto [w, h, channels] = GetParam();
  TempDir dir;
  const fs::path in = dir / "in.png";
  write_image(in, w, h, channels, noise(std::size_t(w) * h * channels, w * 31 + h));
  BuildOptions o = options_for(in, dir / "out.pmtiles");
  o.tile_size = 64;
  o.border = 3;
  build(o);
  const Archive a = Archive::open(dir / "out.pmtiles");
  const int mz = a.info.geometry.max_zoom();
  const Rgba finest = a.level(mz);
  expect_same(finest, read_source(in), "finest level");
  expect_borders_match(a, mz, finest);
  for (int z = mz; z > 0; --z) {
    const Rgba parent = a.level(z - 1);
    EXPECT_LE(max_abs_diff(parent, reference_downsample(a.level(z))), 1) << "z=" << z - 1;
    expect_borders_match(a, z - 1, parent);
  }
}

INSTANTIATE_TEST_SUITE_P(Builder, OddSizes,
                         ::testing::Values(std::tuple{1, 1, 3}, std::tuple{63, 65, 3},
                                           std::tuple{64, 64, 4}, std::tuple{65, 1, 1},
                                           std::tuple{517, 301, 3}, std::tuple{130, 257, 2}));

TEST(Builder, TiledBigTiffAndSixteenBitGreyInputsAreRead) {
  TempDir dir;
  const int w = 700, h = 333;
  const auto px = noise(std::size_t(w) * h * 3, 11);
  {
    auto out = OIIO::ImageOutput::create((dir / "tiled.tif").string());
    OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::UINT8);
    spec.tile_width = spec.tile_height = 64;  // tiled, with partial edge tiles
    spec.attribute("tiff:bigtiff", 1);
    spec.attribute("compression", "zip");
    ASSERT_TRUE(out->open((dir / "tiled.tif").string(), spec));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, px.data()));
    out->close();
  }
  BuildOptions o = options_for(dir / "tiled.tif", dir / "tiled.pmtiles");
  o.tile_size = 128;
  build(o);
  const Archive a = Archive::open(dir / "tiled.pmtiles");
  Rgba expect{std::uint64_t(w), std::uint64_t(h),
              std::vector<std::uint8_t>(std::size_t(w) * h * 4)};
  for (std::size_t i = 0; i < std::size_t(w) * h; ++i) {
    std::memcpy(&expect.px[i * 4], &px[i * 3], 3);
    expect.px[i * 4 + 3] = 255;
  }
  expect_same(a.level(a.info.geometry.max_zoom()), expect, "tiled BigTIFF finest level");

  std::vector<std::uint16_t> grey(std::size_t(w) * h);
  for (std::size_t i = 0; i < grey.size(); ++i) grey[i] = static_cast<std::uint16_t>(i * 97);
  {
    auto out = OIIO::ImageOutput::create((dir / "grey16.tif").string());
    OIIO::ImageSpec spec(w, h, 1, OIIO::TypeDesc::UINT16);
    ASSERT_TRUE(out->open((dir / "grey16.tif").string(), spec));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT16, grey.data()));
    out->close();
  }
  o = options_for(dir / "grey16.tif", dir / "grey16.pmtiles");
  o.tile_size = 128;
  build(o);
  const Archive b = Archive::open(dir / "grey16.pmtiles");
  const Rgba finest = b.level(b.info.geometry.max_zoom());
  std::size_t bad = 0;
  for (std::size_t i = 0; i < grey.size(); ++i) {
    const auto v = static_cast<std::uint8_t>(std::lround(grey[i] / 257.0));
    const std::uint8_t* t = &finest.px[i * 4];
    bad += !(t[0] == v && t[1] == v && t[2] == v && t[3] == 255);
  }
  EXPECT_EQ(bad, 0u) << "16-bit grey texels not expanded to rounded 8-bit RGB";
}

TEST(Builder, UniformImageStoresOneBlob) {
  TempDir dir;
  const fs::path in = dir / "flat.png";
  std::vector<std::uint8_t> flat(1500 * 700 * 3);
  for (std::size_t i = 0; i < flat.size(); i += 3)
    flat[i] = 10, flat[i + 1] = 120, flat[i + 2] = 200;
  write_image(in, 1500, 700, 3, flat);
  const BuildReport r = build(options_for(in, dir / "flat.pmtiles"));
  EXPECT_GT(r.stats.addressed_tiles, 10u);
  EXPECT_EQ(r.stats.tile_contents, 1u);
  const Archive a = Archive::open(dir / "flat.pmtiles");
  EXPECT_EQ(a.reader->header().tile_contents, 1u);
}

TEST(Builder, GridMosaicEqualsTheWholeImage) {
  TempDir dir;
  const int w = 300, h = 200;
  const auto whole = noise(std::size_t(w) * h * 3, 7);
  write_image(dir / "whole.png", w, h, 3, whole);
  // 2x2 pieces with unequal column widths / row heights: 120+180 by 90+110.
  const int xs[3] = {0, 120, 300}, ys[3] = {0, 90, 200};
  std::vector<fs::path> pieces;
  for (int r = 0; r < 2; ++r)
    for (int c = 0; c < 2; ++c) {
      const int pw = xs[c + 1] - xs[c], ph = ys[r + 1] - ys[r];
      std::vector<std::uint8_t> piece(std::size_t(pw) * ph * 3);
      for (int y = 0; y < ph; ++y)
        std::memcpy(&piece[std::size_t(y) * pw * 3],
                    &whole[(std::size_t(ys[r] + y) * w + xs[c]) * 3], std::size_t(pw) * 3);
      pieces.push_back(dir / ("p" + std::to_string(r) + std::to_string(c) + ".png"));
      write_image(pieces.back(), pw, ph, 3, piece);
    }
  BuildOptions o = options_for(dir / "whole.png", dir / "whole.pmtiles");
  o.tile_size = 64;
  build(o);
  o.inputs = pieces;
  o.grid_columns = o.grid_rows = 2;
  o.output = dir / "grid.pmtiles";
  build(o);
  const Archive a = Archive::open(dir / "whole.pmtiles"), b = Archive::open(dir / "grid.pmtiles");
  for (int z = 0; z <= a.info.geometry.max_zoom(); ++z)
    expect_same(a.level(z), b.level(z), "level " + std::to_string(z));
}

TEST(Builder, ContentHashFollowsTheTilesNotTheBuild) {
  TempDir dir;
  write_image(dir / "a.png", 300, 200, 3, noise(300 * 200 * 3, 1));
  auto b = noise(300 * 200 * 3, 1);
  b[1000] ^= 1;  // one texel differs
  write_image(dir / "b.png", 300, 200, 3, b);
  BuildOptions o = options_for(dir / "a.png", dir / "a1.pmtiles");
  o.threads = 1;
  const std::string a1 = build(o).info.content_hash;
  o.output = dir / "a2.pmtiles";
  o.threads = 3;  // another order of completion
  const std::string a2 = build(o).info.content_hash;
  o.inputs = {dir / "b.png"};
  o.output = dir / "b.pmtiles";
  const std::string h_b = build(o).info.content_hash;
  EXPECT_EQ(a1.size(), 16u);
  EXPECT_EQ(a1, a2);
  EXPECT_NE(a1, h_b);
  EXPECT_EQ(Archive::open(dir / "a1.pmtiles").info.content_hash, a1);
}

TEST(Builder, GridWithMismatchedPiecesIsRejected) {
  TempDir dir;
  write_image(dir / "a.png", 10, 10, 3, noise(300, 1));
  write_image(dir / "b.png", 10, 12, 3, noise(360, 2));
  BuildOptions o;
  o.inputs = {dir / "a.png", dir / "b.png"};
  o.grid_columns = 2;
  o.output = dir / "x.pmtiles";
  auto r = build_pyramid(o);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::invalid_argument);
  EXPECT_NE(r.error().message.find("b.png"), std::string::npos) << r.error().message;
  o.grid_columns = 3;
  EXPECT_FALSE(build_pyramid(o).ok());
  EXPECT_FALSE(fs::exists(dir / "x.pmtiles"));
}

TEST(Builder, SixteenBitAndFloatInputsConvertToEightBitSrgb) {
  TempDir dir;
  {
    auto out = OIIO::ImageOutput::create((dir / "a.png").string());
    OIIO::ImageSpec spec(2, 1, 3, OIIO::TypeDesc::UINT16);
    ASSERT_TRUE(out->open((dir / "a.png").string(), spec));
    const std::uint16_t px[6] = {0, 257 * 100, 65535, 257 * 7, 257 * 200 + 128, 300};
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT16, px));
    out->close();
  }
  {
    auto out = OIIO::ImageOutput::create((dir / "b.exr").string());
    OIIO::ImageSpec spec(2, 1, 3, OIIO::TypeDesc::FLOAT);
    ASSERT_TRUE(out->open((dir / "b.exr").string(), spec));
    const float px[6] = {0.0f, 0.5f, 1.0f, 2.0f, -1.0f, 0.0031308f};
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, px));
    out->close();
  }
  build(options_for(dir / "a.png", dir / "a.pmtiles"));
  build(options_for(dir / "b.exr", dir / "b.pmtiles"));
  const TileImage a = Archive::open(dir / "a.pmtiles").tile({0, 0, 0});
  const TileImage b = Archive::open(dir / "b.pmtiles").tile({0, 0, 0});
  const std::uint32_t B = 4, S = a.width;
  const std::uint8_t* a0 = &a.pixels[(B * S + B) * 4];
  EXPECT_EQ(a0[0], 0);
  EXPECT_EQ(a0[1], 100);
  EXPECT_EQ(a0[2], 255);
  EXPECT_EQ(a0[4], 7);
  EXPECT_EQ(a0[5], 200);  // (257*200+128)/257 rounds to 200
  EXPECT_EQ(a0[6], 1);    // 300/257 rounds to 1
  const std::uint8_t* b0 = &b.pixels[(B * S + B) * 4];
  EXPECT_EQ(b0[0], 0);
  EXPECT_EQ(b0[1], 188);  // linear 0.5 is sRGB 0.7354 → 188
  EXPECT_EQ(b0[2], 255);
  EXPECT_EQ(b0[4], 255);  // > 1 clamps
  EXPECT_EQ(b0[5], 0);    // < 0 clamps
  EXPECT_EQ(b0[6], 10);   // 0.0031308 linear → 0.04045 sRGB → 10.3
}

TEST(Builder, SyntheticTexelsEncodeTheirCoordinatesAtEveryLevel) {
  TempDir dir;
  BuildOptions o;
  o.synthetic = SyntheticSpec{3000, 1700, std::nullopt, 0};
  o.output = dir / "syn.pmtiles";
  build(o);
  const Archive a = Archive::open(dir / "syn.pmtiles");
  const Geometry& g = a.info.geometry;
  for (int z : {0, g.max_zoom() - 1, g.max_zoom()}) {
    const Rgba level = a.level(z);
    std::size_t bad = 0;
    for (std::uint64_t y = 0; y < level.h; ++y)
      for (std::uint64_t x = 0; x < level.w; ++x) {
        std::uint8_t expect[4];
        synthetic_texel(x, y, expect);
        bad += std::memcmp(level.at(x, y), expect, 4) != 0;
      }
    EXPECT_EQ(bad, 0u) << "z=" << z;
    expect_borders_match(a, z, level);
  }
}

TEST(Builder, SparsePlanetSizedSyntheticArchiveStaysSmall) {
  TempDir dir;
  BuildOptions o;
  SyntheticSpec s;
  s.width = s.height = 1ull << 25;
  s.region = TexelRect{(1ull << 24), (1ull << 24), (1ull << 24) + 2048, (1ull << 24) + 1024};
  s.region_level = 5;
  o.synthetic = s;
  o.output = dir / "planet.pmtiles";
  const BuildReport r = build(o);
  EXPECT_LT(fs::file_size(dir / "planet.pmtiles"), 8u << 20);
  const Archive a = Archive::open(dir / "planet.pmtiles");
  EXPECT_EQ(a.info.geometry.max_zoom(), 17);
  EXPECT_TRUE(a.info.sparse);
  // The finest tile over the region's corner exists and is exact; one far away does not.
  const TileId inside{17, 1u << 16, 1u << 16};
  const TileImage t = a.tile(inside);
  std::uint8_t expect[4];
  synthetic_texel(1ull << 24, 1ull << 24, expect);
  EXPECT_EQ(std::memcmp(&t.pixels[(4 * t.width + 4) * 4], expect, 4), 0);
  auto missing = a.reader->get({17, 0, 0});
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, ErrorCode::not_found);
  EXPECT_EQ(r.levels[17].tiles, 8u * 4u);
  EXPECT_EQ(r.levels[3].tiles, 64u);
  // The finest level is far too large to write as one image: a clear error, no allocation.
  ExtractOptions eo;
  eo.output = dir / "level17.png";
  const Status too_big = extract_level(*a.reader, a.info, 17, eo);
  ASSERT_FALSE(too_big.ok());
  EXPECT_EQ(too_big.error().code, ErrorCode::too_large);
  EXPECT_FALSE(fs::exists(eo.output));
}

TEST(Builder, SparseLevelExtractsWithAbsentTilesTransparent) {
  TempDir dir;
  BuildOptions o;
  o.synthetic = SyntheticSpec{1024, 1024, TexelRect{100, 100, 200, 150}, 2};
  o.tile_size = 64;
  o.output = dir / "sparse.pmtiles";
  build(o);
  const Archive a = Archive::open(dir / "sparse.pmtiles");
  ASSERT_EQ(a.info.geometry.max_zoom(), 4);
  ExtractOptions eo;
  eo.output = dir / "level4.png";
  ASSERT_TRUE(extract_level(*a.reader, a.info, 4, eo).ok());
  const Rgba img = read_source(eo.output);  // alpha kept: the file has 4 channels
  ASSERT_EQ(img.w, 1024u);
  std::uint8_t expect[4];
  synthetic_texel(150, 120, expect);
  EXPECT_EQ(std::memcmp(img.at(150, 120), expect, 4), 0);  // inside the region: exact
  synthetic_texel(64, 64, expect);
  EXPECT_EQ(std::memcmp(img.at(64, 64), expect, 4), 0);  // in a tile that touches the region
  const std::uint8_t clear[4] = {0, 0, 0, 0};
  EXPECT_EQ(std::memcmp(img.at(900, 900), clear, 4), 0);  // absent tile: transparent
}

TEST(Builder, FailedBuildLeavesNoFileBehind) {
  TempDir dir;
  auto r = build_pyramid(options_for(dir / "missing.jpg", dir / "out.pmtiles"));
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::not_found);
  EXPECT_NE(r.error().message.find("missing.jpg"), std::string::npos);
  { std::ofstream(dir / "junk.png") << "this is not an image"; }
  r = build_pyramid(options_for(dir / "junk.png", dir / "out.pmtiles"));
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::invalid_argument);
  // Cancelled mid-way.
  std::atomic<bool> cancel{false};
  BuildOptions o;
  o.synthetic = SyntheticSpec{20000, 20000, std::nullopt, 0};
  o.output = dir / "out.pmtiles";
  o.cancel = &cancel;
  o.on_progress = [&](const BuildProgress& p) {
    if (p.tiles_done > 20) cancel = true;
  };
  r = build_pyramid(o);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::cancelled);
  std::vector<std::string> left;
  for (const auto& e : fs::directory_iterator(dir.path()))
    if (e.path().filename() != "junk.png") left.push_back(e.path().filename().string());
  EXPECT_TRUE(left.empty()) << left.front();
}

TEST(Downsample, EncodeSrgb8RoundsExactlyInSrgbSpace) {
  for (int i = 0; i <= 100000; ++i) {
    const double lin = i / 100000.0;
    const auto expect = static_cast<int>(std::lround(linear_to_srgb(lin) * 255.0));
    EXPECT_NEAR(encode_srgb8(static_cast<float>(lin)), expect, 1) << lin;
  }
  for (int c = 0; c < 256; ++c) EXPECT_EQ(encode_srgb8(decode_srgb8(c)), c);
  EXPECT_EQ(encode_srgb8(std::nanf("")), 0);
  EXPECT_EQ(encode_srgb8(-1.0f), 0);
  EXPECT_EQ(encode_srgb8(INFINITY), 255);
}

}  // namespace
}  // namespace vts
