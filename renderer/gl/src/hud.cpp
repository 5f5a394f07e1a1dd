// The viewer's HUD: stb_easy_font quads in a tiny GL program (hud.hpp).
#include "vts/renderer/hud.hpp"

#include <epoxy/gl.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

// stb_easy_font is a header of static functions; the viewer uses only some of them.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wsign-compare"
#include <stb/stb_easy_font.h>
#pragma GCC diagnostic pop

#include "vts/renderer/gl_check.hpp"
#include "vts/renderer/gl_handle.hpp"
#include "vts/renderer/gl_program.hpp"

namespace vts::renderer {
namespace {

// Glyph units (stb_easy_font's pixels at scale 1).
constexpr float kLineStep = 12;       // stb_easy_font's line advance
constexpr float kGlyphHeight = 9;     // every printable glyph lies in rows [0, 9] of its line
constexpr float kMargin = 8;          // frame edge to box
constexpr float kPadding = 4;         // box edge to text
constexpr int kMaxQuadsPerChar = 12;  // the busiest glyph has 11
constexpr int kStbVertexBytes = 16;   // x, y, z floats + RGBA8

struct Vertex {
  float x, y;  // pixels from the frame's top-left corner
  std::uint8_t rgba[4];
};
static_assert(sizeof(Vertex) == 12);

const char* kVertexShader = R"(#version 450 core
layout(location = 0) in vec2 a_pos;
layout(location = 1) in vec4 a_color;
uniform vec2 u_size;
out vec4 v_color;
void main() {
  v_color = a_color;
  gl_Position = vec4(a_pos.x / u_size.x * 2.0 - 1.0, 1.0 - a_pos.y / u_size.y * 2.0, 0.0, 1.0);
}
)";

const char* kFragmentShader = R"(#version 450 core
in vec4 v_color;
out vec4 o_color;
void main() { o_color = v_color; }
)";

bool good_scale(float scale) {
  return scale > 0 && scale <= Hud::kMaxScale;  // false for NaN too
}

// One line as stb_easy_font may read it: its glyph table covers 32..126 only.
std::string printable(const std::string& line) {
  std::string s = line.substr(0, std::min(line.size(), Hud::kMaxLineChars));
  for (char& c : s) {
    if (c < 32 || c > 126) c = '?';
  }
  return s;
}

struct Layout {
  HudBox box;
  std::vector<Vertex> vertices;  // triangles: the box, then the glyph quads
};

void push_rect(std::vector<Vertex>& out, float x0, float y0, float x1, float y1,
               const std::array<std::uint8_t, 4>& c) {
  const Vertex a{x0, y0, {c[0], c[1], c[2], c[3]}}, b{x1, y0, {c[0], c[1], c[2], c[3]}},
      d{x1, y1, {c[0], c[1], c[2], c[3]}}, e{x0, y1, {c[0], c[1], c[2], c[3]}};
  out.insert(out.end(), {a, b, d, a, d, e});
}

