// BC1 tilesets in the GPU virtual texture under Xvfb + llvmpipe: an archive of the Earth image
// built by the real builder with the bc1 codec, streamed through the real client stack into a
// GL_COMPRESSED_SRGB_ALPHA_S3TC_DXT1 physical texture, and judged against the CPU reference
// renderer reading the SAME archive (its tiles widened to rgba8 by vts::bc1_to_rgba8), then
// against the lossless archive of the same image (what BC1 costs on screen).
//
// The bounds below were measured on Mesa llvmpipe (docs/RENDERER.md, "BC1 tilesets"); the comments
// say why each holds and what a broken upload would do to it.
#include <epoxy/gl.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "gl_fixture.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/builder/builder.hpp"
#include "vts/client/source.hpp"
#include "vts/client/tile_client.hpp"
#include "vts/imaging/web_image.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/protocol/tileset.hpp"
#include "vts/renderer/camera.hpp"
#include "vts/renderer/gl_program.hpp"
#include "vts/renderer/globe.hpp"
#include "vts/renderer/reference.hpp"
#include "vts/renderer/virtual_texture.hpp"

namespace fs = std::filesystem;
using namespace vts::renderer;

namespace {

// A source that passes every call to another one but describes the tileset with another codec:
// the renderer then expects tiles in a format the payloads do not decode to.
class RelabelledSource final : public vts::client::TileSource {
 public:
  RelabelledSource(std::shared_ptr<vts::client::TileSource> inner, vts::CodecId codec)
      : inner_(std::move(inner)), info_(inner_->info()) {
    info_.info.codec = codec;
    info_.key += "#relabelled";
  }
  const vts::client::SourceInfo& info() const override { return info_; }
  bool local() const override { return inner_->local(); }
  Handle fetch(const vts::client::SourceRequest& request,
               vts::client::SourceCallback callback) override {
    return inner_->fetch(request, std::move(callback));
  }
  void cancel(Handle h) override { inner_->cancel(h); }

 private:
  std::shared_ptr<vts::client::TileSource> inner_;
  vts::client::SourceInfo info_;
};

class Bc1Test : public vts::test::VirtualTextureFixture {
 protected:
  // The Earth image (2048 x 1024), 64-texel tiles with a 4-texel border: 72-texel slots, whole
  // 4 x 4 blocks. Built once per suite, by the real builder with the bc1 codec.
  static fs::path bc1_archive() {
    const fs::path out = *dir_ / "earth64-bc1.pmtiles";
    if (fs::exists(out)) return out;
    vts::BuildOptions o;
    o.inputs = {"/usr/share/xplanet/images/earth.jpg"};
    o.output = out;
    o.tile_size = 64;
    o.border = 4;
    o.codec = vts::CodecId::bc1;
    o.encode.bc1 = vts::Bc1Quality::high;
    o.threads = 2;
    auto r = build_pyramid(o);
    EXPECT_TRUE(r.ok()) << r.error().to_string();
    return out;
  }
  static fs::path lossless_archive() { return archive("earth64", 64, 4); }

  // Renders until complete; checks that every frame uploaded whole compressed tiles only.
  static bool converge(VirtualTexture& vt, const Scene& scene, int w, int h,
                       FrameStats* last = nullptr) {
    const std::uint64_t s = vt.geometry().stored_size();
    const std::uint64_t tile_bytes =
        vt.tile_format() == vts::PixelFormat::bc1 ? (s / 4) * (s / 4) * 8 : s * s * 4;
    FrameStats st;
    for (int i = 0; i < 400; ++i) {
      st = vt.render(scene, w, h);
      EXPECT_EQ(st.upload_bytes, std::uint64_t(st.uploads) * tile_bytes) << "frame " << st.frame;
      if (st.complete) break;
      if (st.pending > 0) ::usleep(2000);
    }
    if (last) *last = st;
    EXPECT_TRUE(st.complete) << "wanted " << st.wanted << ", missing " << st.wanted_missing
                             << ", pending " << st.pending << ", errors " << st.errors;
    EXPECT_EQ(st.errors, 0u);
    EXPECT_FALSE(vt.last_error()) << vt.last_error()->to_string();
    return st.complete;
  }

