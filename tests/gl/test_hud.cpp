// The viewer's HUD (renderer/gl/include/vts/renderer/hud.hpp) under Mesa llvmpipe: known text on a
// known background, read back pixel by pixel.
#include "vts/renderer/hud.hpp"

#include <epoxy/gl.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <limits>
#include <string>
#include <vector>

#include "gl_fixture.hpp"

namespace {

using vts::renderer::Hud;
using vts::renderer::HudBox;
using vts::renderer::Image;

constexpr std::uint8_t kBg[4] = {40, 120, 200, 255};

// An offscreen RGBA8 target cleared to kBg.
struct Target {
  GLuint tex = 0, fbo = 0;
  int width, height;
  Target(int w, int h) : width(w), height(h) {
    glCreateTextures(GL_TEXTURE_2D, 1, &tex);
    glTextureStorage2D(tex, 1, GL_RGBA8, w, h);
    glCreateFramebuffers(1, &fbo);
    glNamedFramebufferTexture(fbo, GL_COLOR_ATTACHMENT0, tex, 0);
    const float c[4] = {kBg[0] / 255.f, kBg[1] / 255.f, kBg[2] / 255.f, kBg[3] / 255.f};
    glClearNamedFramebufferfv(fbo, GL_COLOR, 0, c);
  }
  ~Target() {
    glDeleteFramebuffers(1, &fbo);
    glDeleteTextures(1, &tex);
  }
  // Rows top to bottom, as the HUD's coordinates run.
  Image read() const {
    Image img = Image::blank(width, height);
    std::vector<std::uint8_t> raw(img.rgba.size());
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glGetTextureImage(tex, 0, GL_RGBA, GL_UNSIGNED_BYTE, GLsizei(raw.size()), raw.data());
    const std::size_t row = std::size_t(width) * 4;
    for (int y = 0; y < height; ++y)
      std::copy_n(raw.data() + std::size_t(height - 1 - y) * row, row, img.at(0, y));
    return img;
  }
};

bool inside(const HudBox& b, int x, int y) {
  return x >= b.x && x < b.x + b.width && y >= b.y && y < b.y + b.height;
}
bool is_text(const std::uint8_t* p) {
  return p[0] == Hud::kTextColor[0] && p[1] == Hud::kTextColor[1] && p[2] == Hud::kTextColor[2];
}
// kBoxColor blended over `under` (src-alpha, one-minus-src-alpha), within 1 of 8-bit rounding.
bool is_box_over(const std::uint8_t* p, const std::uint8_t* under) {
  const double a = Hud::kBoxColor[3] / 255.0;
  for (int c = 0; c < 3; ++c) {
    const double want = Hud::kBoxColor[c] * a + under[c] * (1 - a);
    if (std::abs(double(p[c]) - want) > 1.0) return false;
  }
  return true;
}

class HudTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string error;
    ASSERT_NE(vts::test::shared_gl_context(&error), nullptr) << error;
    while (glGetError() != GL_NO_ERROR) {
    }
    auto h = Hud::create();
    ASSERT_TRUE(h) << h.error().to_string();
    hud_ = std::move(*h);
  }
  void TearDown() override {
    hud_.reset();
    EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
  }
  std::unique_ptr<Hud> hud_;
};

const std::vector<std::string> kLines = {"resident 123 | pending 4", "hit 98.5% | bias 0.25"};

TEST_F(HudTest, DrawsTextInsideItsTopLeftBoxAndLeavesEveryOtherPixelAlone) {
  Target t(240, 120);
  const HudBox box = Hud::measure(kLines, 1);
  ASSERT_GT(box.width, 0);
  ASSERT_LT(box.x + box.width, t.width) << "the test's frame must be wider than the box";
  ASSERT_LT(box.y + box.height, t.height);
  EXPECT_LT(box.x, 16) << "top-left";
  EXPECT_LT(box.y, 16) << "top-left";

  ASSERT_TRUE(hud_->draw(kLines, t.width, t.height, 1, t.fbo));
  ASSERT_EQ(glGetError(), GLenum(GL_NO_ERROR));
  const Image img = t.read();

  int text = 0, box_px = 0, line1 = 0, line2 = 0;
  for (int y = 0; y < img.height; ++y) {
    for (int x = 0; x < img.width; ++x) {
      const std::uint8_t* p = img.at(x, y);
      if (!inside(box, x, y)) {
        ASSERT_TRUE(p[0] == kBg[0] && p[1] == kBg[1] && p[2] == kBg[2] && p[3] == kBg[3])
            << "pixel (" << x << ", " << y << ") outside the box changed";
        continue;
      }
      if (is_text(p)) {
        ++text;
        // The two lines are 12 glyph rows apart: a text pixel belongs to one of them.
        (y - box.y < box.height / 2 ? line1 : line2)++;
      } else {
        ASSERT_TRUE(is_box_over(p, kBg)) << "pixel (" << x << ", " << y << ") in the box is "
                                         << int(p[0]) << "," << int(p[1]) << "," << int(p[2]);
        ++box_px;
      }
    }
  }
  // Dozens of glyphs of a few quads each: hundreds of text pixels, and most of the box is box.
  EXPECT_GT(line1, 100);
  EXPECT_GT(line2, 100);
  EXPECT_GT(box_px, text);
  // A one-pixel frame of box colour around the text (the padding) at the box's edges.
  for (int x = box.x; x < box.x + box.width; ++x) {
    EXPECT_FALSE(is_text(img.at(x, box.y))) << x;
    EXPECT_FALSE(is_text(img.at(x, box.y + box.height - 1))) << x;
  }
}

