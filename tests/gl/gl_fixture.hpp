// One hidden GL context for every renderer test of the process: opening a display per test adds
// nothing to what is tested and makes X connections the test's busiest resource.
#pragma once

#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "vts/builder/builder.hpp"
#include "vts/client/source.hpp"
#include "vts/client/tile_client.hpp"
#include "vts/renderer/gl_context.hpp"
#include "vts/renderer/reference.hpp"
#include "vts/renderer/virtual_texture.hpp"

namespace vts::test {

// A small hidden context's options, GL debug output on, made through `backend`: what the context
// tests open (GLFW's and EGL's alike).
inline renderer::GlContextOptions hidden_options(
    int width = 64, int height = 64, renderer::GlBackend backend = renderer::GlBackend::automatic) {
  renderer::GlContextOptions o;
  o.width = width;
  o.height = height;
  o.visible = false;
  o.vsync = false;
  o.debug = true;
  o.backend = backend;
  return o;
}

// The context, current on the calling (main) thread; nullptr with the reason in `error`. Created
// on first use and kept until the process exits.
inline renderer::GlContext* shared_gl_context(std::string* error = nullptr) {
  static std::string failure;
  static renderer::GlContext* context = [] {
    renderer::GlContextOptions o;
    o.width = 64;
    o.height = 64;
    o.visible = false;
    o.vsync = false;
    auto c = renderer::GlContext::create(o);
    if (!c.ok()) {
      failure = c.error().to_string();
      return static_cast<renderer::GlContext*>(nullptr);
    }
    return c->release();  // lives until exit: no GLFW teardown in static destructors
  }();
  if (context) context->make_current();
  if (error) *error = failure;
  return context;
}

// Base of the virtual-texture GL tests: archives built by the real builder in a per-suite temp
// folder, the shared context, and a VirtualTexture over the real client stack.
class VirtualTextureFixture : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new std::filesystem::path(std::filesystem::temp_directory_path() /
                                     ("vts-gl-test-" + std::to_string(::getpid())));
    std::filesystem::create_directories(*dir_);
  }
  static void TearDownTestSuite() {
    std::error_code ec;
    std::filesystem::remove_all(*dir_, ec);
    delete dir_;
  }

  // Builds (once per name and suite) an archive of the Earth image or of a synthetic source.
  static std::filesystem::path archive(const std::string& name, std::uint32_t tile,
                                       std::uint32_t border,
                                       std::optional<SyntheticSpec> synthetic = std::nullopt) {
    const std::filesystem::path out = *dir_ / (name + ".pmtiles");
    if (std::filesystem::exists(out)) return out;
    BuildOptions o;
    if (synthetic) {
      o.synthetic = synthetic;
    } else {
      o.inputs = {"/usr/share/xplanet/images/earth.jpg"};
    }
    o.output = out;
    o.tile_size = tile;
    o.border = border;
    o.threads = 2;
    auto r = build_pyramid(o);
    EXPECT_TRUE(r.ok()) << r.error().to_string();
    return out;
  }

  void SetUp() override {
    std::string error;
    gl_ = shared_gl_context(&error);
    ASSERT_NE(gl_, nullptr) << error;
  }

  // A VirtualTexture reading `path` through a local source and a TileClient (decode pool).
  static std::unique_ptr<renderer::VirtualTexture> open(
      const std::filesystem::path& path, renderer::VirtualTextureOptions options = {}) {
    auto src = client::open_local_archive(path);
    EXPECT_TRUE(src.ok()) << src.error().to_string();
    if (!src.ok()) return nullptr;
    auto tiles = client::TileClient::create(std::shared_ptr(std::move(*src)));
    EXPECT_TRUE(tiles.ok()) << tiles.error().to_string();
    if (!tiles.ok()) return nullptr;
    auto geometry = (*tiles)->info().info.geometry;
    auto vt =
        renderer::VirtualTexture::create(std::shared_ptr(std::move(*tiles)), geometry, options);
    EXPECT_TRUE(vt.ok()) << vt.error().to_string();
    return vt.ok() ? std::move(*vt) : nullptr;
  }

  // Pixels in the shader's "nothing resident" colour (magenta): there must never be any.
  static int magenta(const renderer::Image& img) {
    int n = 0;
    for (int y = 0; y < img.height; ++y) {
      for (int x = 0; x < img.width; ++x) {
        const auto* p = img.at(x, y);
        if (p[0] == 255 && p[1] == 0 && p[2] == 255) ++n;
      }
    }
    return n;
  }

  static inline std::filesystem::path* dir_ = nullptr;
  renderer::GlContext* gl_ = nullptr;
};

}  // namespace vts::test
