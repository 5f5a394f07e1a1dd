// EGL contexts with no display (renderer/gl/src/gl_context_egl.cpp) on Mesa: the device platform
// (EGL_EXT_platform_device; here Mesa's software device, EGL_MESA_device_software, llvmpipe)
// and Mesa's surfaceless platform. GlEgl runs in its own ctest entry with DISPLAY and
// WAYLAND_DISPLAY unset (gl.egl_without_display), where a hidden context must come from EGL; the
// rest of the GL suite runs there too, on that EGL context.
#include <epoxy/gl.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <string>
#include <vector>

#include "gl_fixture.hpp"
#include "vts/builder/synthetic.hpp"
#include "vts/renderer/gl_context.hpp"
#include "vts/renderer/viewer.hpp"

namespace {

using vts::renderer::GlBackend;
using vts::renderer::GlContext;
using vts::renderer::GlContextOptions;

GlContextOptions headless(GlBackend backend, int w = 64, int h = 64) {
  return vts::test::hidden_options(w, h, backend);
}

// Sets an environment variable for one scope.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const char* value) : name_(name) {
    if (const char* old = std::getenv(name)) old_ = old;
    setenv(name, value, 1);
  }
  ~ScopedEnv() {
    if (old_.empty())
      unsetenv(name_);
    else
      setenv(name_, old_.c_str(), 1);
  }

 private:
  const char* name_;
  std::string old_;
};

// Clears a w x h RGBA8 framebuffer object to (r, g, b, 255) and reads it back: the number of
// pixels that differ (a context with no surface must still render into its own FBOs).
int fbo_clear_mismatches(int w, int h, unsigned char r, unsigned char g, unsigned char b) {
  GLuint tex = 0, fbo = 0;
  glCreateTextures(GL_TEXTURE_2D, 1, &tex);
  glTextureStorage2D(tex, 1, GL_RGBA8, w, h);
  glCreateFramebuffers(1, &fbo);
  glNamedFramebufferTexture(fbo, GL_COLOR_ATTACHMENT0, tex, 0);
  EXPECT_EQ(glCheckNamedFramebufferStatus(fbo, GL_FRAMEBUFFER), GLenum(GL_FRAMEBUFFER_COMPLETE));
  const float colour[4] = {r / 255.0f, g / 255.0f, b / 255.0f, 1.0f};
  glClearNamedFramebufferfv(fbo, GL_COLOR, 0, colour);
  std::vector<unsigned char> px(std::size_t(w) * std::size_t(h) * 4);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, w, h, GL_RGBA, GL_UNSIGNED_BYTE, px.data());
  glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
  glDeleteFramebuffers(1, &fbo);
  glDeleteTextures(1, &tex);
  int wrong = 0;
  for (std::size_t i = 0; i < px.size(); i += 4)
    if (px[i] != r || px[i + 1] != g || px[i + 2] != b || px[i + 3] != 255) ++wrong;
  return wrong;
}

TEST(GlEgl, WithoutADisplayAHiddenContextComesFromEgl) {
  ASSERT_EQ(std::getenv("DISPLAY"), nullptr) << "this test runs with DISPLAY unset";
  ASSERT_EQ(std::getenv("VTS_GL"), nullptr);
  auto c = GlContext::create(headless(GlBackend::automatic));
  ASSERT_TRUE(c) << c.error().to_string();
  EXPECT_EQ((*c)->info().backend.rfind("egl-", 0), 0u) << (*c)->info().backend;
  EXPECT_EQ((*c)->window(), nullptr);
  auto resolved = vts::renderer::resolve_gl_backend(headless(GlBackend::automatic));
  ASSERT_TRUE(resolved);
  EXPECT_EQ(*resolved, GlBackend::egl);
}

