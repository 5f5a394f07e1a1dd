// GL tests run under Xvfb with Mesa llvmpipe (tests/CMakeLists.txt wraps them in xvfb-run): the
// real driver CI has. GlNoDisplay runs in its own ctest entry with DISPLAY unset; these tests run
// again with no display on an EGL context (gl.egl_without_display, test_gl_egl.cpp).
#include <epoxy/gl.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "gl_fixture.hpp"
#include "vts/renderer/gl_context.hpp"

namespace {

using vts::renderer::GlContext;
using vts::renderer::GlContextOptions;

GlContextOptions hidden(int w = 64, int h = 64) {
  return vts::test::hidden_options(w, h);
}

GLuint compile(GLenum type, const char* source) {
  const GLuint s = glCreateShader(type);
  glShaderSource(s, 1, &source, nullptr);
  glCompileShader(s);
  GLint ok = 0;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[2048] = {};
    glGetShaderInfoLog(s, sizeof log, nullptr, log);
    ADD_FAILURE() << "shader does not compile: " << log;
  }
  return s;
}

TEST(GlContext, OpensAHiddenOpenGl45CoreContext) {
  auto c = GlContext::create(hidden());
  ASSERT_TRUE(c) << c.error().to_string();
  const auto& info = (*c)->info();
  EXPECT_GE(info.version, 45) << info.version_text;
  EXPECT_FALSE(info.renderer.empty());
  GLint profile = 0;
  glGetIntegerv(GL_CONTEXT_PROFILE_MASK, &profile);
  EXPECT_TRUE(profile & GL_CONTEXT_CORE_PROFILE_BIT) << "not a core profile context";
  int w = 0, h = 0;
  (*c)->framebuffer_size(w, h);
  EXPECT_EQ(w, 64);
  EXPECT_EQ(h, 64);
}

// The whole path the viewer's feedback pass uses: a shader draws into an offscreen RGBA8 target,
// the pixels go into a pixel-pack buffer, a fence says when they are there, and the mapped bytes
// are exactly what the shader wrote (k/255 values survive 8-bit storage unchanged).
TEST(GlContext, ShaderOutputComesBackExactlyThroughAPixelBufferAndAFence) {
  auto c = GlContext::create(hidden());
  ASSERT_TRUE(c) << c.error().to_string();
  constexpr int kW = 37, kH = 19;  // odd sizes: no row padding assumptions
  GLuint tex = 0, fbo = 0, vao = 0, pbo = 0;
  glCreateTextures(GL_TEXTURE_2D, 1, &tex);
  glTextureStorage2D(tex, 1, GL_RGBA8, kW, kH);
  glCreateFramebuffers(1, &fbo);
  glNamedFramebufferTexture(fbo, GL_COLOR_ATTACHMENT0, tex, 0);
  ASSERT_EQ(glCheckNamedFramebufferStatus(fbo, GL_FRAMEBUFFER), GLenum(GL_FRAMEBUFFER_COMPLETE));

  const GLuint vs = compile(GL_VERTEX_SHADER, R"(#version 450 core
    void main() {  // one triangle covering the viewport
      vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
      gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
    })");
  const GLuint fs = compile(GL_FRAGMENT_SHADER, R"(#version 450 core
    out vec4 color;
    void main() {
      ivec2 p = ivec2(gl_FragCoord.xy);
      color = vec4(float(p.x) / 255.0, float(p.y) / 255.0, float(p.x + p.y) / 255.0, 1.0);
    })");
  const GLuint prog = glCreateProgram();
  glAttachShader(prog, vs);
  glAttachShader(prog, fs);
  glLinkProgram(prog);
  GLint linked = 0;
  glGetProgramiv(prog, GL_LINK_STATUS, &linked);
  ASSERT_TRUE(linked);

  glCreateVertexArrays(1, &vao);
  glBindFramebuffer(GL_FRAMEBUFFER, fbo);
  glViewport(0, 0, kW, kH);
  glUseProgram(prog);
  glBindVertexArray(vao);
  glDrawArrays(GL_TRIANGLES, 0, 3);

  glCreateBuffers(1, &pbo);
  glNamedBufferStorage(pbo, kW * kH * 4, nullptr, GL_MAP_READ_BIT);
  glBindBuffer(GL_PIXEL_PACK_BUFFER, pbo);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, kW, kH, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);  // into the PBO: no stall
  GLsync fence = glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
  ASSERT_NE(fence, nullptr);
  const GLenum waited = glClientWaitSync(fence, GL_SYNC_FLUSH_COMMANDS_BIT, 5'000'000'000ull);
  ASSERT_TRUE(waited == GL_ALREADY_SIGNALED || waited == GL_CONDITION_SATISFIED);
  glDeleteSync(fence);
  const auto* px = static_cast<const unsigned char*>(
      glMapNamedBufferRange(pbo, 0, kW * kH * 4, GL_MAP_READ_BIT));
  ASSERT_NE(px, nullptr);
  int wrong = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const unsigned char* p = px + (y * kW + x) * 4;
      if (p[0] != x || p[1] != y || p[2] != x + y || p[3] != 255) ++wrong;
    }
  glUnmapNamedBuffer(pbo);
  EXPECT_EQ(wrong, 0) << "pixels differ from what the shader wrote";
  EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));

  glDeleteBuffers(1, &pbo);
  glDeleteVertexArrays(1, &vao);
  glDeleteProgram(prog);
  glDeleteShader(vs);
  glDeleteShader(fs);
  glDeleteFramebuffers(1, &fbo);
  glDeleteTextures(1, &tex);
}