TEST_F(HudTest, DrawsOverAnImageInPlaceTopRowsFirst) {
  // A gradient, so that any flip or shift of the untouched pixels shows.
  Image img = Image::blank(200, 90);
  for (int y = 0; y < img.height; ++y) {
    for (int x = 0; x < img.width; ++x) {
      std::uint8_t* p = img.at(x, y);
      p[0] = std::uint8_t(x);
      p[1] = std::uint8_t(y * 2);
      p[2] = std::uint8_t((x + y) & 255);
      p[3] = 255;
    }
  }
  const Image before = img;
  const HudBox box = Hud::measure(kLines, 1);
  ASSERT_TRUE(hud_->draw_onto(img, kLines, 1));
  ASSERT_EQ(img.width, before.width);
  ASSERT_EQ(img.height, before.height);
  int text = 0;
  for (int y = 0; y < img.height; ++y) {
    for (int x = 0; x < img.width; ++x) {
      const std::uint8_t *p = img.at(x, y), *q = before.at(x, y);
      if (!inside(box, x, y)) {
        ASSERT_TRUE(std::equal(p, p + 4, q)) << "pixel (" << x << ", " << y << ") changed";
      } else if (is_text(p)) {
        ++text;
      } else {
        ASSERT_TRUE(is_box_over(p, q)) << "pixel (" << x << ", " << y << ")";
        ASSERT_EQ(p[3], 255) << "an opaque screenshot stays opaque";
      }
    }
  }
  EXPECT_GT(text, 200);

  // A second image of another size: the offscreen target follows.
  Image small = Image::blank(150, 40);
  EXPECT_TRUE(hud_->draw_onto(small, {"ok"}, 1));
  EXPECT_FALSE(is_text(small.at(0, 0)));
}

TEST_F(HudTest, ScaleTwoDrawsTheSameTextTwiceAsLarge) {
  const HudBox one = Hud::measure(kLines, 1), two = Hud::measure(kLines, 2);
  EXPECT_EQ(two.x, 2 * one.x);
  EXPECT_EQ(two.width, 2 * one.width);
  EXPECT_EQ(two.height, 2 * one.height);
  Target a(240, 120), b(480, 240);
  ASSERT_TRUE(hud_->draw(kLines, a.width, a.height, 1, a.fbo));
  ASSERT_TRUE(hud_->draw(kLines, b.width, b.height, 2, b.fbo));
  const Image ia = a.read(), ib = b.read();
  // Every pixel of the scale-1 glyphs becomes a 2 x 2 block at scale 2.
  for (int y = 0; y < ia.height; ++y)
    for (int x = 0; x < ia.width; ++x)
      for (int k = 0; k < 4; ++k)
        ASSERT_EQ(is_text(ia.at(x, y)), is_text(ib.at(2 * x + (k & 1), 2 * y + (k >> 1))))
            << "(" << x << ", " << y << ")";
}

TEST_F(HudTest, RejectsAFrameWithoutPixelsOrABadScaleWithoutAnyGlError) {
  Target t(64, 32);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  struct Case {
    int w, h;
    float scale;
  };
  for (const Case& c :
       {Case{0, 32, 1}, Case{64, 0, 1}, Case{0, 0, 1}, Case{-5, 32, 1}, Case{64, 32, 0},
        Case{64, 32, -1}, Case{64, 32, nan}, Case{64, 32, inf}, Case{64, 32, Hud::kMaxScale * 2}}) {
    auto s = hud_->draw(kLines, c.w, c.h, c.scale, t.fbo);
    ASSERT_FALSE(s) << c.w << " x " << c.h << " scale " << c.scale;
    EXPECT_EQ(s.error().code, vts::ErrorCode::invalid_argument);
    EXPECT_FALSE(s.error().message.empty());
    EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
  }
  const Image img = t.read();
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) ASSERT_EQ(img.at(x, y)[0], kBg[0]);

  Image empty;
  EXPECT_FALSE(hud_->draw_onto(empty, kLines, 1));
  Image malformed = Image::blank(8, 8);
  malformed.rgba.resize(10);
  EXPECT_FALSE(hud_->draw_onto(malformed, kLines, 1));
  EXPECT_EQ(malformed.rgba.size(), 10u);
  Image fine = Image::blank(8, 8);
  EXPECT_FALSE(hud_->draw_onto(fine, kLines, 0));
  EXPECT_EQ(fine.rgba, Image::blank(8, 8).rgba);
  EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));

  // No lines: nothing drawn, and no error.
  EXPECT_TRUE(hud_->draw({}, 64, 32, 1, t.fbo));
  EXPECT_EQ(Hud::measure({}, 1).width, 0);
  EXPECT_EQ(Hud::measure(kLines, 0).width, 0);
}