TEST(GlEgl, EachPlatformGivesAnOpenGl45CoreContextThatRendersIntoFramebufferObjects) {
  for (GlBackend b : {GlBackend::egl_device, GlBackend::egl_surfaceless, GlBackend::egl}) {
    SCOPED_TRACE(vts::renderer::gl_backend_name(b));
    auto c = GlContext::create(headless(b, 48, 20));
    ASSERT_TRUE(c) << c.error().to_string();
    const auto& info = (*c)->info();
    EXPECT_GE(info.version, 45) << info.version_text;
    EXPECT_FALSE(info.renderer.empty());
    if (b != GlBackend::egl) {
      EXPECT_EQ(info.backend, vts::renderer::gl_backend_name(b));
    }
    GLint profile = 0;
    glGetIntegerv(GL_CONTEXT_PROFILE_MASK, &profile);
    EXPECT_TRUE(profile & GL_CONTEXT_CORE_PROFILE_BIT) << "not a core profile context";
    int w = 0, h = 0;
    (*c)->framebuffer_size(w, h);  // no default framebuffer: the size asked for
    EXPECT_EQ(w, 48);
    EXPECT_EQ(h, 20);
    EXPECT_FALSE((*c)->should_close());
    (*c)->swap_buffers();  // nothing to swap, nothing to poll: no-ops
    (*c)->poll_events();
    EXPECT_EQ(fbo_clear_mismatches(48, 20, 10, 200, 30), 0);
    EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
  }
}

// What this machine's EGL offers (Mesa: one software device) is what the device platform picks
// when it has no hardware device and is asked for the device platform alone; the report names it.
TEST(GlEgl, TheDevicePlatformEnumeratesAndNamesTheDeviceItUses) {
  auto c = GlContext::create(headless(GlBackend::egl_device));
  ASSERT_TRUE(c) << c.error().to_string();
  const std::string& d = (*c)->info().device;
  EXPECT_EQ(d.rfind("device 0 of ", 0), 0u) << d;
  EXPECT_NE(d.find("EGL_"), std::string::npos) << "the device's extensions: " << d;

  auto by_index = GlContext::create([] {
    auto o = headless(GlBackend::egl_device);
    o.egl_device = 0;
    return o;
  }());
  ASSERT_TRUE(by_index) << by_index.error().to_string();
  EXPECT_EQ((*by_index)->info().device, d);
}

TEST(GlEgl, RefusalsNameWhatIsWrong) {
  auto visible = headless(GlBackend::egl);
  visible.visible = true;
  auto v = GlContext::create(visible);
  ASSERT_FALSE(v);
  EXPECT_EQ(v.error().code, vts::ErrorCode::invalid_argument);
  EXPECT_NE(v.error().message.find("GLFW"), std::string::npos) << v.error().message;

  auto far = headless(GlBackend::egl_device);
  far.egl_device = 99;
  auto f = GlContext::create(far);
  ASSERT_FALSE(f);
  EXPECT_NE(f.error().message.find("EGL lists"), std::string::npos) << f.error().message;
  {
    ScopedEnv env("VTS_GL", "vulkan");
    auto e = GlContext::create(headless(GlBackend::automatic));
    ASSERT_FALSE(e);
    EXPECT_NE(e.error().message.find("VTS_GL=vulkan"), std::string::npos) << e.error().message;
  }
  {
    ScopedEnv env("VTS_EGL_DEVICE", "first");
    auto e = GlContext::create(headless(GlBackend::egl_device));
    ASSERT_FALSE(e);
    EXPECT_NE(e.error().message.find("VTS_EGL_DEVICE=first"), std::string::npos)
        << e.error().message;
  }
  {  // the environment picks the backend when the options leave it automatic
    ScopedEnv env("VTS_GL", "egl-surfaceless");
    auto e = GlContext::create(headless(GlBackend::automatic));
    ASSERT_TRUE(e) << e.error().to_string();
    EXPECT_EQ((*e)->info().backend, "egl-surfaceless");
  }
  {  // GLFW asked for with no display: GLFW's error, which says what to do
    auto e = GlContext::create(headless(GlBackend::glfw));
    ASSERT_FALSE(e);
    EXPECT_NE(e.error().message.find("VTS_GL=egl"), std::string::npos) << e.error().message;
  }
}

