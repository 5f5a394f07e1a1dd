// The globe scene end to end under Xvfb + llvmpipe: the Earth image and a planet-sized sparse
// synthetic archive wrapped on a sphere of the Earth's radius, drawn by the GPU virtual texture
// and judged against the CPU reference renderer (GlobeScene::hit in double).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <numbers>
#include <string>

#include "gl_fixture.hpp"
#include "vts/builder/builder.hpp"
#include "vts/client/source.hpp"
#include "vts/client/tile_client.hpp"
#include "vts/imaging/web_image.hpp"
#include "vts/renderer/geo_view.hpp"
#include "vts/renderer/gl_context.hpp"
#include "vts/renderer/globe.hpp"
#include "vts/renderer/reference.hpp"
#include "vts/renderer/virtual_texture.hpp"

namespace fs = std::filesystem;
using namespace vts::renderer;

namespace {

constexpr double kDeg = 180 / std::numbers::pi;

// A 2^25 x 2^24 sparse synthetic image (1.19 m per finest texel at the equator), complete only
// over a 2048 x 2048 region just south of (0, 0).
constexpr std::uint64_t kBigW = 1ull << 25, kBigH = 1ull << 24;
const vts::TexelRect kRegion{1u << 24, 1u << 23, (1u << 24) + 2048, (1u << 23) + 2048};

class GlobeTest : public vts::test::VirtualTextureFixture {
 protected:
  static fs::path earth() { return archive("earth64", 64, 4); }
  static fs::path big() {
    return archive("g25", 256, 4, vts::SyntheticSpec{kBigW, kBigH, kRegion, 6});
  }

  static GlobeScene scene_for(const VirtualTexture& vt, const GlobeView& view) {
    return GlobeScene(view, vt.geometry().width(), vt.geometry().height());
  }

  // Renders until complete; the GPU image of the last frame.
  static Image converge(VirtualTexture& vt, const Scene& scene, int w, int h) {
    FrameStats st;
    bool complete = false;
    for (int i = 0; i < 400 && !complete; ++i) {
      st = vt.render(scene, w, h);
      complete = st.complete;
      if (st.pending > 0) ::usleep(2000);
    }
    EXPECT_TRUE(complete) << "wanted " << st.wanted << ", missing " << st.wanted_missing
                          << ", pending " << st.pending;
    EXPECT_FALSE(vt.last_error()) << vt.last_error()->to_string();
    return vt.read_image();
  }

  static Image reference(const fs::path& path, const Scene& scene, int w, int h,
                         int anisotropy = 1) {
    auto sampler = PyramidSampler::open(path);
    EXPECT_TRUE(sampler.ok()) << sampler.error().to_string();
    if (!sampler.ok()) return Image::blank(w, h);
    auto ref = render_reference(**sampler, scene, w, h, 0, anisotropy);
    EXPECT_TRUE(ref.ok()) << ref.error().to_string();
    return ref.ok() ? *ref : Image::blank(w, h);
  }

  static ImageDiff compare(const Image& a, const Image& b, const std::string& name) {
    if (const char* keep = std::getenv("VTS_TEST_KEEP_IMAGES")) {
      (void)vts::imaging::write_png(fs::path(keep) / (name + "-a.png"), a.width, a.height, a.rgba);
      (void)vts::imaging::write_png(fs::path(keep) / (name + "-b.png"), b.width, b.height, b.rgba);
    }
    auto d = compare_images(a, b);
    EXPECT_TRUE(d.ok()) << d.error().to_string();
    if (!d.ok()) return {};
    std::printf("  %s: PSNR %.2f dB, max |error| %d, mean |error| %.3f, over 8: %llu px\n",
                name.c_str(), d->psnr_db, d->max_abs, d->mean_abs,
                static_cast<unsigned long long>(d->pixels_over));
    return *d;
  }

