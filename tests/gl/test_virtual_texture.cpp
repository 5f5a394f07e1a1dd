// The sparse virtual texture end to end under Xvfb + llvmpipe: real archives built by the real
// builder, read through the real client stack (local source, TileClient decode pool), streamed
// into the GPU page table and physical texture, and judged against the CPU reference renderer.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include "gl_fixture.hpp"
#include "vts/builder/builder.hpp"
#include "vts/client/source.hpp"
#include "vts/client/tile_client.hpp"
#include "vts/imaging/web_image.hpp"
#include "vts/renderer/camera.hpp"
#include "vts/renderer/gl_context.hpp"
#include "vts/renderer/page_table.hpp"
#include "vts/renderer/reference.hpp"
#include "vts/renderer/virtual_texture.hpp"

namespace fs = std::filesystem;
using namespace vts::renderer;

namespace {

class VirtualTextureTest : public vts::test::VirtualTextureFixture {
 protected:
  // Renders until the frame reports complete (or max_frames); returns the frames it took.
  static int converge(VirtualTexture& vt, const PlaneView& view, int w, int h, int max_frames,
                      FrameStats* last = nullptr) {
    for (int i = 1; i <= max_frames; ++i) {
      const FrameStats st = vt.render(view, w, h);
      if (last) *last = st;
      if (st.complete) return i;
      // The decode pool works on its own threads: give it a moment between frames.
      if (st.pending > 0) ::usleep(2000);
    }
    return -1;
  }

  static ImageDiff against_reference(VirtualTexture& vt, const fs::path& path,
                                     const PlaneView& view, int w, int h,
                                     const std::string& save_as = {}) {
    auto sampler = PyramidSampler::open(path);
    EXPECT_TRUE(sampler.ok()) << sampler.error().to_string();
    auto ref =
        render_reference(**sampler, PlaneCamera::from_view(view, w, h), 0, vt.options().anisotropy);
    EXPECT_TRUE(ref.ok()) << ref.error().to_string();
    return against(vt.read_image(), *ref, save_as);
  }

