// An OpenGL 4.5 core context, made one of two ways (docs/RENDERER.md, "Contexts: GLFW or EGL"):
//   - GLFW 3.3: a window (or a hidden one) on a display (X11 or Wayland; Xvfb in CI);
//   - EGL with no display and no surface: on a GPU server, EGL_EXT_platform_device (a hardware
//     device of eglQueryDevicesEXT's list, e.g. an NVIDIA GPU), else Mesa's
//     EGL_MESA_platform_surfaceless (llvmpipe, or the GPU Mesa drives). The context has no
//     default framebuffer: the renderer draws into its own framebuffer objects, which is what
//     the headless viewer, the benchmark and the accuracy tables read back on both paths.
// libepoxy resolves GL entry points through whichever context is current. The viewer's only way
// into GL, so that a missing display or driver, or a context without 4.5 core, is one clear
// error at start-up instead of a crash at the first GL call.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "vts/base/result.hpp"

struct GLFWwindow;

namespace vts::renderer {

// How a context is made. automatic: a visible window is GLFW; a hidden one is GLFW when a
// display is named (DISPLAY or WAYLAND_DISPLAY set), else EGL. egl: the device platform with a
// hardware device, else Mesa's surfaceless platform, else a software device. egl_device and
// egl_surfaceless: that platform only.
enum class GlBackend : std::uint8_t { automatic, glfw, egl, egl_device, egl_surfaceless };

// "auto", "glfw", "egl", "egl-device", "egl-surfaceless"; nullopt for any other name.
std::optional<GlBackend> gl_backend_from_name(const std::string& name);
const char* gl_backend_name(GlBackend backend);

struct GlContextOptions {
  int width = 1280;  // framebuffer size in pixels (of the window's default framebuffer)
  int height = 720;
  bool visible = true;  // false: a hidden window or no window (EGL), for --headless and tests
  std::string title = "vtstream";
  bool vsync = true;
  bool debug = false;  // a debug context with GL_KHR_debug messages sent to stderr
  // automatic takes the environment's VTS_GL (a name above) first. A visible window needs GLFW.
  GlBackend backend = GlBackend::automatic;
  // The EGL device platform's device, an index into eglQueryDevicesEXT's list; -1: the
  // environment's VTS_EGL_DEVICE, else the first hardware device (a software one only where
  // none is, or with egl_device alone).
  int egl_device = -1;
};

struct GlInfo {
  int version = 0;           // major * 10 + minor, e.g. 45
  std::string version_text;  // GL_VERSION
  std::string renderer;      // GL_RENDERER, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)"
  std::string vendor;        // GL_VENDOR
  std::string backend;       // what made it: "glfw", "egl-device" or "egl-surfaceless"
  // egl-device: "device I of N" and what EGL says of it (its DRM file, software or not).
  std::string device;
};

// The backend `options` resolve to in this environment (never automatic): what create() uses.
// Error: VTS_GL set to an unknown name, or a visible window asked of EGL.
Result<GlBackend> resolve_gl_backend(const GlContextOptions& options);

class EglContext;  // gl_context_egl.hpp

// Thread-affine: create, use and destroy it on one thread (GLFW wants the main thread). Several
// contexts may exist at once; GLFW is initialised with the first and terminated with the last,
// and an EGL display likewise.
class GlContext {
 public:
  // Fails with a message that names the cause: no display (DISPLAY unset, no X server), no
  // libEGL, no EGL device or platform, an EGL extension the driver lacks, no GL 4.5 core
  // context available, or a window the system refused.
  static Result<std::unique_ptr<GlContext>> create(const GlContextOptions& options);
  ~GlContext();
  GlContext(const GlContext&) = delete;
  GlContext& operator=(const GlContext&) = delete;

  // The GLFW window; nullptr on EGL (no window: headless only).
  GLFWwindow* window() const { return window_; }
  const GlInfo& info() const { return info_; }
  void make_current();
  bool should_close() const;
  void swap_buffers();
  void poll_events();
  // The default framebuffer's size in pixels (differs from the window size on HiDPI screens);
  // on EGL, which has none, the size asked for.
  void framebuffer_size(int& width, int& height) const;

  // Whether some OpenGL context (GLFW's or EGL's) is current on the calling thread.
  static bool any_current();
  // Leaves the calling thread with no current context (either kind).
  static void release_current();

 private:
  GlContext() = default;
  Status finish(const GlContextOptions& options);  // GL info, version check, debug output
  GLFWwindow* window_ = nullptr;
  std::unique_ptr<EglContext> egl_;
  int width_ = 0, height_ = 0;
  GlInfo info_;
};

}  // namespace vts::renderer