  static int lit(const Image& img) {  // pixels that are not the black background
    int n = 0;
    for (int y = 0; y < img.height; ++y) {
      for (int x = 0; x < img.width; ++x) {
        const auto* p = img.at(x, y);
        if (p[0] | p[1] | p[2]) ++n;
      }
    }
    return n;
  }
};

TEST_F(GlobeTest, WholeEarthMatchesTheReference) {
  const fs::path path = earth();
  auto vt = open(path);
  ASSERT_TRUE(vt);
  const GlobeScene scene =
      scene_for(*vt, GlobeView{.lon_deg = 15, .lat_deg = 25, .altitude_m = 2e7, .heading = 0.3});
  const Image got = converge(*vt, scene, 256, 256);
  const ImageDiff d = compare(got, reference(path, scene, 256, 256), "globe-whole");
  EXPECT_GE(d.psnr_db, 35.0);
  EXPECT_EQ(magenta(got), 0);
  // The disc and the space around it are both on screen.
  EXPECT_GT(lit(got), 256 * 256 / 4);
  EXPECT_LT(lit(got), 256 * 256 * 9 / 10);
}

TEST_F(GlobeTest, DateLineMatchesTheReference) {
  const fs::path path = earth();
  auto vt = open(path);
  ASSERT_TRUE(vt);
  // The anchor on either side of the date line; the view straddles it.
  for (double lon : {179.6, 180.0, -179.6}) {
    const GlobeScene scene = scene_for(
        *vt,
        GlobeView{.lon_deg = lon, .lat_deg = 10, .altitude_m = 1e6, .heading = 0.4, .tilt = 0.3});
    const auto left = scene.hit(0.5, 96, 256, 192), right = scene.hit(255.5, 96, 256, 192);
    ASSERT_TRUE(left && right);
    EXPECT_GT(left->first, 1024.0) << lon;   // west of the date line: u near W
    EXPECT_LT(right->first, 1024.0) << lon;  // east of it: u near 0
    const Image got = converge(*vt, scene, 256, 192);
    const ImageDiff d = compare(got, reference(path, scene, 256, 192),
                                "globe-dateline" + std::to_string(int(lon * 10)));
    EXPECT_GE(d.psnr_db, 30.0) << lon;
    EXPECT_EQ(magenta(got), 0) << lon;
    EXPECT_EQ(lit(got), 256 * 192) << lon;  // every pixel sees the ground: no hole at the seam
  }
}

TEST_F(GlobeTest, AnisotropicTapsAcrossTheDateLineMatchTheReference) {
  const fs::path path = earth();
  VirtualTextureOptions o;
  o.anisotropy = 8;
  auto vt = open(path, o);
  ASSERT_TRUE(vt);
  // Low and tilted towards the horizon, straddling the date line: taps wrap in u.
  const GlobeScene scene = scene_for(
      *vt,
      GlobeView{.lon_deg = 179.9, .lat_deg = 66, .altitude_m = 3e5, .heading = 1.4, .tilt = 1.2});
  const Image got = converge(*vt, scene, 256, 192);
  const ImageDiff d = compare(got, reference(path, scene, 256, 192, 8), "globe-aniso8");
  EXPECT_GE(d.psnr_db, 35.0);
  EXPECT_EQ(magenta(got), 0);
  // The taps are really there: the image is measurably unlike the trilinear one.
  const ImageDiff iso = compare(got, reference(path, scene, 256, 192, 1), "globe-aniso8-vs-1");
  EXPECT_LT(iso.psnr_db, d.psnr_db - 10.0);
}

TEST_F(GlobeTest, PoleMatchesTheReference) {
  const fs::path path = earth();
  auto vt = open(path);
  ASSERT_TRUE(vt);
  for (double lat : {89.9, -89.9}) {
    const GlobeScene scene =
        scene_for(*vt, GlobeView{.lon_deg = 40, .lat_deg = lat, .altitude_m = 2e6, .tilt = 0});
    const Image got = converge(*vt, scene, 256, 192);
    const ImageDiff d = compare(got, reference(path, scene, 256, 192),
                                lat > 0 ? "globe-north-pole" : "globe-south-pole");
    EXPECT_GE(d.psnr_db, 30.0) << lat;
    EXPECT_EQ(magenta(got), 0) << lat;
    EXPECT_EQ(lit(got), 256 * 192) << lat;  // no NaN hole (NaN is drawn as background)
  }
}

// The view over the synthetic region: the nadir at finest texel (u, v), off the texel grid.
GlobeView big_view(double u, double v, double altitude, double tilt, double heading) {
  return GlobeView{.lon_deg = (u / double(kBigW) - 0.5) * 360,
                   .lat_deg = (0.5 - v / double(kBigH)) * 180,
                   .altitude_m = altitude,
                   .heading = heading,
                   .tilt = tilt};
}

TEST_F(GlobeTest, OneMetreAboveTheSurfaceMatchesTheReferenceWithoutJitter) {
  const fs::path path = big();
  auto vt = open(path);
  ASSERT_TRUE(vt);
  ASSERT_EQ(vt->geometry().width(), kBigW);
  const double u0 = double(kRegion.x0) + 1024.37, v0 = double(kRegion.y0) + 1024.61;
  const GlobeView view = big_view(u0, v0, 1.0, 1.0, 0.4);
  const GlobeScene scene = scene_for(*vt, view);
  const Image got = converge(*vt, scene, 256, 192);
  const Image ref = reference(path, scene, 256, 192);
  const ImageDiff d = compare(got, ref, "globe-1m");
  EXPECT_GE(d.psnr_db, 35.0);
  EXPECT_LE(d.max_abs, 8);
  EXPECT_EQ(magenta(got), 0);

  // The camera 1 cm further north: the image moves by a hundredth of a texel. The GPU images
  // differ by about as much as the reference images do; a float eye or a float (u, v) over the
  // whole texture would move them by metres.
  GlobeView moved = view;
  moved.lat_deg += 0.01 / view.radius_m * kDeg;
  const GlobeScene scene2 = scene_for(*vt, moved);
  const Image got2 = converge(*vt, scene2, 256, 192);
  const Image ref2 = reference(path, scene2, 256, 192);
  const ImageDiff gpu_step = compare(got, got2, "globe-1m-gpu-step");
  const ImageDiff ref_step = compare(ref, ref2, "globe-1m-ref-step");
  EXPECT_LE(gpu_step.max_abs, ref_step.max_abs + 2);
  EXPECT_NEAR(gpu_step.mean_abs, ref_step.mean_abs, 0.05);
  EXPECT_GE(gpu_step.psnr_db, 45.0);
  const ImageDiff d2 = compare(got2, ref2, "globe-1m-moved");
  EXPECT_GE(d2.psnr_db, 35.0);
  // Precision: each GPU image is much closer to its own reference than a 1 cm (1/120 texel)
  // camera move changes the picture.
  EXPECT_LT(d.mean_abs, ref_step.mean_abs / 2);
  EXPECT_LT(d2.mean_abs, ref_step.mean_abs / 2);
}

TEST_F(GlobeTest, ThreeHundredMetresUpMatchesTheReference) {
  // About one finest texel per pixel, a few hundred texels from the anchor: the local offset
  // becomes lon/lat exactly (no first-order map).
  const fs::path path = big();
  auto vt = open(path);
  ASSERT_TRUE(vt);
  const double u0 = double(kRegion.x0) + 900.5, v0 = double(kRegion.y0) + 1300.25;
  const GlobeScene scene = scene_for(*vt, big_view(u0, v0, 300, 0.5, -0.7));
  const Image got = converge(*vt, scene, 256, 192);
  const ImageDiff d = compare(got, reference(path, scene, 256, 192), "globe-300m");
  EXPECT_GE(d.psnr_db, 35.0);
  EXPECT_EQ(magenta(got), 0);
}

TEST_F(GlobeTest, TiltedTwoHundredMetresUpSeesAKilometreAccurately) {
  // Hits up to ~1.2 km from the nadir and ~850 m from the anchor: a first-order local map would
  // be off by d^2 / R ~ 0.1 m ~ 0.1 texel there; the exact relative lon/lat is not.
  const fs::path path = big();
  auto vt = open(path);
  ASSERT_TRUE(vt);
  const double u0 = double(kRegion.x0) + 1024.5, v0 = double(kRegion.y0) + 1900.75;
  const GlobeScene scene = scene_for(*vt, big_view(u0, v0, 200, 1.0, 0.0));
  const auto top = scene.hit(128, 0.5, 256, 192);
  ASSERT_TRUE(top);
  EXPECT_GT(v0 - top->second, 800.0);               // looks ~1 km north
  EXPECT_GT(top->second, double(kRegion.y0) + 50);  // and stays over the region
  const Image got = converge(*vt, scene, 256, 192);
  const ImageDiff d = compare(got, reference(path, scene, 256, 192), "globe-200m-tilted");
  EXPECT_GE(d.psnr_db, 35.0);
  EXPECT_EQ(magenta(got), 0);
}

}  // namespace