  static Image reference(const fs::path& path, const Scene& scene, int w, int h) {
    auto sampler = PyramidSampler::open(path);
    EXPECT_TRUE(sampler.ok()) << sampler.error().to_string();
    if (!sampler.ok()) return Image::blank(w, h);
    auto ref = render_reference(**sampler, scene, w, h);
    EXPECT_TRUE(ref.ok()) << ref.error().to_string();
    return ref.ok() ? *ref : Image::blank(w, h);
  }

  static ImageDiff compare(const Image& got, const Image& ref, const std::string& name) {
    // VTS_TEST_KEEP_IMAGES=DIR keeps both images for a look.
    if (const char* keep = std::getenv("VTS_TEST_KEEP_IMAGES")) {
      (void)vts::imaging::write_png(fs::path(keep) / (name + "-gpu.png"), got.width, got.height,
                                    got.rgba);
      (void)vts::imaging::write_png(fs::path(keep) / (name + "-ref.png"), ref.width, ref.height,
                                    ref.rgba);
    }
    auto d = compare_images(got, ref);
    EXPECT_TRUE(d.ok()) << d.error().to_string();
    if (!d.ok()) return {};
    std::printf("  %s: PSNR %.2f dB, max |error| %d, mean |error| %.3f, over 8: %llu px\n",
                name.c_str(), d->psnr_db, d->max_abs, d->mean_abs,
                static_cast<unsigned long long>(d->pixels_over));
    return *d;
  }
};

// The plane views of the lossless tests, on the BC1 archive. The GPU reads the same blocks the
// reference widens with bc1_to_rgba8, filters them the same way in linear light, so the two
// images differ only by the GPU's float filtering, its sRGB decode, and the rounding of the
// interpolated block colours (where a GPU may differ from libsquish by one code, see
// GpuBlockDecodeMatchesBc1ToRgba8). Measured 55.4-58.3 dB, max error 2-6; the lossless path
// measures 55.3-58.8 dB, max 1-7 on the same kind of views. A slot uploaded one block (4 texels)
// off measured 18-26 dB, a non-sRGB atlas 12-14 dB.
TEST_F(Bc1Test, PlaneViewsMatchTheReferenceOfTheSameArchive) {
  const fs::path path = bc1_archive();
  auto vt = open(path);
  ASSERT_TRUE(vt);
  EXPECT_EQ(vt->tile_format(), vts::PixelFormat::bc1);
  struct Case {
    const char* name;
    PlaneView view;
  };
  const Case cases[] = {
      // Between levels (trilinear), off the texel grid.
      {"bc1-straight", {.center_u = 700.3, .center_v = 400.7, .texels_per_pixel = 1.7}},
      // Magnified 3x at the finest level: each block's 4 x 4 texels are 12 x 12 pixels.
      {"bc1-magnified", {.center_u = 1024.4, .center_v = 300.6, .texels_per_pixel = 0.33}},
      // On a tile corner of the finest level (512 = 8 tiles of 64): four slots meet.
      {"bc1-corner", {.center_u = 512.2, .center_v = 256.3, .texels_per_pixel = 0.6}},
      {"bc1-tilted",
       {.center_u = 1200, .center_v = 500, .texels_per_pixel = 0.8, .heading = 0.6, .tilt = 1.0}},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const PlaneScene scene(c.view);
    ASSERT_TRUE(converge(*vt, scene, 256, 192));
    const Image got = vt->read_image();
    EXPECT_EQ(magenta(got), 0);
    const ImageDiff d = compare(got, reference(path, scene, 256, 192), c.name);
    EXPECT_GE(d.psnr_db, 50.0);
    EXPECT_LE(d.max_abs, 8);
  }
}

// The globe through the same slots: the whole Earth (measured 63.4 dB, max 4) and the date line,
// where the view straddles u = 0 / W (90.3 dB, max 1).
TEST_F(Bc1Test, GlobeMatchesTheReferenceOfTheSameArchive) {
  const fs::path path = bc1_archive();
  auto vt = open(path);
  ASSERT_TRUE(vt);
  for (const GlobeView& view :
       {GlobeView{.lon_deg = 15, .lat_deg = 25, .altitude_m = 2e7, .heading = 0.3},
        GlobeView{
            .lon_deg = 179.6, .lat_deg = 10, .altitude_m = 1e6, .heading = 0.4, .tilt = 0.3}}) {
    const GlobeScene scene(view, vt->geometry().width(), vt->geometry().height());
    ASSERT_TRUE(converge(*vt, scene, 256, 192));
    const Image got = vt->read_image();
    EXPECT_EQ(magenta(got), 0);
    const ImageDiff d = compare(got, reference(path, scene, 256, 192),
                                "bc1-globe" + std::to_string(int(view.lon_deg)));
    EXPECT_GE(d.psnr_db, 55.0);
    EXPECT_LE(d.max_abs, 8);
  }
}

// The physical texture holds the blocks as they are: half a byte per texel, an eighth of the
// rgba8 atlas of the same slots, as the driver reports it.
TEST_F(Bc1Test, PhysicalTextureIsAnEighthOfTheRgba8One) {
  VirtualTextureOptions o;
  o.slots = 64;  // 8 x 8 slots of 72 texels: a 576 x 576 atlas
  auto bc1 = open(bc1_archive(), o);
  auto rgba = open(lossless_archive(), o);
  ASSERT_TRUE(bc1 && rgba);
  EXPECT_EQ(bc1->tile_format(), vts::PixelFormat::bc1);
  EXPECT_EQ(rgba->tile_format(), vts::PixelFormat::rgba8);
  EXPECT_EQ(rgba->physical_gpu_bytes(), 576u * 576u * 4u);
  EXPECT_EQ(bc1->physical_gpu_bytes(), 576u * 576u / 2u);
  EXPECT_EQ(bc1->physical_gpu_bytes() * 8, rgba->physical_gpu_bytes());
  // The page table does not depend on the codec.
  EXPECT_EQ(bc1->page_table_gpu_bytes(), rgba->page_table_gpu_bytes());
}

// What BC1 costs on screen: the BC1 render against the reference of the LOSSLESS archive of the
// same image. Lossy (BC1 keeps 2 endpoint colours per 4 x 4 block), but bounded: measured
// 36.6 dB (max 44) magnified 3x at the finest level, where every block's error is on screen, and
// 42.1 dB (max 49) at 1 texel per pixel, where trilinear filtering averages some of it away;
// the codec alone (the BC1 archive's CPU reference against the lossless one) measures 36.6 and
// 42.5 dB. Both bounds matter: a BC1 render equal to the lossless one would mean rgba8 tiles were
// drawn, and a much lower PSNR a broken block layout.
TEST_F(Bc1Test, LossyAgainstTheLosslessArchiveButBounded) {
  const fs::path bc1_path = bc1_archive();
  const fs::path lossless_path = lossless_archive();
  auto vt = open(bc1_path);
  ASSERT_TRUE(vt);
  const PlaneView views[] = {
      {.center_u = 1024.4, .center_v = 300.6, .texels_per_pixel = 0.33},
      {.center_u = 700.3, .center_v = 400.7, .texels_per_pixel = 1.0},
  };
  int i = 0;
  for (const PlaneView& view : views) {
    const PlaneScene scene(view);
    ASSERT_TRUE(converge(*vt, scene, 256, 192));
    const Image got = vt->read_image();
    const std::string name = "bc1-vs-lossless" + std::to_string(i++);
    const ImageDiff codec_only = compare(reference(bc1_path, scene, 256, 192),
                                         reference(lossless_path, scene, 256, 192), name + "-cpu");
    const ImageDiff d = compare(got, reference(lossless_path, scene, 256, 192), name);
    EXPECT_LT(d.psnr_db, 45.0);
    EXPECT_GE(d.psnr_db, 33.0);
    EXPECT_GT(d.max_abs, 16);
    EXPECT_LE(d.max_abs, 64);
    // The GPU adds next to nothing to the codec's own error.
    EXPECT_NEAR(d.psnr_db, codec_only.psnr_db, 1.0);
  }
}

TEST_F(Bc1Test, DebugViewsWork) {
  const fs::path path = bc1_archive();
  auto vt = open(path);
  ASSERT_TRUE(vt);
  const PlaneScene scene(PlaneView{.center_u = 700.3, .center_v = 400.7, .texels_per_pixel = 1.7});
  ASSERT_TRUE(converge(*vt, scene, 256, 192));
  const Image normal = vt->read_image();
  for (DebugView mode : {DebugView::levels, DebugView::physical, DebugView::page_table}) {
    SCOPED_TRACE(int(mode));
    vt->set_debug_view(mode);
    const FrameStats st = vt->render(scene, 256, 192);
    EXPECT_EQ(st.errors, 0u);
    EXPECT_FALSE(vt->last_error());
    const Image img = vt->read_image();
    EXPECT_EQ(magenta(img), 0);
    const ImageDiff d = compare(img, normal, "bc1-debug" + std::to_string(int(mode)));
    EXPECT_LT(d.psnr_db, 30.0);  // it shows something else than the image
  }
  // The physical view: slot 0 (top-left) holds the root tile, the Earth, not the black the atlas
  // was cleared to; the slots never used stay black.
  vt->set_debug_view(DebugView::physical);
  (void)vt->render(scene, 256, 192);
  const Image atlas = vt->read_image();
  int lit_root = 0;
  for (int y = 0; y < 8; ++y) {
    for (int x = 0; x < 8; ++x) {
      const auto* p = atlas.at(x, y);
      lit_root += (p[0] | p[1] | p[2]) != 0;
    }
  }
  EXPECT_GT(lit_root, 32);
  const auto* last = atlas.at(atlas.width - 1, atlas.height - 1);
  EXPECT_EQ(last[0] | last[1] | last[2], 0);
}

// The GPU's S3TC decoder against vts::bc1_to_rgba8 (libsquish's rounding), texel by texel, on
// every tile of the archive: each tile is uploaded into a DXT1 texture and read back through the
// sampler (texelFetch into an RGBA8 target), so this is the decode the virtual texture's
// filtering starts from. The S3TC specification leaves the rounding of the two interpolated
// colours open; the bound is one code.
TEST_F(Bc1Test, GpuBlockDecodeMatchesBc1ToRgba8) {
  const fs::path path = bc1_archive();
  auto reader = vts::archive::Reader::open(path);
  ASSERT_TRUE(reader.ok()) << reader.error().to_string();
  auto info = vts::TilesetInfo::from_json((*reader)->metadata_json());
  ASSERT_TRUE(info.ok()) << info.error().to_string();
  const vts::Geometry& g = info->geometry;
  const int s = int(g.stored_size());

  auto program = link_program(R"(#version 450 core
void main() {
  vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
  gl_Position = vec4(p, 0.0, 1.0);
})",
                              R"(#version 450 core
uniform sampler2D u_tex;
out vec4 o_color;
void main() { o_color = texelFetch(u_tex, ivec2(gl_FragCoord.xy), 0); })",
                              "bc1 decode");
  ASSERT_TRUE(program.ok()) << program.error().to_string();
  GLuint tex = 0, target = 0, fbo = 0, vao = 0;
  glCreateTextures(GL_TEXTURE_2D, 1, &tex);
  glTextureStorage2D(tex, 1, GL_COMPRESSED_RGBA_S3TC_DXT1_EXT, s, s);  // no sRGB decode
  glCreateTextures(GL_TEXTURE_2D, 1, &target);
  glTextureStorage2D(target, 1, GL_RGBA8, s, s);
  glCreateFramebuffers(1, &fbo);
  glNamedFramebufferTexture(fbo, GL_COLOR_ATTACHMENT0, target, 0);
  glCreateVertexArrays(1, &vao);

  std::uint64_t tiles = 0, values = 0, differing = 0;
  int max_diff = 0;
  std::vector<std::uint8_t> gpu(std::size_t(s) * s * 4);
  for (int z = 0; z <= g.max_zoom(); ++z) {
    for (std::uint32_t y = 0; y < g.tiles_y(z); ++y) {
      for (std::uint32_t x = 0; x < g.tiles_x(z); ++x) {
        const vts::TileId id{std::uint8_t(z), x, y};
        auto bytes = (*reader)->get(id);
        if (!bytes.ok()) continue;  // a tile wholly outside the image
        auto img = vts::decode_tile(*bytes);
        ASSERT_TRUE(img.ok()) << img.error().to_string();
        ASSERT_EQ(img->format, vts::PixelFormat::bc1);
        auto cpu = vts::bc1_to_rgba8(*img);
        ASSERT_TRUE(cpu.ok()) << cpu.error().to_string();
        glBindBuffer(GL_PIXEL_UNPACK_BUFFER, 0);
        glCompressedTextureSubImage2D(tex, 0, 0, 0, s, s, GL_COMPRESSED_RGBA_S3TC_DXT1_EXT,
                                      GLsizei(img->pixels.size()), img->pixels.data());
        glBindFramebuffer(GL_FRAMEBUFFER, fbo);
        glViewport(0, 0, s, s);
        glDisable(GL_FRAMEBUFFER_SRGB);
        glUseProgram(program->get());
        glBindTextureUnit(0, tex);
        glBindVertexArray(vao);
        glDrawArrays(GL_TRIANGLES, 0, 3);
        glPixelStorei(GL_PACK_ALIGNMENT, 1);
        glReadPixels(0, 0, s, s, GL_RGBA, GL_UNSIGNED_BYTE, gpu.data());  // row 0 = tile row 0
        for (std::size_t i = 0; i < gpu.size(); ++i) {
          if (i % 4 == 3) continue;  // opaque image: alpha is 255 in both
          const int d = std::abs(int(gpu[i]) - int(cpu->pixels[i]));
          max_diff = std::max(max_diff, d);
          differing += d != 0;
          ++values;
        }
        ++tiles;
      }
    }
  }
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  glDeleteTextures(1, &tex);
  glDeleteTextures(1, &target);
  glDeleteFramebuffers(1, &fbo);
  glDeleteVertexArrays(1, &vao);
  std::printf("  %llu tiles: %llu of %llu colour values differ, max |difference| %d\n",
              static_cast<unsigned long long>(tiles), static_cast<unsigned long long>(differing),
              static_cast<unsigned long long>(values), max_diff);
  EXPECT_GT(tiles, 100u);
  EXPECT_LE(max_diff, 1);
}

