// The CPU reference renderer against real archives of the synthetic source, whose texels encode
// their own level coordinates (vts/builder/synthetic.hpp), so every expected pixel is known
// exactly; plus the image metrics and the PNG round trip.
#include "vts/renderer/reference.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <optional>
#include <string>

#include "vts/builder/builder.hpp"
#include "vts/builder/synthetic.hpp"
#include "vts/imaging/web_image.hpp"

namespace fs = std::filesystem;

namespace vts::renderer {
namespace {

Rgba8 synthetic(std::uint64_t x, std::uint64_t y) {
  Rgba8 t;
  synthetic_texel(x, y, t.data());
  return t;
}

Rgba8 pixel(const Image& img, int x, int y) {
  const std::uint8_t* p = img.at(x, y);
  return {p[0], p[1], p[2], p[3]};
}

// The level texel a synthetic pixel shows.
std::pair<int, int> decode(const Rgba8& t) {
  return {t[0] | ((t[2] & 0x0F) << 8), t[1] | ((t[2] >> 4) << 8)};
}

bool is_background(const Rgba8& t) {
  return t[0] == kBackground[0] && t[1] == kBackground[1] && t[2] == kBackground[2] &&
         t[3] == kBackground[3];
}

PlaneCamera straight_down(double cu, double cv, double tpp, int w, int h, double heading = 0) {
  PlaneView v;
  v.center_u = cu;
  v.center_v = cv;
  v.texels_per_pixel = tpp;
  v.heading = heading;
  return PlaneCamera::from_view(v, w, h);
}

class ReferenceArchive : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() /
                        ("vts-reference-test-" + std::to_string(::getpid())));
    fs::create_directories(*dir_);
    build("wide", 1000, 600, 64, 4, std::nullopt);  // max level 4: 1000x600 ... 63x38
    build("odd", 333, 777, 32, 2, std::nullopt);    // max level 5: 333x777 ... 11x25
    // Levels >= 3 exist only over the finest texels [0, 64)^2: finest tile (0,0), level-3 (0,0).
    build("sparse", 1000, 600, 64, 4, TexelRect{0, 0, 64, 64});
  }
  static void TearDownTestSuite() {
    std::error_code ec;
    fs::remove_all(*dir_, ec);
    delete dir_;
  }
  static void build(const std::string& name, std::uint64_t w, std::uint64_t h, std::uint32_t tile,
                    std::uint32_t border, std::optional<TexelRect> region) {
    BuildOptions o;
    o.synthetic = SyntheticSpec{w, h, region, 3};
    o.output = path(name);
    o.tile_size = tile;
    o.border = border;
    o.threads = 1;
    auto r = build_synthetic_pyramid(o);
    ASSERT_TRUE(r.ok()) << r.error().to_string();
  }
  static fs::path path(const std::string& name) { return *dir_ / (name + ".pmtiles"); }
  static std::unique_ptr<PyramidSampler> open(const std::string& name) {
    auto s = PyramidSampler::open(path(name));
    EXPECT_TRUE(s.ok()) << s.error().to_string();
    return s.ok() ? std::move(*s) : nullptr;
  }

  static inline fs::path* dir_ = nullptr;
};

using ReferenceSampler = ReferenceArchive;
using ReferenceRender = ReferenceArchive;