Layout layout(const std::vector<std::string>& lines, float scale, bool with_vertices) {
  Layout l;
  const std::size_t n = std::min(lines.size(), Hud::kMaxLines);
  if (n == 0 || !good_scale(scale)) return l;
  std::vector<std::string> text(n);
  int text_w = 0;
  for (std::size_t i = 0; i < n; ++i) {
    text[i] = printable(lines[i]);
    text_w = std::max(text_w, stb_easy_font_width(text[i].data()));
  }
  const float text_h = kLineStep * float(n - 1) + kGlyphHeight;
  const float margin = std::round(kMargin * scale), pad = std::round(kPadding * scale);
  l.box.x = int(margin);
  l.box.y = int(margin);
  l.box.width = int(std::ceil(2 * pad + float(text_w) * scale));
  l.box.height = int(std::ceil(2 * pad + text_h * scale));
  if (!with_vertices) return l;

  const float x0 = float(l.box.x), y0 = float(l.box.y);
  push_rect(l.vertices, x0, y0, x0 + float(l.box.width), y0 + float(l.box.height), Hud::kBoxColor);
  const float ox = x0 + pad, oy = y0 + pad;
  std::vector<char> quads;
  for (std::size_t i = 0; i < n; ++i) {
    quads.resize(std::max<std::size_t>(text[i].size(), 1) * kMaxQuadsPerChar * 4 * kStbVertexBytes);
    const int count = stb_easy_font_print(0, kLineStep * float(i), text[i].data(), nullptr,
                                          quads.data(), int(quads.size()));
    for (int q = 0; q < count; ++q) {
      // A quad's four corners in order (x, y0) (x1, y0) (x1, y1) (x, y1): corners 0 and 2 suffice.
      float a[2], b[2];
      std::memcpy(a, quads.data() + std::size_t(q) * 4 * kStbVertexBytes, sizeof a);
      std::memcpy(b, quads.data() + (std::size_t(q) * 4 + 2) * kStbVertexBytes, sizeof b);
      push_rect(l.vertices, ox + a[0] * scale, oy + a[1] * scale, ox + b[0] * scale,
                oy + b[1] * scale, Hud::kTextColor);
    }
  }
  return l;
}

// Every piece of GL state draw() changes, captured on entry and put back on exit.
class SavedState {
 public:
  SavedState() {
    glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &draw_fbo_);
    glGetIntegerv(GL_VIEWPORT, viewport_);
    glGetIntegerv(GL_CURRENT_PROGRAM, &program_);
    // A program deleted while current lives only until it is replaced: it cannot come back.
    if (program_ != 0) {
      GLint deleted = GL_FALSE;
      glGetProgramiv(GLuint(program_), GL_DELETE_STATUS, &deleted);
      if (deleted) program_ = 0;
    }
    glGetIntegerv(GL_VERTEX_ARRAY_BINDING, &vao_);
    glGetIntegerv(GL_BLEND_SRC_RGB, &blend_[0]);
    glGetIntegerv(GL_BLEND_DST_RGB, &blend_[1]);
    glGetIntegerv(GL_BLEND_SRC_ALPHA, &blend_[2]);
    glGetIntegerv(GL_BLEND_DST_ALPHA, &blend_[3]);
    glGetIntegerv(GL_BLEND_EQUATION_RGB, &equation_[0]);
    glGetIntegerv(GL_BLEND_EQUATION_ALPHA, &equation_[1]);
    for (std::size_t i = 0; i < std::size(kCaps); ++i) enabled_[i] = glIsEnabled(kCaps[i]);
  }
  ~SavedState() {
    for (std::size_t i = 0; i < std::size(kCaps); ++i) {
      if (enabled_[i]) {
        glEnable(kCaps[i]);
      } else {
        glDisable(kCaps[i]);
      }
    }
    glBlendEquationSeparate(GLenum(equation_[0]), GLenum(equation_[1]));
    glBlendFuncSeparate(GLenum(blend_[0]), GLenum(blend_[1]), GLenum(blend_[2]), GLenum(blend_[3]));
    glBindVertexArray(GLuint(vao_));
    glUseProgram(GLuint(program_));
    glViewport(viewport_[0], viewport_[1], viewport_[2], viewport_[3]);
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, GLuint(draw_fbo_));
  }
  SavedState(const SavedState&) = delete;
  SavedState& operator=(const SavedState&) = delete;

 private:
  static constexpr GLenum kCaps[] = {GL_BLEND,        GL_FRAMEBUFFER_SRGB, GL_DEPTH_TEST,
                                     GL_SCISSOR_TEST, GL_STENCIL_TEST,     GL_CULL_FACE};
  GLint draw_fbo_ = 0, viewport_[4] = {}, program_ = 0, vao_ = 0, blend_[4] = {}, equation_[2] = {};
  GLboolean enabled_[std::size(kCaps)] = {};
};

}  // namespace