TEST(GlContext, TwoContextsCanLiveAtOnceAndCloseInAnyOrder) {
  auto a = GlContext::create(hidden());
  ASSERT_TRUE(a) << a.error().to_string();
  auto b = GlContext::create(hidden(32, 16));
  ASSERT_TRUE(b) << b.error().to_string();
  a->reset();  // GLFW must stay up for b
  (*b)->make_current();
  int w = 0, h = 0;
  (*b)->framebuffer_size(w, h);
  EXPECT_EQ(w, 32);
  EXPECT_EQ(h, 16);
  b->reset();
  auto again = GlContext::create(hidden());  // and come back after the last one closed
  EXPECT_TRUE(again) << again.error().to_string();
}

TEST(GlContext, RejectsANonPositiveSize) {
  auto c = GlContext::create(hidden(0, 10));
  ASSERT_FALSE(c);
  EXPECT_EQ(c.error().code, vts::ErrorCode::invalid_argument);
}

// Run with DISPLAY unset: GLFW's error must say what is missing and what to do, not crash (a
// hidden context left to choose comes from EGL there: test_gl_egl.cpp).
TEST(GlNoDisplay, CreatingAGlfwContextFailsWithAClearMessage) {
  ASSERT_EQ(std::getenv("DISPLAY"), nullptr) << "this test runs with DISPLAY unset";
  auto o = hidden();
  o.backend = vts::renderer::GlBackend::glfw;
  auto c = GlContext::create(o);
  ASSERT_FALSE(c);
  EXPECT_NE(c.error().message.find("xvfb-run"), std::string::npos) << c.error().message;
  EXPECT_NE(c.error().message.find("DISPLAY"), std::string::npos) << c.error().message;
  EXPECT_NE(c.error().message.find("VTS_GL=egl"), std::string::npos) << c.error().message;
}

// A visible window is GLFW's whatever the display: with none, the same clear error.
TEST(GlNoDisplay, AVisibleWindowWithoutADisplayFailsWithAClearMessage) {
  auto o = hidden();
  o.visible = true;
  auto c = GlContext::create(o);
  ASSERT_FALSE(c);
  EXPECT_NE(c.error().message.find("xvfb-run"), std::string::npos) << c.error().message;
}

}  // namespace
