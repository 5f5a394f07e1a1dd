// Table: addressing (accuracy/include/vts/accuracy/accuracy.hpp, table 4). How precisely a pixel
// finds its finest-level texel, float32 UV against the renderer's integer + fraction scheme, at
// virtual sizes 2^15 ... 2^25, and what each costs in the shader.
//
// Both variants run as a fullscreen pass of a small dedicated shader on a plane view
// (camera.hpp) and write the finest texel each pixel addresses — integer texel + fraction bits,
// one RGBA32UI target, the same for both — and the footprint log2(rho) the level would be chosen
// from. They are read back and compared with PlaneCamera::hit() in double at each pixel centre.
//   float32 UV  the classic way: the eye and the ray in normalised [0, 1] texture space as float,
//               texel = uv * S;
//   ours        the shipped code: PlaneScene's GLSL (shaders.hpp kPlaneScene) and its uniforms
//               (PlaneScene::set_uniforms: the eye relative to the integer anchor, formed in
//               double), then the virtual-texturing shader's own lines that take the derivatives
//               and split rel into integer texel + fraction. Those lines are checked to be a
//               verbatim (whitespace-insensitive) part of the production fragment shader, so the
//               table refuses to publish figures for code that is no longer shipped.
#include <epoxy/gl.h>

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "vts/accuracy/accuracy.hpp"
#include "vts/accuracy/addressing_detail.hpp"
#include "vts/renderer/camera.hpp"
#include "vts/renderer/gl_program.hpp"
#include "vts/renderer/gl_uniforms.hpp"
#include "vts/renderer/scene.hpp"
#include "vts/renderer/shaders.hpp"

namespace vts::accuracy {

namespace detail_addressing {

std::string squeeze(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (char c : s) {
    if (c != ' ' && c != '\t' && c != '\n' && c != '\r') out.push_back(c);
  }
  return out;
}

bool production_has(std::string_view snippet) {
  return squeeze(renderer::detail::kVirtualTextureFragment).find(squeeze(snippet)) !=
         std::string::npos;
}

}  // namespace detail_addressing

namespace {

using namespace detail_addressing;
using renderer::PlaneCamera;
using renderer::PlaneView;

// Output of both passes: the finest texel (integer, fraction bits) and the footprint.
constexpr const char* kOutputs = R"(
layout(location = 0) out uvec4 o_addr;     // texel x, texel y, floatBitsToUint(fraction x, y)
layout(location = 1) out vec2 o_footprint;  // log2(rho) in finest texels per pixel, hit ? 1 : 0
)";

std::string ours_fragment() {
  return std::string("#version 450 core\nuniform vec2 u_viewport;\n") +
         renderer::detail::kPlaneScene + "uniform ivec2 u_anchor;\n" + kOutputs +
         "void main() {\n" + kOursHit + kOursDerivatives + kOursSplit +
         R"(
  // The isotropic footprint, as the production shader forms it (taps = 1).
  float rho = max(length(ddx), length(ddy));
  o_addr = uvec4(uvec2(abs_i), floatBitsToUint(fr));
  o_footprint = vec2(log2(rho), hit ? 1.0 : 0.0);
}
)";
}

// The classic way: one float coordinate over the whole texture, in [0, 1].
constexpr const char* kFloatFragment = R"(#version 450 core
uniform vec2 u_viewport;
uniform vec3 u_eye_uv;  // eye / S: normalised texture space (u right, v down, w into the ground)
uniform vec3 u_forward;
uniform vec3 u_right;
uniform vec3 u_up;
uniform float u_tan_half_fov;
uniform float u_aspect;
uniform float u_size;   // S, texels per side
layout(location = 0) out uvec4 o_addr;
layout(location = 1) out vec2 o_footprint;
void main() {
  vec2 px = vec2(gl_FragCoord.x, u_viewport.y - gl_FragCoord.y);
  float nx = (2.0 * px.x / u_viewport.x - 1.0) * u_tan_half_fov * u_aspect;
  float ny = (1.0 - 2.0 * px.y / u_viewport.y) * u_tan_half_fov;
  vec3 d = u_forward + u_right * nx + u_up * ny;
  float t = -u_eye_uv.z / d.z;
  vec2 uv = u_eye_uv.xy + t * d.xy;
  bool hit = d.z > 0.0;
  vec2 ddx = dFdxFine(uv) * u_size;
  vec2 ddy = dFdyFine(uv) * u_size;
  float rho = max(length(ddx), length(ddy));
  vec2 p = uv * u_size;  // the finest texel coordinate: exact, S is a power of two
  vec2 f = floor(p);
  o_addr = uvec4(uvec2(ivec2(f)), floatBitsToUint(p - f));
  o_footprint = vec2(log2(rho), hit ? 1.0 : 0.0);
}
)";