  static ImageDiff against(const Image& got, const Image& ref, const std::string& save_as) {
    if (!save_as.empty()) {
      // VTS_TEST_KEEP_IMAGES=DIR keeps both images for a look.
      if (const char* keep = std::getenv("VTS_TEST_KEEP_IMAGES")) {
        (void)vts::imaging::write_png(fs::path(keep) / (save_as + "-gpu.png"), got.width,
                                      got.height, got.rgba);
        (void)vts::imaging::write_png(fs::path(keep) / (save_as + "-ref.png"), ref.width,
                                      ref.height, ref.rgba);
      }
    }
    auto diff = compare_images(got, ref);
    EXPECT_TRUE(diff.ok()) << diff.error().to_string();
    if (diff.ok()) {
      std::printf("  %s: PSNR %.2f dB, max |error| %d, mean |error| %.3f\n", save_as.c_str(),
                  diff->psnr_db, diff->max_abs, diff->mean_abs);
    }
    return diff.ok() ? *diff : ImageDiff{};
  }
};

TEST_F(VirtualTextureTest, PlaneStraightDownMatchesTheReference) {
  const fs::path path = archive("earth64", 64, 4);
  auto vt = open(path);
  ASSERT_TRUE(vt);
  // Between levels (trilinear), off the texel grid.
  PlaneView view{.center_u = 700.3, .center_v = 400.7, .texels_per_pixel = 1.7};
  FrameStats st;
  const int frames = converge(*vt, view, 256, 192, 300, &st);
  ASSERT_GT(frames, 0) << "never complete: wanted " << st.wanted << ", missing "
                       << st.wanted_missing << ", pending " << st.pending;
  const ImageDiff d = against_reference(*vt, path, view, 256, 192, "straight");
  EXPECT_GE(d.psnr_db, 40.0);
  EXPECT_LE(d.max_abs, 16);
}

// Texels are straight RGBA; the viewer composites them over its black background, so a
// transparent region shows the background (not the white RGB the file holds there), an opaque one
// the image's colour, and a half-transparent one half of it, as the CPU reference does.
TEST_F(VirtualTextureTest, AlphaIsCompositedOverTheBlackBackground) {
  const int W = 512, H = 256;
  std::vector<std::uint8_t> rgba(std::size_t(W) * H * 4);
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x < W; ++x) {
      std::uint8_t* p = &rgba[(std::size_t(y) * W + x) * 4];
      const bool opaque = x < W / 2, half = y >= H / 2 && !opaque;
      p[0] = opaque ? 200 : 255;
      p[1] = opaque ? 40 : 255;
      p[2] = opaque ? 20 : 255;
      p[3] = opaque ? 255 : half ? 128 : 0;
    }
  }
  const fs::path png = *dir_ / "alpha.png", path = *dir_ / "alpha.pmtiles";
  ASSERT_TRUE(vts::imaging::write_png(png, W, H, rgba).ok());
  vts::BuildOptions o;
  o.inputs = {png};
  o.output = path;
  o.tile_size = 64;
  o.border = 4;
  o.threads = 2;
  auto built = vts::build_pyramid(o);
  ASSERT_TRUE(built.ok()) << built.error().to_string();
  auto vt = open(path);
  ASSERT_TRUE(vt);
  // The whole image on a 256 x 128 viewport, 2 texels a pixel.
  const PlaneView view{.center_u = 256, .center_v = 128, .texels_per_pixel = 2};
  ASSERT_GT(converge(*vt, view, 256, 128, 300), 0);
  const Image img = vt->read_image();
  const auto near = [](const std::uint8_t* p, int r, int g, int b) {
    return std::abs(p[0] - r) <= 2 && std::abs(p[1] - g) <= 2 && std::abs(p[2] - b) <= 2;
  };
  // Rows: screen row 30 is image row 60 (transparent half), row 100 is image row 200.
  const std::uint8_t* opaque = img.at(60, 30);
  const std::uint8_t* clear = img.at(200, 30);
  const std::uint8_t* half = img.at(200, 100);
  EXPECT_TRUE(near(opaque, 200, 40, 20))
      << int(opaque[0]) << "," << int(opaque[1]) << "," << int(opaque[2]);
  EXPECT_TRUE(near(clear, 0, 0, 0))
      << int(clear[0]) << "," << int(clear[1]) << "," << int(clear[2]);
  // White at alpha 128/255 over black, in linear light, encoded to sRGB: 188.
  EXPECT_TRUE(near(half, 188, 188, 188))
      << int(half[0]) << "," << int(half[1]) << "," << int(half[2]);
  const ImageDiff d = against_reference(*vt, path, view, 256, 128, "alpha");
  EXPECT_GE(d.psnr_db, 40.0);
  EXPECT_LE(d.max_abs, 16);
}

TEST_F(VirtualTextureTest, PlaneTiltedAndTurnedMatchesTheReference) {
  const fs::path path = archive("earth64", 64, 4);
  auto vt = open(path);
  ASSERT_TRUE(vt);
  PlaneView view{
      .center_u = 1200, .center_v = 500, .texels_per_pixel = 0.8, .heading = 0.6, .tilt = 1.0};
  const int frames = converge(*vt, view, 256, 192, 300);
  ASSERT_GT(frames, 0);
  const ImageDiff d = against_reference(*vt, path, view, 256, 192, "tilted");
  EXPECT_GE(d.psnr_db, 35.0);
}

TEST_F(VirtualTextureTest, AnisotropicTapsMatchTheReference) {
  const fs::path path = archive("earth64", 64, 4);
  VirtualTextureOptions o;
  o.anisotropy = 8;
  auto vt = open(path, o);
  ASSERT_TRUE(vt);
  // Steep enough that the footprint reaches the 8-tap limit towards the top of the screen.
  PlaneView view{
      .center_u = 1000, .center_v = 600, .texels_per_pixel = 1.2, .heading = -0.4, .tilt = 1.25};
  ASSERT_GT(converge(*vt, view, 256, 192, 300), 0);
  const ImageDiff d = against_reference(*vt, path, view, 256, 192, "aniso8");
  EXPECT_GE(d.psnr_db, 35.0);
  EXPECT_EQ(magenta(vt->read_image()), 0);
}