TEST_F(ReferenceSampler, ReadsTheGeometryAndClampsTexelsToTheLevel) {
  auto s = open("odd");
  ASSERT_TRUE(s);
  EXPECT_EQ(s->geometry().width(), 333u);
  EXPECT_EQ(s->geometry().height(), 777u);
  EXPECT_EQ(s->geometry().tile_size(), 32u);
  EXPECT_EQ(s->max_level(), 5);
  for (int z = 0; z <= 5; ++z) {
    const auto lw = s->geometry().level_width(z), lh = s->geometry().level_height(z);
    EXPECT_EQ(*s->texel(z, 0, 0), synthetic(0, 0)) << z;
    EXPECT_EQ(*s->texel(z, lw - 1, lh - 1), synthetic(lw - 1, lh - 1)) << z;
    EXPECT_EQ(*s->texel(z, -7, 100000), synthetic(0, lh - 1)) << z;
    EXPECT_EQ(*s->texel(z, lw + 3, -1), synthetic(lw - 1, 0)) << z;
  }
  // Texels on both sides of tile boundaries (tile 32, border 2).
  for (std::int64_t x : {31, 32, 33, 63, 64, 255, 256, 332})
    for (std::int64_t y : {0, 31, 32, 300, 776}) EXPECT_EQ(*s->texel(5, x, y), synthetic(x, y));
  EXPECT_EQ(s->stats().fallback_texels, 0u);
  EXPECT_FALSE(s->texel(6, 0, 0).ok());
  EXPECT_FALSE(s->texel(-1, 0, 0).ok());
  EXPECT_FALSE(s->bilinear(0, std::nan(""), 0).ok());
}

TEST_F(ReferenceSampler, AbsentTilesFallBackOnTheNearestAncestorAndAreCounted) {
  auto s = open("sparse");
  ASSERT_TRUE(s);
  ASSERT_EQ(s->max_level(), 4);
  EXPECT_EQ(*s->texel(4, 10, 20), synthetic(10, 20));  // present
  EXPECT_EQ(s->stats().fallback_texels, 0u);
  EXPECT_EQ(*s->texel(4, 100, 100), synthetic(50, 50));  // level-3 tile (0,0)
  EXPECT_EQ(s->stats().fallback_texels, 1u);
  EXPECT_EQ(*s->texel(4, 200, 120), synthetic(50, 30));  // level 3 (1,0) absent too: level 2
  EXPECT_EQ(s->stats().fallback_texels, 2u);
  EXPECT_EQ(*s->texel(2, 200, 120), synthetic(200, 120));  // coarse levels are complete
  EXPECT_EQ(s->stats().fallback_texels, 2u);
}

TEST_F(ReferenceSampler, BilinearAtTexelCentresIsTheTexelAndBetweenThemTheLinearMean) {
  auto s = open("wide");
  ASSERT_TRUE(s);
  auto centre = s->bilinear(4, 300.5, 200.5);
  ASSERT_TRUE(centre.ok());
  EXPECT_DOUBLE_EQ((*centre)[0], srgb_to_linear(300 % 256 / 255.0));
  EXPECT_DOUBLE_EQ((*centre)[1], srgb_to_linear(200 / 255.0));
  EXPECT_DOUBLE_EQ((*centre)[3], 1.0);
  // Halfway between x = 299 and 300 (R = 43, 44): mean of the decoded values, not of the codes.
  auto mid = s->bilinear(4, 300.0, 200.5);
  ASSERT_TRUE(mid.ok());
  EXPECT_DOUBLE_EQ((*mid)[0], 0.5 * (srgb_to_linear(43 / 255.0) + srgb_to_linear(44 / 255.0)));
  // Clamp to edge: beyond the corner every tap is the corner texel.
  auto corner = s->bilinear(4, -50, 1e9);
  ASSERT_TRUE(corner.ok());
  EXPECT_DOUBLE_EQ((*corner)[1], srgb_to_linear((599 % 256) / 255.0));
  EXPECT_EQ(srgb_to_linear(0.04045), 0.04045 / 12.92);
  EXPECT_EQ(encode_srgb8_exact(srgb_to_linear(200 / 255.0)), 200);
}

TEST_F(ReferenceSampler, OpenErrorsNameTheFile) {
  const fs::path missing = *dir_ / "missing.pmtiles";
  auto r = PyramidSampler::open(missing);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find(missing.string()), std::string::npos) << r.error().message;
  const fs::path junk = *dir_ / "junk.pmtiles";
  std::ofstream(junk) << std::string(300, 'x');
  r = PyramidSampler::open(junk);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find(junk.string()), std::string::npos) << r.error().message;
}