enum Variant { kFloat = 0, kOurs = 1 };
constexpr const char* kVariantName[2] = {"float32 UV", "ours (int + frac)"};

// What one pixel addresses: finest texel coordinate (double of what the GPU holds), footprint.
struct Address {
  double u = 0, v = 0;
  double log2_rho = 0;
  bool hit = false;
};

// The GL objects of the table; released on every path out.
struct GlState {
  renderer::GlFramebuffer fbo;
  renderer::GlTexture addr_tex, foot_tex;
  renderer::GlVertexArray vao;
  renderer::GlProgram programs[2];
  int width = 0, height = 0;
  GLint viewport[4] = {0, 0, 0, 0};  // the caller's, restored
  GlState() { glGetIntegerv(GL_VIEWPORT, viewport); }
  GlState(const GlState&) = delete;
  GlState& operator=(const GlState&) = delete;
  ~GlState() {
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    glUseProgram(0);
    glBindVertexArray(0);
    glViewport(viewport[0], viewport[1], viewport[2], viewport[3]);
  }
};

Result<bool> create_targets(GlState& gl, int w, int h) {
  gl.width = w;
  gl.height = h;
  glCreateTextures(GL_TEXTURE_2D, 1, gl.addr_tex.out());
  glTextureStorage2D(gl.addr_tex.get(), 1, GL_RGBA32UI, w, h);
  glCreateTextures(GL_TEXTURE_2D, 1, gl.foot_tex.out());
  glTextureStorage2D(gl.foot_tex.get(), 1, GL_RG32F, w, h);
  glCreateFramebuffers(1, gl.fbo.out());
  glNamedFramebufferTexture(gl.fbo.get(), GL_COLOR_ATTACHMENT0, gl.addr_tex.get(), 0);
  glNamedFramebufferTexture(gl.fbo.get(), GL_COLOR_ATTACHMENT1, gl.foot_tex.get(), 0);
  const GLenum bufs[2] = {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1};
  glNamedFramebufferDrawBuffers(gl.fbo.get(), 2, bufs);
  glCreateVertexArrays(1, gl.vao.out());
  const GLenum status = glCheckNamedFramebufferStatus(gl.fbo.get(), GL_FRAMEBUFFER);
  if (status != GL_FRAMEBUFFER_COMPLETE)
    return Error{ErrorCode::unsupported,
                 "addressing table: the RGBA32UI + RG32F render target is incomplete (status 0x" +
                     [&] {
                       char b[16];
                       std::snprintf(b, sizeof b, "%x", unsigned(status));
                       return std::string(b);
                     }() +
                     ")"};
  if (GLenum e = glGetError(); e != GL_NO_ERROR)
    return Error{ErrorCode::unsupported,
                 "addressing table: creating the render targets failed (GL error " +
                     std::to_string(e) + ")"};
  return true;
}

// Sets the variant's uniforms for `view` at S texels per side.
void set_uniforms(GlState& gl, Variant variant, const PlaneView& view, double size) {
  const GLuint p = gl.programs[variant].get();
  renderer::GlProgramUniforms u(p);
  u.set("u_viewport", float(gl.width), float(gl.height));
  if (variant == kOurs) {
    const renderer::PlaneScene scene(view);
    scene.set_uniforms(u, gl.width, gl.height);  // the production uniforms, eye_rel in double
    const auto a = scene.anchor();
    u.set_int("u_anchor", int(a[0]), int(a[1]));
    return;
  }
  const PlaneCamera cam = PlaneCamera::from_view(view, gl.width, gl.height);
  const auto set3 = [&u](const char* name, renderer::Vec3d v) {
    u.set(name, float(v.x), float(v.y), float(v.z));
  };
  set3("u_eye_uv", cam.eye * (1.0 / size));
  set3("u_forward", cam.forward);
  set3("u_right", cam.right);
  set3("u_up", cam.up);
  u.set("u_tan_half_fov", float(cam.tan_half_fov));
  u.set("u_aspect", float(cam.aspect));
  u.set("u_size", float(size));
}

