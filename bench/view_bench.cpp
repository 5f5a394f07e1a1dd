// The renderer's benchmark driver (bench/view_bench.sh runs it under Xvfb with Mesa llvmpipe, or
// with no display through EGL; bench/gpu_device.sh on a GPU server):
//   vts_view_bench SOURCE [--width 1920 --height 1080] [--frames 60] [--cache-dir DIR]
//                  [--bilinear]   (one lookup per fragment instead of trilinear's two)
//                  [--anisotropy N] (N taps at most along the footprint's major axis; the
//                                   mipmapped peer gets GL_TEXTURE_MAX_ANISOTROPY N)
//                  [--gl auto|glfw|egl|egl-device|egl-surfaceless] (the context; default $VTS_GL,
//                                   else GLFW with a display and EGL without: gl_context.hpp)
//                  [--screenshot FILE.png] (the converged virtual-texture frame, for comparisons)
// prints one JSON object with
//   - vt_cpu_ms: CPU time per frame in the virtual-texturing system (feedback reduction, requests,
//     uploads, page table), median over --frames converged frames, 1/8 feedback;
//   - vt_frame_ms / mip_frame_ms: the GPU-finished time of the same view drawn through the
//     virtual texture and through an ordinary mipmapped texture of the whole image (SOURCE's
//     finest level, its tiles' content assembled: the texels the virtual texture shows; it must
//     fit in GL_MAX_TEXTURE_SIZE), each median, and their ratio;
//   - first_full_ms / jump_warm_ram_ms / jump_warm_disk_ms: time to full resolution from a cold
//     start on SOURCE, after a jump back to a view whose tiles are in the client's RAM cache,
//     and from a new client whose disk cache (--cache-dir) holds the tiles;
//   - gl_renderer, gl_backend, gl_device: the context it ran on.
#include <epoxy/gl.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "vts/client/disk_cache.hpp"
#include "vts/client/source.hpp"
#include "vts/client/tile_client.hpp"
#include "vts/imaging/web_image.hpp"
#include "vts/renderer/gl_context.hpp"
#include "vts/renderer/gl_handle.hpp"
#include "vts/renderer/gl_program.hpp"
#include "vts/renderer/gl_uniforms.hpp"
#include "vts/renderer/scene.hpp"
#include "vts/renderer/virtual_texture.hpp"

using namespace vts::renderer;
using Clock = std::chrono::steady_clock;