// Pixel centres on texel centres at one texel per pixel: the image is the finest level itself.
TEST_F(ReferenceRender, OneTexelPerPixelIsTheFinestLevel) {
  struct Case {
    const char* archive;
    double cu, cv;
    int w, h;
    int x0, y0;  // finest texel of pixel (0, 0)
  };
  for (const Case& c :
       {Case{"wide", 500, 300, 1000, 600, 0, 0}, Case{"wide", 300, 200, 100, 80, 250, 160},
        Case{"odd", 166.5, 388.5, 333, 777, 0, 0}, Case{"odd", 100.5, 500, 61, 50, 70, 475}}) {
    auto s = open(c.archive);
    ASSERT_TRUE(s);
    auto img = render_reference(*s, straight_down(c.cu, c.cv, 1, c.w, c.h), 0);
    ASSERT_TRUE(img.ok()) << img.error().to_string();
    ASSERT_EQ(img->width, c.w);
    ASSERT_EQ(img->height, c.h);
    int wrong = 0;
    for (int y = 0; y < c.h; ++y)
      for (int x = 0; x < c.w; ++x)
        if (pixel(*img, x, y) != synthetic(c.x0 + x, c.y0 + y) && ++wrong <= 3)
          ADD_FAILURE() << c.archive << " pixel " << x << "," << y;
    EXPECT_EQ(wrong, 0) << c.archive << " " << c.w << "x" << c.h;
  }
}

TEST_F(ReferenceRender, HeadingZeroIsUnmirroredAndHeadingHalfPiPutsPlusUUp) {
  auto s = open("wide");
  ASSERT_TRUE(s);
  auto north = render_reference(*s, straight_down(500, 300, 1, 64, 48), 0);
  ASSERT_TRUE(north.ok());
  const auto [u0, v0] = decode(pixel(*north, 0, 0));
  const auto [u1, v1] = decode(pixel(*north, 63, 47));
  EXPECT_LT(u0, u1);
  EXPECT_LT(v0, v1);
  EXPECT_EQ(u0, 468);
  EXPECT_EQ(v0, 276);

  // Screen-up is +u, so screen-right is +v: pixel (x, y) shows u = 500 + 32 - (y + 0.5),
  // v = 300 + (x + 0.5) - 32.
  auto east = render_reference(*s, straight_down(500, 300, 1, 64, 64, std::numbers::pi / 2), 0);
  ASSERT_TRUE(east.ok());
  const auto [eu0, ev0] = decode(pixel(*east, 0, 0));
  const auto [eu1, ev1] = decode(pixel(*east, 63, 63));
  EXPECT_GT(eu0, eu1);
  EXPECT_LT(ev0, ev1);
  int wrong = 0;
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x)
      if (pixel(*east, x, y) != synthetic(531 - y, 268 + x)) ++wrong;
  EXPECT_EQ(wrong, 0);
}

// Independent bilinear of the synthetic level (clamped), for the expected images below.
LinearRgba expected_bilinear(const Geometry& g, int z, double tx, double ty) {
  const double sx = tx - 0.5, sy = ty - 0.5;
  const double x0 = std::floor(sx), y0 = std::floor(sy);
  const double fx = sx - x0, fy = sy - y0;
  LinearRgba out{0, 0, 0, 0};
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 2; ++i) {
      const auto x =
          static_cast<std::uint64_t>(std::clamp<double>(x0 + i, 0, double(g.level_width(z) - 1)));
      const auto y =
          static_cast<std::uint64_t>(std::clamp<double>(y0 + j, 0, double(g.level_height(z) - 1)));
      const Rgba8 t = synthetic(x, y);
      const double w = (i ? fx : 1 - fx) * (j ? fy : 1 - fy);
      for (int c = 0; c < 3; ++c) {
        const double e = t[c] / 255.0;
        out[c] += w * (e <= 0.04045 ? e / 12.92 : std::pow((e + 0.055) / 1.055, 2.4));
      }
      out[3] += w * t[3] / 255.0;
    }
  return out;
}