void draw(GlState& gl, Variant variant) {
  glBindFramebuffer(GL_FRAMEBUFFER, gl.fbo.get());
  glViewport(0, 0, gl.width, gl.height);
  glDisable(GL_DEPTH_TEST);
  glDisable(GL_BLEND);
  glDisable(GL_SCISSOR_TEST);
  glUseProgram(gl.programs[variant].get());
  glBindVertexArray(gl.vao.get());
  glDrawArrays(GL_TRIANGLES, 0, 3);
}

// Renders `view` with `variant` and reads back what every pixel addresses, rows top to bottom.
Result<std::vector<Address>> addresses(GlState& gl, Variant variant, const PlaneView& view,
                                       double size) {
  set_uniforms(gl, variant, view, size);
  draw(gl, variant);
  const int w = gl.width, h = gl.height;
  std::vector<std::uint32_t> addr(std::size_t(w) * h * 4);
  std::vector<float> foot(std::size_t(w) * h * 2);
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  glNamedFramebufferReadBuffer(gl.fbo.get(), GL_COLOR_ATTACHMENT0);
  glReadPixels(0, 0, w, h, GL_RGBA_INTEGER, GL_UNSIGNED_INT, addr.data());
  glNamedFramebufferReadBuffer(gl.fbo.get(), GL_COLOR_ATTACHMENT1);
  glReadPixels(0, 0, w, h, GL_RG, GL_FLOAT, foot.data());
  if (GLenum e = glGetError(); e != GL_NO_ERROR)
    return Error{ErrorCode::unsupported, std::string("addressing table: the ") +
                                             kVariantName[variant] + " pass failed (GL error " +
                                             std::to_string(e) + ")"};
  std::vector<Address> out(std::size_t(w) * h);
  for (int gy = 0; gy < h; ++gy) {
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(gy) * w + x;
      const std::uint32_t* a = &addr[4 * i];
      Address& o = out[std::size_t(h - 1 - gy) * w + x];
      o.u = double(std::int32_t(a[0])) + double(std::bit_cast<float>(a[2]));
      o.v = double(std::int32_t(a[1])) + double(std::bit_cast<float>(a[3]));
      o.log2_rho = foot[2 * i];
      o.hit = foot[2 * i + 1] > 0.5f;
    }
  }
  return out;
}

// The double-precision truth: PlaneCamera::hit at each pixel centre, and the footprint from the
// differences across the 2x2 quad (GL rows, as dFdxFine / dFdyFine pair them).
std::vector<Address> reference(const PlaneView& view, int w, int h) {
  const PlaneCamera cam = PlaneCamera::from_view(view, w, h);
  std::vector<renderer::UvHit> hits(std::size_t(w) * h);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) hits[std::size_t(y) * w + x] = cam.hit(x + 0.5, y + 0.5);
  }
  const auto at = [&](int x, int y) -> const renderer::UvHit& {
    return hits[std::size_t(std::clamp(y, 0, h - 1)) * w + std::clamp(x, 0, w - 1)];
  };
  std::vector<Address> out(hits.size());
  for (int y = 0; y < h; ++y) {
    const int gy = h - 1 - y, gy0 = gy & ~1;
    const int ya = h - 1 - gy0, yb = h - 1 - (gy0 + 1);  // the quad's two rows, top-down
    for (int x = 0; x < w; ++x) {
      Address& o = out[std::size_t(y) * w + x];
      const auto& c = at(x, y);
      const int x0 = x & ~1;
      const auto &l = at(x0, y), &r = at(x0 + 1, y), &a = at(x, ya), &b = at(x, yb);
      if (!c || !l || !r || !a || !b) continue;
      o.hit = true;
      o.u = c->first;
      o.v = c->second;
      const double lx = std::hypot(r->first - l->first, r->second - l->second);
      const double ly = std::hypot(b->first - a->first, b->second - a->second);
      o.log2_rho = std::log2(std::max(lx, ly));
    }
  }
  return out;
}