namespace {

[[noreturn]] void fail(const std::string& what) {
  std::fprintf(stderr, "vts_view_bench: %s\n", what.c_str());
  std::exit(1);
}

double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// `text` for a JSON string's inside (the device text is the driver's: quotes and backslashes
// escaped, control characters dropped).
std::string json_text(const std::string& text) {
  std::string out;
  for (const char c : text) {
    if (c == '"' || c == '\\') out += '\\';
    if (static_cast<unsigned char>(c) >= 0x20) out += c;
  }
  return out;
}

bool g_trilinear = true;
int g_anisotropy = 1;

std::unique_ptr<VirtualTexture> open_vt(const std::string& source, const std::string& cache_dir) {
  auto src = vts::client::open_source(source);
  if (!src) fail(src.error().to_string());
  vts::client::TileClientOptions o;
  if (!cache_dir.empty()) o.cache.disk = vts::client::DiskCacheOptions{.dir = cache_dir};
  auto client = vts::client::TileClient::create(std::shared_ptr(std::move(*src)), o);
  if (!client) fail(client.error().to_string());
  const vts::Geometry g = (*client)->info().info.geometry;
  VirtualTextureOptions vo;
  vo.trilinear = g_trilinear;
  vo.anisotropy = g_anisotropy;
  auto vt = VirtualTexture::create(std::shared_ptr(std::move(*client)), g, vo);
  if (!vt) fail(vt.error().to_string());
  return std::move(*vt);
}

// Milliseconds until a frame of `scene` is complete (every frame finished on the GPU).
double time_to_full(VirtualTexture& vt, const Scene& scene, int w, int h) {
  const auto t0 = Clock::now();
  for (int i = 0; i < 5000; ++i) {
    const FrameStats st = vt.render(scene, w, h);
    glFinish();
    if (st.complete) return ms_since(t0);
    if (st.pending > 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  fail("the view never reached full resolution");
}

// The same plane view through one ordinary mipmapped SRGB texture of the whole image, hardware
// trilinear: the cost the virtual texture adds is the difference.
struct MipmappedRenderer {
  GlTexture tex, color;
  GlProgram prog;
  GlVertexArray vao;
  GlFramebuffer fbo;
  double W = 0, H = 0;

  void init(const vts::TileImage& img, int w, int h) {
    W = img.width;
    H = img.height;
    const int iw = int(img.width), ih = int(img.height);
    int levels = 1;
    while ((std::max(iw, ih) >> levels) > 0) ++levels;
    glCreateTextures(GL_TEXTURE_2D, 1, tex.out());
    glTextureStorage2D(tex.get(), levels, GL_SRGB8_ALPHA8, iw, ih);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
    glTextureSubImage2D(tex.get(), 0, 0, 0, iw, ih, GL_RGBA, GL_UNSIGNED_BYTE, img.pixels.data());
    glGenerateTextureMipmap(tex.get());
    glTextureParameteri(tex.get(), GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
    glTextureParameteri(tex.get(), GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glTextureParameteri(tex.get(), GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTextureParameteri(tex.get(), GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    if (g_anisotropy > 1)
      glTextureParameterf(tex.get(), GL_TEXTURE_MAX_ANISOTROPY, float(g_anisotropy));

    const std::string vs = R"(#version 450 core
void main() {
  vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
  gl_Position = vec4(p, 0.0, 1.0);
})";
    const std::string fs =
        "#version 450 core\nuniform vec2 u_viewport;\n" + PlaneScene(PlaneView{}).glsl() + R"(
uniform ivec2 u_anchor;
uniform vec2 u_image;
uniform sampler2D u_tex;
layout(location = 0) out vec4 o_color;
void main() {
  vec2 rel;
  bool hit = scene_hit(vec2(gl_FragCoord.x, u_viewport.y - gl_FragCoord.y), rel);
  vec2 uv = (vec2(u_anchor) + rel) / u_image;
  vec4 c = texture(u_tex, uv);
  o_color = hit && all(greaterThanEqual(uv, vec2(0))) && all(lessThan(uv, vec2(1)))
                ? vec4(c.rgb, 1) : vec4(0, 0, 0, 1);
})";
    auto linked = link_program(vs, fs, "mipmapped");
    if (!linked) fail(linked.error().message);
    prog = std::move(*linked);
    glCreateVertexArrays(1, vao.out());
    glCreateTextures(GL_TEXTURE_2D, 1, color.out());
    glTextureStorage2D(color.get(), 1, GL_SRGB8_ALPHA8, w, h);
    glCreateFramebuffers(1, fbo.out());
    glNamedFramebufferTexture(fbo.get(), GL_COLOR_ATTACHMENT0, color.get(), 0);
  }

  double frame(const PlaneScene& scene, int w, int h) {
    const auto t0 = Clock::now();
    GlProgramUniforms u(prog.get());
    scene.set_uniforms(u, w, h);
    const auto a = scene.anchor();
    glProgramUniform2f(prog.get(), glGetUniformLocation(prog.get(), "u_viewport"), float(w),
                       float(h));
    glProgramUniform2i(prog.get(), glGetUniformLocation(prog.get(), "u_anchor"), GLint(a[0]),
                       GLint(a[1]));
    glProgramUniform2f(prog.get(), glGetUniformLocation(prog.get(), "u_image"), float(W), float(H));
    glBindFramebuffer(GL_FRAMEBUFFER, fbo.get());
    glViewport(0, 0, w, h);
    glEnable(GL_FRAMEBUFFER_SRGB);
    glUseProgram(prog.get());
    glBindVertexArray(vao.get());
    glBindTextureUnit(0, tex.get());
    glDrawArrays(GL_TRIANGLES, 0, 3);
    glFinish();
    return ms_since(t0);
  }
};

// SOURCE's finest level as one rgba8 image: every tile's content (borders cropped) in place.
vts::TileImage finest_level(const std::string& source) {
  auto src = vts::client::open_source(source);
  if (!src) fail(src.error().to_string());
  auto client = vts::client::TileClient::create(std::shared_ptr(std::move(*src)));
  if (!client) fail(client.error().to_string());
  const vts::Geometry g = (*client)->info().info.geometry;
  const int z = g.max_zoom();
  GLint max_size = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
  if (g.width() > std::uint64_t(max_size) || g.height() > std::uint64_t(max_size))
    fail(source + ": the image does not fit one texture (GL_MAX_TEXTURE_SIZE " +
         std::to_string(max_size) + ")");
  vts::TileImage out{std::uint32_t(g.width()), std::uint32_t(g.height())};
  out.pixels.assign(std::size_t(out.width) * out.height * 4, 0);
  std::uint64_t left = 0;
  const auto zl = std::uint8_t(z);
  for (std::uint32_t y = 0; y < g.tiles_y(z); ++y)
    for (std::uint32_t x = 0; x < g.tiles_x(z); ++x)
      if (g.exists({zl, x, y})) {
        (*client)->request({zl, x, y});
        ++left;
      }
  while (left > 0) {
    auto e = (*client)->wait(std::chrono::seconds(60));
    if (!e) fail(source + ": no tile came in a minute");
    if (e->kind != vts::client::TileEvent::Kind::decoded)
      fail("tile " + e->id.to_string() + ": " + (e->error ? e->error->message : "absent"));
    auto content = vts::imaging::tile_content(e->image, g, e->id);
    if (!content) fail(content.error().to_string());
    const vts::TexelRect r = g.content_rect(e->id);
    for (std::uint64_t row = 0; row < r.height(); ++row)
      std::memcpy(out.pixels.data() + ((r.y0 + row) * out.width + r.x0) * 4,
                  content->pixels.data() + row * content->width * 4, r.width() * 4);
    --left;
  }
  return out;
}

void write_screenshot(const VirtualTexture& vt, const std::string& path) {
  const Image img = vt.read_image();
  if (auto s = vts::imaging::write_png(path, img.width, img.height, img.rgba); !s)
    fail(s.error().to_string());
}

struct Args {
  std::string source, cache_dir, screenshot;
  int w = 1920, h = 1080, frames = 60;
  GlBackend backend = GlBackend::automatic;
};

Args parse_args(int argc, char** argv) {
  Args r;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const auto next = [&]() -> std::string {
      if (i + 1 >= argc) fail(a + " needs a value");
      return argv[++i];
    };
    if (a == "--width")
      r.w = std::stoi(next());
    else if (a == "--height")
      r.h = std::stoi(next());
    else if (a == "--frames")
      r.frames = std::stoi(next());
    else if (a == "--cache-dir")
      r.cache_dir = next();
    else if (a == "--bilinear")
      g_trilinear = false;
    else if (a == "--anisotropy")
      g_anisotropy = std::stoi(next());
    else if (a == "--screenshot")
      r.screenshot = next();
    else if (a == "--gl") {
      const auto b = gl_backend_from_name(next());
      if (!b) fail("--gl takes auto, glfw, egl, egl-device or egl-surfaceless");
      r.backend = *b;
    } else if (!a.empty() && a[0] != '-' && r.source.empty())
      r.source = a;
    else
      fail("unknown argument " + a);
  }
  if (r.source.empty()) fail("usage: vts_view_bench SOURCE [--width W --height H ...]");
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  const Args args = parse_args(argc, argv);
  const std::string& source = args.source;
  const std::string& cache_dir = args.cache_dir;
  const int w = args.w, h = args.h, frames = args.frames;
  GlContextOptions go;
  go.width = w;
  go.height = h;
  go.visible = false;
  go.vsync = false;
  go.backend = args.backend;
  auto gl = GlContext::create(go);
  if (!gl) fail(gl.error().to_string());

  auto vt = open_vt(source, cache_dir);
  const vts::Geometry& g = vt->geometry();
  const double W = double(g.width()), H = double(g.height());
  // A tilted view over the image at about one texel per pixel near the centre (several levels
  // on screen), and a second view elsewhere to jump to.
  const PlaneScene a(PlaneView{.center_u = W * 0.3,
                               .center_v = H * 0.4,
                               .texels_per_pixel = 1.2,
                               .heading = 0.4,
                               .tilt = 0.9});
  const PlaneScene b(PlaneView{.center_u = W * 0.7,
                               .center_v = H * 0.6,
                               .texels_per_pixel = 1.2,
                               .heading = -0.3,
                               .tilt = 0.7});

  const double first_full = time_to_full(*vt, a, w, h);
  std::vector<double> cpu, frame_ms;
  for (int i = 0; i < frames; ++i) {
    const auto t0 = Clock::now();
    const FrameStats st = vt->render(a, w, h);
    glFinish();
    frame_ms.push_back(ms_since(t0));
    cpu.push_back(st.vt_cpu_ms);
  }
  (void)time_to_full(*vt, b, w, h);
  const double jump_ram = time_to_full(*vt, a, w, h);

  double jump_disk = -1;
  if (!cache_dir.empty()) {
    vt.reset();  // flushes the disk cache
    vt = open_vt(source, cache_dir);
    jump_disk = time_to_full(*vt, a, w, h);
  }

  // The last frame is view a, complete: what the screenshot compares across contexts.
  if (!args.screenshot.empty()) write_screenshot(*vt, args.screenshot);

  MipmappedRenderer mip;
  mip.init(finest_level(source), w, h);
  std::vector<double> mip_ms;
  for (int i = 0; i < frames; ++i) mip_ms.push_back(mip.frame(a, w, h));

  const double vt_med = median(frame_ms), mip_med = median(mip_ms);
  std::printf(
      "{\"width\": %d, \"height\": %d, \"frames\": %d, \"anisotropy\": %d, "
      "\"gl_renderer\": \"%s\", \"gl_backend\": \"%s\", \"gl_device\": \"%s\", "
      "\"vt_cpu_ms\": %.3f, \"vt_frame_ms\": %.2f, \"mip_frame_ms\": %.2f, "
      "\"vt_over_mip\": %.2f, \"first_full_ms\": %.1f, \"jump_warm_ram_ms\": %.1f, "
      "\"jump_warm_disk_ms\": %.1f, \"page_table_bytes\": %llu, \"physical_bytes\": %llu}\n",
      w, h, frames, g_anisotropy, (*gl)->info().renderer.c_str(), (*gl)->info().backend.c_str(),
      json_text((*gl)->info().device).c_str(), median(cpu), vt_med, mip_med,
      mip_med > 0 ? vt_med / mip_med : 0.0, first_full, jump_ram, jump_disk,
      static_cast<unsigned long long>(vt->page_table_gpu_bytes()),
      static_cast<unsigned long long>(vt->physical_gpu_bytes()));
  return 0;
}