class Hud::Impl {
 public:
  Status init() {
    auto program = link_program(kVertexShader, kFragmentShader, "HUD");
    if (!program) return program.error();
    program_ = std::move(*program);
    size_loc_ = glGetUniformLocation(program_.get(), "u_size");

    glCreateBuffers(1, vbo_.out());
    glCreateVertexArrays(1, vao_.out());
    glVertexArrayVertexBuffer(vao_.get(), 0, vbo_.get(), 0, sizeof(Vertex));
    glEnableVertexArrayAttrib(vao_.get(), 0);
    glVertexArrayAttribFormat(vao_.get(), 0, 2, GL_FLOAT, GL_FALSE, offsetof(Vertex, x));
    glVertexArrayAttribBinding(vao_.get(), 0, 0);
    glEnableVertexArrayAttrib(vao_.get(), 1);
    glVertexArrayAttribFormat(vao_.get(), 1, 4, GL_UNSIGNED_BYTE, GL_TRUE, offsetof(Vertex, rgba));
    glVertexArrayAttribBinding(vao_.get(), 1, 0);
    return {};
  }

  Status draw(const std::vector<std::string>& lines, int width, int height, float scale,
              GLuint framebuffer) {
    if (width < 1 || height < 1) {
      return make_error(ErrorCode::invalid_argument, "HUD: a " + std::to_string(width) + " x " +
                                                         std::to_string(height) +
                                                         " frame has no pixels to draw on");
    }
    if (!good_scale(scale)) {
      return make_error(ErrorCode::invalid_argument, "HUD: scale " + std::to_string(scale) +
                                                         " is outside (0, " +
                                                         std::to_string(int(Hud::kMaxScale)) + "]");
    }
    const Layout l = layout(lines, scale, true);
    if (l.vertices.empty()) return {};

    SavedState saved;
    glNamedBufferData(vbo_.get(), GLsizeiptr(l.vertices.size() * sizeof(Vertex)), l.vertices.data(),
                      GL_STREAM_DRAW);
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, framebuffer);
    glViewport(0, 0, width, height);
    // Colours are already in the framebuffer's encoding: no sRGB conversion, no tests.
    glDisable(GL_FRAMEBUFFER_SRGB);
    glDisable(GL_DEPTH_TEST);
    glDisable(GL_SCISSOR_TEST);
    glDisable(GL_STENCIL_TEST);
    glDisable(GL_CULL_FACE);
    glEnable(GL_BLEND);
    glBlendEquation(GL_FUNC_ADD);
    glBlendFuncSeparate(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA, GL_ONE, GL_ONE_MINUS_SRC_ALPHA);
    glUseProgram(program_.get());
    glUniform2f(size_loc_, float(width), float(height));
    glBindVertexArray(vao_.get());
    glDrawArrays(GL_TRIANGLES, 0, GLsizei(l.vertices.size()));
    return {};
  }

  Status draw_onto(Image& image, const std::vector<std::string>& lines, float scale) {
    if (image.width < 1 || image.height < 1 ||
        image.rgba.size() != std::size_t(image.width) * std::size_t(image.height) * 4) {
      return make_error(ErrorCode::invalid_argument,
                        "HUD: the image (" + std::to_string(image.width) + " x " +
                            std::to_string(image.height) + ", " +
                            std::to_string(image.rgba.size()) + " bytes) is empty or malformed");
    }
    if (!good_scale(scale)) {
      return make_error(ErrorCode::invalid_argument, "HUD: scale " + std::to_string(scale) +
                                                         " is outside (0, " +
                                                         std::to_string(int(Hud::kMaxScale)) + "]");
    }
    GLint max_size = 0;
    glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
    if (image.width > max_size || image.height > max_size) {
      return make_error(ErrorCode::invalid_argument, "HUD: a " + std::to_string(image.width) +
                                                         " x " + std::to_string(image.height) +
                                                         " image is above GL_MAX_TEXTURE_SIZE " +
                                                         std::to_string(max_size));
    }
    if (layout(lines, scale, false).box.width == 0) return {};

    if (image.width != image_w_ || image.height != image_h_) {
      image_fbo_.reset();
      glCreateTextures(GL_TEXTURE_2D, 1, image_tex_.out());
      glTextureStorage2D(image_tex_.get(), 1, GL_RGBA8, image.width, image.height);
      glCreateFramebuffers(1, image_fbo_.out());
      glNamedFramebufferTexture(image_fbo_.get(), GL_COLOR_ATTACHMENT0, image_tex_.get(), 0);
      image_w_ = image.width;
      image_h_ = image.height;
    }

    // Rows go bottom to top in GL: flip on the way in and on the way out. A pixel buffer left
    // bound by someone else would turn the pointers below into offsets: unbind, then restore.
    GLint unpack_buffer = 0, pack_buffer = 0, unpack_align = 4, pack_align = 4;
    glGetIntegerv(GL_PIXEL_UNPACK_BUFFER_BINDING, &unpack_buffer);
    glGetIntegerv(GL_PIXEL_PACK_BUFFER_BINDING, &pack_buffer);
    glGetIntegerv(GL_UNPACK_ALIGNMENT, &unpack_align);
    glGetIntegerv(GL_PACK_ALIGNMENT, &pack_align);
    glBindBuffer(GL_PIXEL_UNPACK_BUFFER, 0);
    glBindBuffer(GL_PIXEL_PACK_BUFFER, 0);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);

    const std::size_t row = std::size_t(image.width) * 4;
    std::vector<std::uint8_t> flipped(image.rgba.size());
    auto flip = [&](const std::uint8_t* from, std::uint8_t* to) {
      for (int y = 0; y < image.height; ++y)
        std::memcpy(to + std::size_t(y) * row, from + std::size_t(image.height - 1 - y) * row, row);
    };
    flip(image.rgba.data(), flipped.data());
    glTextureSubImage2D(image_tex_.get(), 0, 0, 0, image.width, image.height, GL_RGBA,
                        GL_UNSIGNED_BYTE, flipped.data());
    Status drawn = draw(lines, image.width, image.height, scale, image_fbo_.get());
    if (drawn) {
      glGetTextureImage(image_tex_.get(), 0, GL_RGBA, GL_UNSIGNED_BYTE, GLsizei(flipped.size()),
                        flipped.data());
      flip(flipped.data(), image.rgba.data());
    }

    glPixelStorei(GL_UNPACK_ALIGNMENT, unpack_align);
    glPixelStorei(GL_PACK_ALIGNMENT, pack_align);
    glBindBuffer(GL_PIXEL_UNPACK_BUFFER, GLuint(unpack_buffer));
    glBindBuffer(GL_PIXEL_PACK_BUFFER, GLuint(pack_buffer));
    return drawn;
  }

 private:
  GlProgram program_;
  GlBuffer vbo_;
  GlVertexArray vao_;
  GLint size_loc_ = -1;
  GlTexture image_tex_;  // draw_onto()'s target, kept while the size holds
  GlFramebuffer image_fbo_;
  int image_w_ = 0, image_h_ = 0;
};

Hud::Hud(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Hud::~Hud() = default;

Result<std::unique_ptr<Hud>> Hud::create() {
  VTS_GL_CALL_SITE("Hud::create");
  auto impl = std::make_unique<Impl>();
  if (auto s = impl->init(); !s) return s.error();
  return std::unique_ptr<Hud>(new Hud(std::move(impl)));
}

HudBox Hud::measure(const std::vector<std::string>& lines, float scale) {
  return layout(lines, scale, false).box;
}

Status Hud::draw(const std::vector<std::string>& lines, int width, int height, float scale,
                 unsigned framebuffer) {
  VTS_GL_CALL_SITE("Hud::draw");
  return impl_->draw(lines, width, height, scale, GLuint(framebuffer));
}

Status Hud::draw_onto(Image& image, const std::vector<std::string>& lines, float scale) {
  VTS_GL_CALL_SITE("Hud::draw_onto");
  return impl_->draw_onto(image, lines, scale);
}

}  // namespace vts::renderer