// The level a footprint selects, counted from the finest (0) and clamped there: what sampling
// uses. A zero footprint selects the finest, a NaN or infinite one the coarsest.
double level(double log2_rho, double size) {
  if (std::isnan(log2_rho) || log2_rho == std::numeric_limits<double>::infinity())
    return std::log2(size);
  return std::clamp(log2_rho, 0.0, std::log2(size));
}

struct Errors {
  double max = 0, sum = 0;
  std::size_t pixels = 0, wrong = 0, missed = 0;
  double max_level = 0;
  void add(const Address& gpu, const Address& ref, double size) {
    if (!ref.hit) return;
    if (!gpu.hit) {
      ++missed;
      return;
    }
    double e = std::max(std::abs(gpu.u - ref.u), std::abs(gpu.v - ref.v));
    if (std::isnan(e)) e = std::numeric_limits<double>::infinity();  // counted, and as the worst
    max = std::max(max, e);
    sum += e;
    ++pixels;
    if (std::floor(gpu.u) != std::floor(ref.u) || std::floor(gpu.v) != std::floor(ref.v)) ++wrong;
    max_level =
        std::max(max_level, std::abs(level(gpu.log2_rho, size) - level(ref.log2_rho, size)));
  }
};

// The views of one size: far from the origin, where a float over [0, 1] has the fewest bits left
// for the fraction, at fractional centres that put no pixel centre on a texel edge.
std::vector<std::pair<std::string, PlaneView>> views_for(double size) {
  std::vector<std::pair<std::string, PlaneView>> v;
  PlaneView magnified;
  magnified.center_u = size - 137.3183;
  magnified.center_v = size - 91.5772;
  magnified.texels_per_pixel = 0.25;
  v.emplace_back("4 px/texel, straight down", magnified);
  PlaneView one;
  one.center_u = size - 611.2718;
  one.center_v = size - 402.1414;
  one.texels_per_pixel = 1;
  v.emplace_back("1 px/texel, straight down", one);
  PlaneView tilted;
  tilted.center_u = size - 2345.6789;
  tilted.center_v = size - 1987.6543;
  tilted.texels_per_pixel = 1;
  tilted.tilt = 0.9;
  tilted.heading = 0.7;
  v.emplace_back("1 px/texel, tilted 0.9 and turned 0.7", tilted);
  return v;
}

// GPU time of one pass of each variant: `draws` passes between two glFinish, wall time per pass,
// the fastest of `runs` (on a shared machine, the run least disturbed by other work: a median
// still moves with the load); the variants alternate so that a busy machine slows both alike.
std::array<double, 2> pass_ms(GlState& gl, const PlaneView& view, double size, int runs,
                              int draws) {
  using SteadyClock = std::chrono::steady_clock;
  std::array<std::vector<double>, 2> t;
  for (int v = 0; v < 2; ++v) {
    set_uniforms(gl, Variant(v), view, size);
    // Warm up: the driver may compile or specialise a program on its first draws.
    for (int i = 0; i < 2 * draws; ++i) draw(gl, Variant(v));
    glFinish();
  }
  for (int r = 0; r < runs; ++r) {
    for (int v = 0; v < 2; ++v) {
      const auto t0 = SteadyClock::now();
      for (int i = 0; i < draws; ++i) draw(gl, Variant(v));
      glFinish();
      t[v].push_back(std::chrono::duration<double, std::milli>(SteadyClock::now() - t0).count() /
                     draws);
    }
  }
  return {*std::min_element(t[0].begin(), t[0].end()), *std::min_element(t[1].begin(), t[1].end())};
}

std::string fmt(double x, int digits) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", digits, x);
  return b;
}

}  // namespace

