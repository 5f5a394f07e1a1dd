// The renderer's benchmark driver (bench/view_bench.sh runs it under Xvfb with Mesa llvmpipe):
//   vts_view_bench SOURCE --image FILE [--width 1920 --height 1080] [--frames 60] [--cache-dir DIR]
//                  [--bilinear]   (one lookup per fragment instead of trilinear's two)
//                  [--anisotropy N] (N taps at most along the footprint's major axis; the
//                                   mipmapped peer gets GL_TEXTURE_MAX_ANISOTROPY N)
// prints one JSON object with
//   - vt_cpu_ms: CPU time per frame in the virtual-texturing system (feedback reduction, requests,
//     uploads, page table), median over --frames converged frames, 1/8 feedback;
//   - vt_frame_ms / mip_frame_ms: the GPU-finished time of the same view drawn through the
//     virtual texture and through an ordinary mipmapped texture of the whole image (FILE, which
//     must fit in GL_MAX_TEXTURE_SIZE), each median, and their ratio;
//   - first_full_ms / jump_warm_ram_ms / jump_warm_disk_ms: time to full resolution from a cold
//     start on SOURCE, after a jump back to a view whose tiles are in the client's RAM cache,
//     and from a new client whose disk cache (--cache-dir) holds the tiles.
#include <epoxy/gl.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

#include "vts/builder/image_io.hpp"
#include "vts/client/disk_cache.hpp"
#include "vts/client/source.hpp"
#include "vts/client/tile_client.hpp"
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

  void init(const std::string& image, int w, int h) {
    auto img = vts::read_rgba8(image);
    if (!img) fail(img.error().to_string());
    W = img->width;
    H = img->height;
    GLint max_size = 0;
    glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
    if (img->width > max_size || img->height > max_size) fail(image + " does not fit a texture");
    int levels = 1;
    while ((std::max(img->width, img->height) >> levels) > 0) ++levels;
    glCreateTextures(GL_TEXTURE_2D, 1, tex.out());
    glTextureStorage2D(tex.get(), levels, GL_SRGB8_ALPHA8, img->width, img->height);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
    glTextureSubImage2D(tex.get(), 0, 0, 0, img->width, img->height, GL_RGBA, GL_UNSIGNED_BYTE,
                        img->rgba.data());
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

}  // namespace

int main(int argc, char** argv) {
  std::string source, image, cache_dir;
  int w = 1920, h = 1080, frames = 60;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const auto next = [&]() -> std::string {
      if (i + 1 >= argc) fail(a + " needs a value");
      return argv[++i];
    };
    if (a == "--image")
      image = next();
    else if (a == "--width")
      w = std::stoi(next());
    else if (a == "--height")
      h = std::stoi(next());
    else if (a == "--frames")
      frames = std::stoi(next());
    else if (a == "--cache-dir")
      cache_dir = next();
    else if (a == "--bilinear")
      g_trilinear = false;
    else if (a == "--anisotropy")
      g_anisotropy = std::stoi(next());
    else if (!a.empty() && a[0] != '-' && source.empty())
      source = a;
    else
      fail("unknown argument " + a);
  }
  if (source.empty() || image.empty()) fail("usage: vts_view_bench SOURCE --image FILE [...]");

  GlContextOptions go;
  go.width = w;
  go.height = h;
  go.visible = false;
  go.vsync = false;
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

  MipmappedRenderer mip;
  mip.init(image, w, h);
  std::vector<double> mip_ms;
  for (int i = 0; i < frames; ++i) mip_ms.push_back(mip.frame(a, w, h));

  const double vt_med = median(frame_ms), mip_med = median(mip_ms);
  std::printf(
      "{\"width\": %d, \"height\": %d, \"frames\": %d, \"anisotropy\": %d, "
      "\"gl_renderer\": \"%s\", "
      "\"vt_cpu_ms\": %.3f, \"vt_frame_ms\": %.2f, \"mip_frame_ms\": %.2f, "
      "\"vt_over_mip\": %.2f, \"first_full_ms\": %.1f, \"jump_warm_ram_ms\": %.1f, "
      "\"jump_warm_disk_ms\": %.1f, \"page_table_bytes\": %llu, \"physical_bytes\": %llu}\n",
      w, h, frames, g_anisotropy, (*gl)->info().renderer.c_str(), median(cpu), vt_med, mip_med,
      mip_med > 0 ? vt_med / mip_med : 0.0, first_full, jump_ram, jump_disk,
      static_cast<unsigned long long>(vt->page_table_gpu_bytes()),
      static_cast<unsigned long long>(vt->physical_gpu_bytes()));
  return 0;
}