TEST_F(Bc1Test, UnalignedSlotsAreRefused) {
  // The builder makes no such bc1 archive (it refuses a border that is not a multiple of 4), so
  // a lossless one of 64 + 2 x 1 = 66-texel tiles is described as bc1: not whole 4 x 4 blocks.
  const fs::path path = archive("synth-b1", 64, 1, vts::SyntheticSpec{300, 200, std::nullopt, 6});
  auto src = vts::client::open_local_archive(path);
  ASSERT_TRUE(src.ok()) << src.error().to_string();
  auto relabelled =
      std::make_shared<RelabelledSource>(std::shared_ptr(std::move(*src)), vts::CodecId::bc1);
  auto tiles = vts::client::TileClient::create(relabelled);
  ASSERT_TRUE(tiles.ok());
  const auto geometry = relabelled->info().info.geometry;
  ASSERT_EQ(geometry.stored_size(), 66u);
  auto vt = VirtualTexture::create(std::shared_ptr(std::move(*tiles)), geometry);
  ASSERT_FALSE(vt.ok());
  EXPECT_EQ(vt.error().code, vts::ErrorCode::unsupported);
  EXPECT_NE(vt.error().message.find("multiple of 4"), std::string::npos) << vt.error().message;
}

// Tiles that do not decode to the tileset's format (here rgba8 tiles of a tileset said to be
// bc1) are never uploaded: each is counted as an error and nothing becomes resident.
TEST_F(Bc1Test, TilesOfTheWrongFormatAreErrors) {
  auto src = vts::client::open_local_archive(lossless_archive());
  ASSERT_TRUE(src.ok()) << src.error().to_string();
  auto relabelled =
      std::make_shared<RelabelledSource>(std::shared_ptr(std::move(*src)), vts::CodecId::bc1);
  auto tiles = vts::client::TileClient::create(relabelled);
  ASSERT_TRUE(tiles.ok());
  const auto geometry = relabelled->info().info.geometry;
  auto vt = VirtualTexture::create(std::shared_ptr(std::move(*tiles)), geometry);
  ASSERT_TRUE(vt.ok()) << vt.error().to_string();
  EXPECT_EQ((*vt)->tile_format(), vts::PixelFormat::bc1);
  FrameStats st;
  for (int i = 0; i < 60 && st.errors == 0; ++i) {
    st = (*vt)->render(PlaneView{.center_u = 1024, .center_v = 512, .texels_per_pixel = 4}, 64, 64);
    ::usleep(2000);
  }
  EXPECT_GT(st.errors, 0u);
  EXPECT_EQ(st.resident, 0u);
  EXPECT_EQ(st.uploads, 0u);
  EXPECT_FALSE(st.complete);
}

}  // namespace
