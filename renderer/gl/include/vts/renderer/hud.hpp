// The viewer's heads-up display: lines of text (stb_easy_font glyphs, no font file or texture)
// over a translucent dark box in the top-left corner of a frame, drawn into a framebuffer with
// draw() or over a CPU image with draw_onto() (docs/RENDERER.md, "HUD and keys").
//
// Colours are written as given, in the framebuffer's encoding (GL_FRAMEBUFFER_SRGB is off while
// the HUD draws): the box is kBoxColor blended over the frame, the text kTextColor, opaque.
// Text: printable ASCII only (any other byte, UTF-8 included, is drawn as '?'); at most kMaxLines
// lines of kMaxLineChars characters, the rest cut off.
//
// Thread safety: GL-thread only; create, use and destroy a Hud with its GL context current.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/renderer/reference.hpp"

namespace vts::renderer {

// Where the HUD's box lies, in pixels from the frame's top-left corner (x right, y down); the box
// covers [x, x + width) x [y, y + height). Nothing outside it is ever written.
struct HudBox {
  int x = 0, y = 0, width = 0, height = 0;
};

class Hud {
 public:
  static constexpr std::array<std::uint8_t, 4> kBoxColor = {0, 0, 0, 160};  // straight alpha
  static constexpr std::array<std::uint8_t, 4> kTextColor = {255, 255, 255, 255};
  static constexpr std::size_t kMaxLines = 32;
  static constexpr std::size_t kMaxLineChars = 160;
  static constexpr float kMaxScale = 64;

  // Needs a current GL 4.5 core context. Errors (unsupported): a shader the driver refused, with
  // its log.
  static Result<std::unique_ptr<Hud>> create();
  ~Hud();
  Hud(const Hud&) = delete;
  Hud& operator=(const Hud&) = delete;

  // The box `lines` take at `scale` (glyph units to pixels; 1 = stb_easy_font's native ~12 px
  // lines, an integer keeps glyph edges on pixel edges): a margin, then the text's bounding box
  // plus padding. Pure CPU arithmetic; an empty `lines` or a scale outside (0, kMaxScale] gives
  // an empty box.
  static HudBox measure(const std::vector<std::string>& lines, float scale = 1);

  // Draws `lines` into `framebuffer` (a GL framebuffer name, 0 = the window's) whose size is
  // width x height pixels, the box at measure(lines, scale), clipped to the frame. GL state it
  // changes (framebuffer bindings, viewport, program, vertex array, blending, sRGB encoding,
  // depth/scissor/cull tests) is restored before it returns. Errors (invalid_argument, and then
  // no GL call is made): width or height < 1, scale outside (0, kMaxScale]. No lines: nothing
  // drawn, not an error.
  Status draw(const std::vector<std::string>& lines, int width, int height, float scale = 1,
              unsigned framebuffer = 0);

  // Draws `lines` over `image` (sRGB RGBA8, rows top to bottom) in place. Errors
  // (invalid_argument, the image unchanged): an empty image, one whose pixel buffer does not
  // match its size, one larger than GL_MAX_TEXTURE_SIZE, a bad scale as for draw().
  Status draw_onto(Image& image, const std::vector<std::string>& lines, float scale = 1);

 private:
  class Impl;
  std::unique_ptr<Impl> impl_;
  explicit Hud(std::unique_ptr<Impl> impl);
};

}  // namespace vts::renderer