Rgba8 encode(const LinearRgba& l) {
  Rgba8 out{0, 0, 0, 255};
  for (int c = 0; c < 3; ++c) {
    const double v = std::clamp(l[c], 0.0, 1.0);
    const double e = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055;
    out[c] = static_cast<std::uint8_t>(std::lround(e * 255));
  }
  return out;
}

// Four texels per pixel straight down: c = max_level - 2 exactly, so the image is level
// max_level - 2 sampled bilinearly, with no contribution from level max_level - 3. The centre is
// chosen so that the samples fall a quarter texel off the texel centres (weights 3/4 and 1/4).
TEST_F(ReferenceRender, FourTexelsPerPixelIsBilinearOfLevelMaxMinusTwo) {
  auto s = open("wide");
  ASSERT_TRUE(s);
  const int w = 40, h = 30;
  const PlaneCamera cam = straight_down(401, 243, 4, w, h);
  auto img = render_reference(*s, cam, 0);
  ASSERT_TRUE(img.ok());
  int wrong = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const auto [u, v] = *cam.hit(x + 0.5, y + 0.5);
      const Rgba8 want = encode(expected_bilinear(s->geometry(), 2, u / 4, v / 4));
      EXPECT_NEAR(u / 4 - 0.5 - std::floor(u / 4 - 0.5), 0.25, 1e-9);
      const Rgba8 got = pixel(*img, x, y);
      if (got != want && ++wrong <= 3) ADD_FAILURE() << "pixel " << x << "," << y;
      const auto sampled = s->bilinear(2, u / 4, v / 4);
      ASSERT_TRUE(sampled.ok());
      EXPECT_EQ(got, encode(*sampled));
    }
  EXPECT_EQ(wrong, 0);
  // A bias of one level makes the same view level max_level - 3, which differs.
  auto biased = render_reference(*s, cam, 1.0);
  ASSERT_TRUE(biased.ok());
  auto d = compare_images(*img, *biased, 8);
  ASSERT_TRUE(d.ok());
  EXPECT_GT(d->pixels_over, 0u);
}

// 2 sqrt(2) texels per pixel: c = max_level - 1.5, an equal blend of levels max - 1 and max - 2.
TEST_F(ReferenceRender, HalfwayBetweenLevelsBlendsThemEquallyInLinearLight) {
  auto s = open("odd");
  ASSERT_TRUE(s);
  const int w = 32, h = 32, mz = s->max_level();
  const PlaneCamera cam = straight_down(150.3, 401.7, 2 * std::sqrt(2.0), w, h);
  auto img = render_reference(*s, cam, 0);
  ASSERT_TRUE(img.ok());
  int max_diff = 0, exact = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const auto [u, v] = *cam.hit(x + 0.5, y + 0.5);
      const LinearRgba a = expected_bilinear(s->geometry(), mz - 1, u / 2, v / 2);
      const LinearRgba b = expected_bilinear(s->geometry(), mz - 2, u / 4, v / 4);
      LinearRgba m;
      for (int c = 0; c < 4; ++c) m[c] = 0.5 * (a[c] + b[c]);
      const Rgba8 want = encode(m), got = pixel(*img, x, y);
      int diff = 0;
      for (int c = 0; c < 3; ++c) diff = std::max(diff, std::abs(int(want[c]) - int(got[c])));
      max_diff = std::max(max_diff, diff);
      exact += diff == 0;
    }
  EXPECT_LE(max_diff, 1);  // the level computed from quad differences is 1.5 to ~1e-15
  EXPECT_GE(exact, w * h * 99 / 100);
}