TEST_F(VirtualTextureTest, AnisotropicIsCloserToTheSupersampledTruthThanTrilinear) {
  // The synthetic source changes every texel: what a filter blurs or aliases shows at once.
  const fs::path path = archive("synth64", 64, 4, vts::SyntheticSpec{1000, 600, std::nullopt, 6});
  PlaneView view{
      .center_u = 500, .center_v = 420, .texels_per_pixel = 0.9, .heading = 0.2, .tilt = 1.2};
  const int w = 192, h = 128;
  auto sampler = PyramidSampler::open(path);
  ASSERT_TRUE(sampler.ok()) << sampler.error().to_string();
  auto truth = render_supersampled(**sampler, PlaneScene(view), w, h, 8);
  ASSERT_TRUE(truth.ok()) << truth.error().to_string();
  double psnr[2] = {0, 0};
  const int limits[2] = {1, 8};
  for (int k = 0; k < 2; ++k) {
    VirtualTextureOptions o;
    o.anisotropy = limits[k];
    auto vt = open(path, o);
    ASSERT_TRUE(vt);
    ASSERT_GT(converge(*vt, view, w, h, 300), 0);
    psnr[k] = against(vt->read_image(), *truth, "truth-aniso" + std::to_string(limits[k])).psnr_db;
  }
  // Trilinear over-blurs a tilted plane (its level follows the footprint's long axis); eight
  // taps at a finer level get measurably closer to what the pixel really covers.
  EXPECT_GT(psnr[1], psnr[0] + 5.0)
      << "trilinear " << psnr[0] << " dB, 8 taps " << psnr[1] << " dB";
}

TEST_F(VirtualTextureTest, AnisotropyOutsideItsRangeIsRefused) {
  const fs::path path = archive("earth64", 64, 4);
  auto src = vts::client::open_local_archive(path);
  ASSERT_TRUE(src.ok());
  auto tiles = vts::client::TileClient::create(std::shared_ptr(std::move(*src)));
  ASSERT_TRUE(tiles.ok());
  const auto geometry = (*tiles)->info().info.geometry;
  std::shared_ptr<vts::client::TileClient> client(std::move(*tiles));
  for (int bad : {0, -1, 17}) {
    VirtualTextureOptions o;
    o.anisotropy = bad;
    auto vt = VirtualTexture::create(client, geometry, o);
    ASSERT_FALSE(vt.ok()) << bad;
    EXPECT_NE(vt.error().message.find("anisotropy"), std::string::npos) << vt.error().message;
  }
}

TEST_F(VirtualTextureTest, PageTableMemoryDoesNotDependOnTheImageSize) {
  // A 2^15- and a 2^25-texel-wide sparse synthetic archive: the same page-table texture.
  const vts::TexelRect small_region{0, 0, 1024, 1024};
  const fs::path a =
      archive("w15", 256, 4, vts::SyntheticSpec{1u << 15, 1u << 14, small_region, 6});
  const vts::TexelRect big_region{1u << 24, 1u << 23, (1u << 24) + 1024, (1u << 23) + 1024};
  const fs::path b = archive("w25", 256, 4, vts::SyntheticSpec{1u << 25, 1u << 24, big_region, 6});
  auto va = open(a);
  auto vb = open(b);
  ASSERT_TRUE(va && vb);
  EXPECT_EQ(va->page_table_gpu_bytes(), vb->page_table_gpu_bytes());
  EXPECT_EQ(va->page_table_gpu_bytes(), ClipmapPageTable::gpu_bytes(64));
  EXPECT_LT(vb->page_table_gpu_bytes(), 1u << 20);
}