Result<AccuracyTable> addressing_table(const AccuracyContext& ctx) {
  using namespace detail_addressing;
  if (ctx.width < 2 || ctx.height < 2 || ctx.width > 16384 || ctx.height > 16384)
    return Error{ErrorCode::invalid_argument, "addressing table: viewport " +
                                                  std::to_string(ctx.width) + " x " +
                                                  std::to_string(ctx.height) + " out of range"};
  for (const char* s : {kOursHit, kOursDerivatives, kOursSplit}) {
    if (!production_has(s))
      return Error{ErrorCode::internal,
                   "addressing table: the virtual-texturing shader no longer contains the "
                   "addressing code this table measures as ours "
                   "(renderer/core/include/vts/renderer/shaders.hpp "
                   "changed; update accuracy/include/vts/accuracy/addressing_detail.hpp):\n" +
                       std::string(s)};
  }
  if (glGetString(GL_VERSION) == nullptr || !epoxy_is_desktop_gl() || epoxy_gl_version() < 45)
    return Error{ErrorCode::unsupported,
                 "addressing table: needs a current OpenGL 4.5 core context on this thread"};

  const std::vector<int> log2_sizes =
      ctx.quick ? std::vector<int>{15, 20, 25} : std::vector<int>{15, 17, 19, 21, 23, 25};
  const int runs = ctx.quick ? 15 : 21, draws = ctx.quick ? 16 : 20;
  const int w = ctx.width, h = ctx.height;

  GlState gl;
  while (glGetError() != GL_NO_ERROR) {
  }
  if (auto r = create_targets(gl, w, h); !r) return r.error();
  {
    auto f = renderer::link_program(renderer::detail::kFullscreenVertex, kFloatFragment,
                                    "addressing float32 UV");
    if (!f) return f.error();
    gl.programs[kFloat] = std::move(*f);
    auto o = renderer::link_program(renderer::detail::kFullscreenVertex, ours_fragment(),
                                    "addressing ours");
    if (!o) return o.error();
    gl.programs[kOurs] = std::move(*o);
  }

  AccuracyTable t;
  t.id = "addressing";
  t.title = "Addressing precision: float32 UV vs integer texel + float fraction";
  t.columns = {
      {"virtual_size_log2", "virtual size (2^n texels per side)", 0},
      {"variant", "variant", 0},
      {"max_texel_error", "max texel error (texels)", 6},
      {"mean_texel_error", "mean texel error (texels)", 6},
      {"wrong_texel_fraction", "wrong texel (fraction of pixels)", 6},
      {"max_level_error", "max mip-level error (levels)", 4},
      {"shader_ms", "pass time (ms)", 3},
      {"ratio_to_float32", "time / float32", 2},
  };

  PlotSeries series[2] = {{kVariantName[kFloat], {}}, {kVariantName[kOurs], {}}};
  PlotSeries half_ulp{"half an ulp of a float uv near 1 (S / 2^25)", {}};
  double log_ratio_sum = 0, ratio_min = std::numeric_limits<double>::infinity(), ratio_max = 0;
  PlotSeries wrong_series[2] = {{kVariantName[kFloat], {}}, {kVariantName[kOurs], {}}};
  for (int n : log2_sizes) {
    const double size = std::ldexp(1.0, n);
    const auto views = views_for(size);
    Errors err[2];
    for (const auto& [name, view] : views) {
      ctx.say("addressing: 2^" + std::to_string(n) + ", " + name);
      const auto ref = reference(view, w, h);
      for (int v = 0; v < 2; ++v) {
        auto gpu = addresses(gl, Variant(v), view, size);
        if (!gpu) return gpu.error();
        for (std::size_t i = 0; i < ref.size(); ++i) err[v].add((*gpu)[i], ref[i], size);
      }
    }
    const auto ms = pass_ms(gl, views[1].second, size, runs, draws);
    for (int v = 0; v < 2; ++v) {
      const Errors& e = err[v];
      if (e.pixels == 0)
        return Error{ErrorCode::internal, "addressing table: no pixel of 2^" + std::to_string(n) +
                                              " hit the plane (" + kVariantName[v] + ")"};
      if (e.missed)
        return Error{ErrorCode::internal, "addressing table: " + std::to_string(e.missed) +
                                              " pixels of 2^" + std::to_string(n) +
                                              " hit the plane in double but not in the " +
                                              kVariantName[v] + " pass"};
      const double mean = e.sum / double(e.pixels);
      const double wrong = double(e.wrong) / double(e.pixels);
      t.rows.push_back({double(n), std::string(kVariantName[v]), e.max, mean, wrong, e.max_level,
                        ms[v], ms[v] / ms[kFloat]});
      if (e.max > 0 && std::isfinite(e.max)) series[v].points.emplace_back(double(n), e.max);
      if (wrong > 0) wrong_series[v].points.emplace_back(double(n), wrong);
    }
    half_ulp.points.emplace_back(double(n), std::ldexp(size, -25));
    const double ratio = ms[kOurs] / ms[kFloat];
    log_ratio_sum += std::log(ratio);
    ratio_min = std::min(ratio_min, ratio);
    ratio_max = std::max(ratio_max, ratio);
  }

  const char* gl_renderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
  t.notes = {
      "Each pixel's finest-level texel coordinate, read back from the GPU, against the plane "
      "camera's ray-plane hit in double (camera.hpp) at the pixel centre, over " +
          std::to_string(w) + " x " + std::to_string(h) +
          " pixels of three views per size, all near the far corner (S, S) of an S x S texture "
          "where a [0, 1] float keeps the fewest bits for the fraction: 4 pixels per texel and 1 "
          "pixel per texel straight down, and 1 pixel per texel tilted 0.9 rad and turned 0.7 "
          "rad (fov 0.8 rad). View centres are fractional so no pixel centre sits on a texel edge.",
      "Texel error: max(|du|, |dv|) in finest texels; wrong texel: floor(u) or floor(v) differs "
      "from the reference's; mip-level error: |level - reference level| with the level "
      "max(log2 rho, 0) (0 = finest) from the 2x2-quad footprint rho, as the shader chooses it.",
      "float32 UV: the eye and the ray in normalised [0, 1] texture space as float, uv = eye + t "
      "d, texel = uv * S (exact: S is a power of two), derivatives dFdxFine(uv) * S. The error is "
      "that of the uv a float-UV virtual texture would look its page table up with.",
      "ours: the shipped code — PlaneScene's GLSL and uniforms (the eye relative to an integer "
      "anchor texel, formed in double), then the virtual-texturing shader's own lines that take "
      "dFdxFine(rel) and split rel into integer texel + fraction (checked at run time to be a "
      "verbatim part of renderer/core/include/vts/renderer/shaders.hpp). At a coarser level L the "
      "shader shifts the "
      "integer by s = max_level - L and adds the shifted-out bits to the fraction, / 2^s: in "
      "that level's texels the error is the finest level's / 2^s plus one float rounding "
      "(2^-24), so the finest level measured here bounds them all.",
      "Its error does not depend on S: it is float rounding of rel (|rel| up to the view's "
      "extent in texels) and of the camera uniforms, about 2^-24 x (|rel| + eye distance) "
      "texels: well under 1/256 texel (the weight resolution of hardware bilinear filtering) "
      "at any S, which the GL test asserts at 2^15, 2^20 and 2^25. float32 UV loses a bit per "
      "doubling of S: its uv's ulp near 1 is 2^-24, i.e. S / 2^24 texels; the plot's third "
      "series is half of it, the rounding of a single float uv.",
      "Pass time: one fullscreen pass at " + std::to_string(w) + " x " + std::to_string(h) +
          " (the 1 pixel-per-texel view) writing RGBA32UI + RG32F, wall time of " +
          std::to_string(draws) + " passes between glFinish, the fastest of " +
          std::to_string(runs) +
          " runs (the least disturbed by other work on a shared machine), variants alternating; "
          "on " +
          (gl_renderer ? gl_renderer : "an unknown GPU") +
          ". The same target and the same outputs in both variants: only the addressing math "
          "differs. Ratio: the variant's time over float32 UV's at the same size.",
      "Ours over float32 UV across the sizes (the shaders do not depend on S, so the spread is "
      "the machine's noise): geometric mean " +
          fmt(std::exp(log_ratio_sum / double(log2_sizes.size())), 2) + ", from " +
          fmt(ratio_min, 2) + " to " + fmt(ratio_max, 2) +
          ". The split costs a floor, a float-to-int conversion and an integer add per pixel.",
  };
  TablePlot plot;
  plot.id = "addressing_error";
  plot.title = "Max texel error vs virtual size";
  plot.x_label = "virtual size (log2 texels per side)";
  plot.y_label = "max texel error (texels)";
  plot.log_y = true;
  plot.series = {series[0], series[1], half_ulp};
  t.plots.push_back(std::move(plot));
  TablePlot wplot;
  wplot.id = "addressing_wrong_texel";
  wplot.title = "Pixels on the wrong texel vs virtual size";
  wplot.x_label = "virtual size (log2 texels per side)";
  wplot.y_label = "fraction of pixels on the wrong texel";
  wplot.log_y = true;
  wplot.series = {wrong_series[0], wrong_series[1]};
  t.plots.push_back(std::move(wplot));
  return t;
}

}  // namespace vts::accuracy