// A sparse WorldCRS84Quad synthetic planet (our levels 0-6, 16384 x 8192: the scheme's grid)
// holding only a European footprint, viewed on the globe with vts view --center's camera
// (camera_at): the GPU matches the reference, every pixel sees the footprint's data, and the
// texel under the screen centre is the one tiling.hpp puts at the place.
TEST_F(GlobeTest, ASparseWorldCrs84QuadArchiveSitsWhereItsGeoreferenceSays) {
  const fs::path path = *dir_ / "crs84.pmtiles";
  if (!fs::exists(path)) {
    vts::BuildOptions o;
    o.synthetic = vts::SyntheticSpec{16384, 8192, std::nullopt, 6};
    o.tiling = vts::Tiling::world_crs84_quad;
    o.bounds = vts::LonLatBounds{-10.5, 35.25, 30.125, 60.1};
    o.output = path;
    o.threads = 2;
    auto r = vts::build_pyramid(o);
    ASSERT_TRUE(r.ok()) << r.error().to_string();
  }
  auto vt = open(path);
  ASSERT_TRUE(vt);
  const vts::Geometry& g = vt->geometry();
  for (const vts::LonLat at : {vts::LonLat{5, 45}, vts::LonLat{25.3, 58.9}}) {
    auto k = camera_at(CameraKey{}, vts::Tiling::world_crs84_quad, g, at, 6);
    ASSERT_TRUE(k) << k.error().message;
    const GlobeScene scene = scene_for(*vt, k->globe);
    const auto centre = scene.hit(128, 96, 256, 192);
    const auto want = vts::lonlat_to_texel(vts::Tiling::world_crs84_quad, 256, 6, at);
    ASSERT_TRUE(centre);
    EXPECT_NEAR(centre->first, want.x, 0.01);
    EXPECT_NEAR(centre->second, want.y, 0.01);
    const Image got = converge(*vt, scene, 256, 192);
    const ImageDiff d = compare(got, reference(path, scene, 256, 192),
                                "globe-crs84-" + std::to_string(int(at.lon)));
    EXPECT_GE(d.psnr_db, 35.0) << at.lon;
    EXPECT_EQ(magenta(got), 0) << at.lon;
    EXPECT_EQ(lit(got), 256 * 192) << at.lon;
  }
}