TEST_F(VirtualTextureTest, FinestLevelOfA2To25WideSparseArchive) {
  const vts::TexelRect region{1u << 24, 1u << 23, (1u << 24) + 1024, (1u << 23) + 1024};
  const fs::path path = archive("w25", 256, 4, vts::SyntheticSpec{1u << 25, 1u << 24, region, 6});
  auto vt = open(path);
  ASSERT_TRUE(vt);
  // 4 screen pixels per finest texel, deep inside the region, off the texel grid.
  PlaneView view{.center_u = double(1u << 24) + 300.37,
                 .center_v = double(1u << 23) + 500.61,
                 .texels_per_pixel = 0.25};
  const int frames = converge(*vt, view, 128, 128, 300);
  ASSERT_GT(frames, 0);
  const ImageDiff d = against_reference(*vt, path, view, 128, 128, "w25");
  EXPECT_GE(d.psnr_db, 40.0);
  EXPECT_LE(d.max_abs, 8);
}

TEST_F(VirtualTextureTest, TooFewSlotsRaisesTheBiasAndStillDrawsEverything) {
  const fs::path path = archive("earth64", 64, 4);
  VirtualTextureOptions o;
  o.slots = 12;
  auto vt = open(path, o);
  ASSERT_TRUE(vt);
  PlaneView view{.center_u = 1024, .center_v = 512, .texels_per_pixel = 1.0};
  FrameStats st;
  double max_bias = 0;
  for (int i = 0; i < 200; ++i) {
    st = vt->render(view, 256, 256);
    max_bias = std::max(max_bias, st.mip_bias);
    if (st.pending > 0) ::usleep(2000);
  }
  EXPECT_GT(max_bias, 0.0);
  EXPECT_LE(st.resident, 12u);
  // Complete at a coarser level: nothing magenta (unmapped) on screen.
  EXPECT_EQ(magenta(vt->read_image()), 0);
}

TEST_F(VirtualTextureTest, NoSeamsAcrossTileBordersBilinearOrTrilinear) {
  // The synthetic source changes every texel, so a wrong border or slot offset shows at once.
  const fs::path path = archive("synth64", 64, 4, vts::SyntheticSpec{1000, 600, std::nullopt, 6});
  auto vt = open(path);
  ASSERT_TRUE(vt);
  // Centred on a tile corner of the finest level (512 = 8 tiles of 64), magnified (bilinear
  // inside one level) and minified between levels (trilinear), straight and tilted.
  const PlaneView views[] = {
      {.center_u = 512.2, .center_v = 256.3, .texels_per_pixel = 0.37},
      {.center_u = 512.2, .center_v = 256.3, .texels_per_pixel = 1.5},
      {.center_u = 512.2, .center_v = 256.3, .texels_per_pixel = 0.6, .heading = 0.3, .tilt = 0.9},
  };
  int i = 0;
  for (const PlaneView& view : views) {
    ASSERT_GT(converge(*vt, view, 160, 120, 300), 0);
    const ImageDiff d = against_reference(*vt, path, view, 160, 120, "seams" + std::to_string(i++));
    EXPECT_GE(d.psnr_db, 40.0) << "view " << i;
    EXPECT_LE(d.max_abs, 24) << "view " << i;
  }
}

TEST_F(VirtualTextureTest, ConvergesWithinAFewFramesAfterAJumpWithAWarmCache) {
  const fs::path path = archive("earth64", 64, 4);
  VirtualTextureOptions o;
  o.slots = 64;  // too few to keep both views: the return trip re-uploads from the client's RAM
  auto vt = open(path, o);
  ASSERT_TRUE(vt);
  const PlaneView a{.center_u = 300, .center_v = 300, .texels_per_pixel = 0.5};
  const PlaneView b{.center_u = 1700, .center_v = 700, .texels_per_pixel = 0.5};
  ASSERT_GT(converge(*vt, a, 256, 192, 300), 0);
  ASSERT_GT(converge(*vt, b, 256, 192, 300), 0);
  // Back to a: every tile is in the client's RAM cache. The feedback ring (3 frames) and the
  // upload budget bound the frames to full resolution.
  const int frames = converge(*vt, a, 256, 192, 300);
  std::printf("  frames to full resolution after a jump (warm RAM): %d\n", frames);
  EXPECT_GT(frames, 0);
  EXPECT_LE(frames, 12);
}