// The level is clamped to [0, max_level] whatever the bias; a NaN bias means the finest level.
TEST_F(ReferenceRender, BiasIsClampedToTheLevelRange) {
  auto s = open("wide");
  ASSERT_TRUE(s);
  const Geometry& g = s->geometry();
  const PlaneCamera one = straight_down(500.3, 300.6, 1, 32, 32);
  const PlaneCamera four = straight_down(500.3, 300.6, 4, 32, 32);
  auto coarsest = render_reference(*s, one, 100);
  auto infinite = render_reference(*s, one, std::numeric_limits<double>::infinity());
  auto finest = render_reference(*s, four, -100);
  auto nan = render_reference(*s, one, std::nan(""));
  auto zero = render_reference(*s, one, 0);
  ASSERT_TRUE(coarsest.ok() && infinite.ok() && finest.ok() && nan.ok() && zero.ok());
  EXPECT_EQ(coarsest->rgba, infinite->rgba);
  EXPECT_EQ(nan->rgba, zero->rgba);
  int wrong = 0;
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 32; ++x) {
      const auto [u1, v1] = *one.hit(x + 0.5, y + 0.5);
      wrong += pixel(*coarsest, x, y) != encode(expected_bilinear(g, 0, u1 / 16, v1 / 16));
      const auto [u4, v4] = *four.hit(x + 0.5, y + 0.5);
      wrong += pixel(*finest, x, y) != encode(expected_bilinear(g, 4, u4, v4));
    }
  EXPECT_EQ(wrong, 0);
}

// Where the finest tiles are absent the image shows the nearest ancestor's texels.
TEST_F(ReferenceRender, SparseArchivesShowTheAncestorWhereTilesAreAbsent) {
  auto s = open("sparse");
  ASSERT_TRUE(s);
  auto img = render_reference(*s, straight_down(64, 32, 1, 64, 64), 0);  // texels 32..95, 0..63
  ASSERT_TRUE(img.ok()) << img.error().to_string();
  int wrong = 0;
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      const int u = 32 + x, v = y;
      wrong += pixel(*img, x, y) != (u < 64 ? synthetic(u, v) : synthetic(u / 2, v / 2));
    }
  EXPECT_EQ(wrong, 0);
  EXPECT_GT(s->stats().fallback_texels, 0u);
}

TEST_F(ReferenceRender, OutsideTheImageAndAboveTheHorizonIsBackground) {
  auto s = open("wide");
  ASSERT_TRUE(s);
  // Centred on the image's top-left corner: only the bottom-right quadrant shows the image.
  auto corner = render_reference(*s, straight_down(0, 0, 1, 32, 32), 0);
  ASSERT_TRUE(corner.ok());
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 32; ++x) {
      if (x < 16 || y < 16)
        EXPECT_TRUE(is_background(pixel(*corner, x, y))) << x << "," << y;
      else
        EXPECT_EQ(pixel(*corner, x, y), synthetic(x - 16, y - 16)) << x << "," << y;
    }

  // Tilted 1.4 rad with a 0.8 rad field of view: the top of the screen looks above the horizon.
  PlaneView v;
  v.center_u = 500;
  v.center_v = 300;
  v.tilt = 1.4;
  const PlaneCamera cam = PlaneCamera::from_view(v, 64, 64);
  auto tilted = render_reference(*s, cam, 0);
  ASSERT_TRUE(tilted.ok()) << tilted.error().to_string();
  int horizon_row = -1;
  for (int y = 0; y < 64 && horizon_row < 0; ++y)
    if (cam.hit(32.5, y + 0.5)) horizon_row = y;
  ASSERT_GT(horizon_row, 0);
  for (int x = 0; x < 64; ++x) {
    EXPECT_TRUE(is_background(pixel(*tilted, x, 0))) << x;
    EXPECT_FALSE(is_background(pixel(*tilted, x, 63))) << x;
  }
  // Far away, past the top edge of the image, is background too; the centre shows texel 500,300.
  EXPECT_TRUE(is_background(pixel(*tilted, 32, horizon_row)));
  EXPECT_EQ(pixel(*tilted, 32, 32)[3], 255);
  EXPECT_FALSE(is_background(pixel(*tilted, 32, 32)));
}