TEST_F(HudTest, DrawsAnyBytesAsAsciiAndCutsOverlongText) {
  // A UTF-8 em dash (3 bytes) and control characters draw as '?', one each.
  EXPECT_EQ(Hud::measure({"a\xe2\x80\x94z\t\n"}, 1).width, Hud::measure({"a???z??"}, 1).width);
  EXPECT_EQ(Hud::measure({std::string(10000, 'W')}, 1).width,
            Hud::measure({std::string(Hud::kMaxLineChars, 'W')}, 1).width);
  const std::vector<std::string> many(1000, "x");
  EXPECT_EQ(Hud::measure(many, 1).height,
            Hud::measure(std::vector<std::string>(Hud::kMaxLines, "x"), 1).height);
  Target t(64, 64);
  EXPECT_TRUE(hud_->draw({"\x01\x7f\xff", std::string(10000, 'W')}, t.width, t.height, 1, t.fbo));
  EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
}

TEST_F(HudTest, PutsBackTheGlStateItChanged) {
  Target t(64, 64);
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, t.fbo);
  glViewport(3, 4, 20, 10);
  glEnable(GL_SCISSOR_TEST);
  glScissor(0, 0, 1, 1);
  glDisable(GL_BLEND);
  glEnable(GL_FRAMEBUFFER_SRGB);
  glBlendFunc(GL_ONE, GL_ZERO);
  glUseProgram(0);

  // Into another framebuffer than the bound one (not 0: an EGL context has no default one).
  Target other(64, 64);
  ASSERT_TRUE(hud_->draw(kLines, 64, 64, 1, other.fbo));

  GLint fbo = -1, vp[4] = {}, prog = -1, src = 0, dst = 0;
  glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &fbo);
  glGetIntegerv(GL_VIEWPORT, vp);
  glGetIntegerv(GL_CURRENT_PROGRAM, &prog);
  glGetIntegerv(GL_BLEND_SRC_RGB, &src);
  glGetIntegerv(GL_BLEND_DST_RGB, &dst);
  EXPECT_EQ(GLuint(fbo), t.fbo);
  EXPECT_EQ(vp[0], 3);
  EXPECT_EQ(vp[1], 4);
  EXPECT_EQ(vp[2], 20);
  EXPECT_EQ(vp[3], 10);
  EXPECT_EQ(prog, 0);
  EXPECT_TRUE(glIsEnabled(GL_SCISSOR_TEST));
  EXPECT_TRUE(glIsEnabled(GL_FRAMEBUFFER_SRGB));
  EXPECT_FALSE(glIsEnabled(GL_BLEND));
  EXPECT_EQ(src, GL_ONE);
  EXPECT_EQ(dst, GL_ZERO);
  // The scissor test was off for the HUD (its own state) but t.fbo was not its target: unchanged.
  const Image img = t.read();
  EXPECT_EQ(img.at(10, 10)[0], kBg[0]);

  glDisable(GL_SCISSOR_TEST);
  glDisable(GL_FRAMEBUFFER_SRGB);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  glViewport(0, 0, 64, 64);
}

// Another part of the viewer may delete its program while it is still current (GL keeps it alive
// until it is replaced). The HUD replaces it, so it cannot put it back: no error, program 0.
TEST_F(HudTest, LeavesNoProgramWhenTheCurrentOneWasDeleted) {
  const char* vs = "#version 450 core\nvoid main() { gl_Position = vec4(0.0); }\n";
  const char* fs = "#version 450 core\nout vec4 c;\nvoid main() { c = vec4(1.0); }\n";
  const GLuint v = glCreateShader(GL_VERTEX_SHADER), f = glCreateShader(GL_FRAGMENT_SHADER);
  glShaderSource(v, 1, &vs, nullptr);
  glShaderSource(f, 1, &fs, nullptr);
  glCompileShader(v);
  glCompileShader(f);
  const GLuint p = glCreateProgram();
  glAttachShader(p, v);
  glAttachShader(p, f);
  glLinkProgram(p);
  glDeleteShader(v);
  glDeleteShader(f);
  glUseProgram(p);
  glDeleteProgram(p);
  ASSERT_EQ(glGetError(), GLenum(GL_NO_ERROR));

  Target t(64, 64);
  ASSERT_TRUE(hud_->draw(kLines, t.width, t.height, 1, t.fbo));
  EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
  GLint current = -1;
  glGetIntegerv(GL_CURRENT_PROGRAM, &current);
  EXPECT_EQ(current, 0);
}

}  // namespace