TEST_F(VirtualTextureTest, BiasFallsBackWhenThePhysicalTextureIsLargeEnough) {
  const fs::path path = archive("earth64", 64, 4);
  VirtualTextureOptions o;
  o.slots = 24;
  auto vt = open(path, o);
  ASSERT_TRUE(vt);
  // A wide view wants about 60 tiles (with ancestors), far more than 24; a 32 x 32 close view
  // wants one tile and its ancestors (and predicts fewer than 0.9 x 24 a level finer), so the
  // bias must come back to 0.
  const PlaneView wide{.center_u = 1024, .center_v = 512, .texels_per_pixel = 1.5};
  const PlaneView close{.center_u = 1000, .center_v = 500, .texels_per_pixel = 0.5};
  FrameStats st;
  double peak = 0;
  std::uint32_t peak_wanted = 0;
  for (int i = 0; i < 120; ++i) {
    st = vt->render(wide, 256, 256);
    peak = std::max(peak, st.mip_bias);
    peak_wanted = std::max(peak_wanted, st.wanted);
    if (st.pending > 0) ::usleep(2000);
  }
  EXPECT_GT(peak, 0.0) << "the wide view wanted at most " << peak_wanted << " tiles";
  for (int i = 0; i < 400 && st.mip_bias > 0; ++i) {
    st = vt->render(close, 32, 32);
    if (st.pending > 0) ::usleep(2000);
  }
  EXPECT_EQ(st.mip_bias, 0.0) << "the close view wants " << st.wanted << " tiles";
  ASSERT_GT(converge(*vt, close, 32, 32, 300), 0);
  const ImageDiff d = against_reference(*vt, path, close, 32, 32, "recovered");
  EXPECT_GE(d.psnr_db, 40.0);
}

TEST_F(VirtualTextureTest, HardCasesNeitherCrashNorDrawGarbage) {
  const fs::path path = archive("earth64", 64, 4);
  auto vt = open(path);
  ASSERT_TRUE(vt);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double W = 2048, H = 1024;
  struct Case {
    const char* name;
    PlaneView view;
    bool compare;
  };
  const Case cases[] = {
      // The image's corners: u, v at 0, just below W / H (the last representable double below
      // them) and exactly W / H.
      {"corner0", {.center_u = 0, .center_v = 0, .texels_per_pixel = 0.3}, true},
      {"corner1ulp",
       {.center_u = std::nextafter(W, 0.0),
        .center_v = std::nextafter(H, 0.0),
        .texels_per_pixel = 0.3},
       true},
      {"corner1", {.center_u = W, .center_v = H, .texels_per_pixel = 0.3}, true},
      // Zero footprint (finest level, deep magnification) and a huge one (whole image in a pixel).
      {"tiny", {.center_u = 1000.5, .center_v = 500.5, .texels_per_pixel = 1e-7}, true},
      {"huge", {.center_u = 1000, .center_v = 500, .texels_per_pixel = 1e6}, true},
      // Grazing: most of the screen above the horizon, derivatives explode near it.
      {"horizon", {.center_u = 1000, .center_v = 500, .texels_per_pixel = 1, .tilt = 1.5}, true},
      // NaN in the view: nothing sensible to draw, but no crash and no stray colour.
      {"nan", {.center_u = nan, .center_v = 500, .texels_per_pixel = 1}, false},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    int frames = 0;
    for (; frames < 300; ++frames) {
      const FrameStats st = vt->render(c.view, 128, 96);
      if (st.complete || (!c.compare && frames > 10)) break;
      if (st.pending > 0) ::usleep(2000);
    }
    EXPECT_EQ(magenta(vt->read_image()), 0);
    if (c.compare) {
      const ImageDiff d = against_reference(*vt, path, c.view, 128, 96, c.name);
      EXPECT_GE(d.psnr_db, 35.0);
    }
  }
}

}  // namespace