TEST(ReferenceImageDiff, IdenticalImagesHaveInfinitePsnrAndOnePixelIsCounted) {
  Image a = Image::blank(7, 5);
  for (std::size_t i = 0; i < a.rgba.size(); ++i) a.rgba[i] = static_cast<std::uint8_t>(i * 37);
  auto same = compare_images(a, a);
  ASSERT_TRUE(same.ok());
  EXPECT_TRUE(std::isinf(same->psnr_db) && same->psnr_db > 0);
  EXPECT_EQ(same->max_abs, 0);
  EXPECT_EQ(same->mean_abs, 0.0);
  EXPECT_EQ(same->pixels_over, 0u);
  EXPECT_EQ(same->pixels, 35u);

  Image b = a;
  b.at(3, 2)[1] =
      static_cast<std::uint8_t>(a.at(3, 2)[1] >= 128 ? a.at(3, 2)[1] - 20 : a.at(3, 2)[1] + 20);
  b.at(5, 4)[3] ^= 0xFF;  // alpha is not compared
  auto d = compare_images(a, b, 8);
  ASSERT_TRUE(d.ok());
  EXPECT_EQ(d->max_abs, 20);
  EXPECT_EQ(d->pixels_over, 1u);
  EXPECT_DOUBLE_EQ(d->mean_abs, 20.0 / (35 * 3));
  EXPECT_NEAR(d->psnr_db, 10 * std::log10(255.0 * 255.0 * 35 * 3 / 400.0), 1e-9);
  EXPECT_EQ(compare_images(a, b, 20)->pixels_over, 0u);  // exceeds, not reaches

  EXPECT_FALSE(compare_images(a, Image::blank(5, 7)).ok());
  Image broken = a;
  broken.rgba.pop_back();
  EXPECT_FALSE(compare_images(a, broken).ok());
}

TEST(ReferenceAnisotropy, TapsFollowTheFootprintRatioUpToTheLimit) {
  EXPECT_EQ(anisotropic_taps(4, 1, 8), 4);
  EXPECT_EQ(anisotropic_taps(1, 4.5, 8), 5);  // either axis may be the major one
  EXPECT_EQ(anisotropic_taps(100, 1, 8), 8);
  EXPECT_EQ(anisotropic_taps(2, 2, 8), 1);
  EXPECT_EQ(anisotropic_taps(3, 0, 8), 8);  // a degenerate footprint: the limit
  EXPECT_EQ(anisotropic_taps(4, 1, 1), 1);  // isotropic
  EXPECT_EQ(anisotropic_taps(0, 0, 8), 1);
  EXPECT_EQ(anisotropic_taps(std::numeric_limits<double>::infinity(), 1, 8), 1);
  EXPECT_EQ(anisotropic_taps(std::nan(""), 1, 8), 1);
}

TEST_F(ReferenceRender, AnisotropyOnAStraightDownViewChangesNothing) {
  auto s = open("wide");
  ASSERT_TRUE(s);
  const auto cam = straight_down(500.3, 300.6, 2.7, 64, 48);
  auto iso = render_reference(*s, cam, 0, 1);
  auto aniso = render_reference(*s, cam, 0, 16);
  ASSERT_TRUE(iso.ok() && aniso.ok());
  EXPECT_EQ(iso->rgba, aniso->rgba);  // a round footprint takes one tap
}

TEST_F(ReferenceRender, SupersamplingByOneIsTheReferenceAndBadFactorsAreRefused) {
  auto s = open("wide");
  ASSERT_TRUE(s);
  const PlaneView view{.center_u = 500, .center_v = 300, .texels_per_pixel = 1.5, .tilt = 0.8};
  auto ref = render_reference(*s, PlaneScene(view), 48, 32);
  auto one = render_supersampled(*s, PlaneScene(view), 48, 32, 1);
  ASSERT_TRUE(ref.ok() && one.ok());
  EXPECT_EQ(ref->rgba, one->rgba);
  for (int bad : {0, 17}) {
    auto r = render_supersampled(*s, PlaneScene(view), 48, 32, bad);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("supersampling factor"), std::string::npos);
  }
  EXPECT_FALSE(render_supersampled(*s, PlaneScene(view), 4096, 32, 8).ok());
}

}  // namespace
}  // namespace vts::renderer