TEST(GlEgl, ContextsShareADisplayAndCloseInAnyOrder) {
  auto a = GlContext::create(headless(GlBackend::egl_surfaceless));
  ASSERT_TRUE(a) << a.error().to_string();
  auto b = GlContext::create(headless(GlBackend::egl_surfaceless, 32, 16));
  ASSERT_TRUE(b) << b.error().to_string();
  a->reset();  // the display must stay initialised for b
  (*b)->make_current();
  EXPECT_TRUE(GlContext::any_current());
  EXPECT_EQ(fbo_clear_mismatches(32, 16, 1, 2, 3), 0);
  GlContext::release_current();
  EXPECT_FALSE(GlContext::any_current());
  (*b)->make_current();
  EXPECT_TRUE(GlContext::any_current());
  b->reset();
  EXPECT_FALSE(GlContext::any_current());
  auto again = GlContext::create(headless(GlBackend::egl_surfaceless));
  ASSERT_TRUE(again) << again.error().to_string();
  EXPECT_EQ(fbo_clear_mismatches(8, 8, 255, 0, 128), 0);
}

// The headless viewer on each EGL platform converges to the same frame (both are llvmpipe here;
// tests/gl/egl_headless.sh compares EGL with GLFW under Xvfb).
class GlEglViewer : public vts::test::VirtualTextureFixture {
 protected:
  vts::renderer::Image converged(GlBackend backend) {
    using namespace vts::renderer;
    const auto path = archive("egl", 64, 4, vts::SyntheticSpec{600, 400, std::nullopt, 6});
    auto src = vts::client::open_local_archive(path);
    EXPECT_TRUE(src.ok());
    if (!src.ok()) return {};
    auto tiles = vts::client::TileClient::create(std::shared_ptr(std::move(*src)));
    EXPECT_TRUE(tiles.ok());
    if (!tiles.ok()) return {};
    const vts::Geometry g = (*tiles)->info().info.geometry;
    ViewerOptions o;
    o.window = headless(backend, 160, 100);
    o.window.debug = false;
    o.camera = default_camera(g, 160, 100);
    o.camera.plane.tilt = 0.8;  // several levels on screen
    auto v = Viewer::create(std::shared_ptr(std::move(*tiles)), g, std::move(o),
                            [](const std::string&) {});
    EXPECT_TRUE(v.ok()) << v.error().to_string();
    if (!v.ok()) return {};
    EXPECT_EQ((*v)->context().info().backend, gl_backend_name(backend));
    auto run = (*v)->run_headless(400, true);
    EXPECT_TRUE(run.ok() && run->complete_at) << (run.ok() ? "never complete" : "run failed");
    auto shot = (*v)->screenshot();
    EXPECT_TRUE(shot.ok());
    return shot.ok() ? std::move(*shot) : vts::renderer::Image{};
  }
};

TEST_F(GlEglViewer, DeviceAndSurfacelessPlatformsDrawTheSameFrame) {
  const auto device = converged(GlBackend::egl_device);
  const auto surfaceless = converged(GlBackend::egl_surfaceless);
  gl_->make_current();
  ASSERT_EQ(device.width, 160);
  ASSERT_EQ(device.height, 100);
  EXPECT_EQ(magenta(device), 0);
  // The same frame: at most 0.1% of the values differ, by one 8-bit step at most (the
  // run-to-run spread of a converged frame on llvmpipe; mostly there is none).
  ASSERT_EQ(device.rgba.size(), surfaceless.rgba.size());
  int differ = 0, worst = 0;
  for (std::size_t i = 0; i < device.rgba.size(); ++i) {
    const int d = std::abs(int(device.rgba[i]) - int(surfaceless.rgba[i]));
    differ += d > 0 ? 1 : 0;
    worst = std::max(worst, d);
  }
  EXPECT_LE(worst, 1);
  EXPECT_LE(differ, int(device.rgba.size() / 1000));
  // Not a blank frame: the synthetic image's texels are on screen.
  int lit = 0;
  for (std::size_t i = 0; i < device.rgba.size(); i += 4)
    lit += device.rgba[i] + device.rgba[i + 1] + device.rgba[i + 2] > 0 ? 1 : 0;
  EXPECT_GT(lit, 160 * 100 / 4);
}

}  // namespace
