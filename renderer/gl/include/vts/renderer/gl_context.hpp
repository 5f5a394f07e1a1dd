// A window with an OpenGL 4.5 core context: GLFW 3.3 creates it, libepoxy resolves GL entry
// points. The viewer's only way into GL, so that a missing display, an old driver or a context
// without 4.5 core is one clear error at start-up instead of a crash at the first GL call.
// Headless rendering uses a hidden window (under Xvfb with Mesa llvmpipe where there is no GPU).
#pragma once

#include <memory>
#include <string>

#include "vts/base/result.hpp"

struct GLFWwindow;

namespace vts::renderer {

struct GlContextOptions {
  int width = 1280;  // framebuffer size in pixels (of the window's default framebuffer)
  int height = 720;
  bool visible = true;  // false: a hidden window, for --headless and tests
  std::string title = "vtstream";
  bool vsync = true;
  bool debug = false;  // a debug context with GL_KHR_debug messages sent to stderr
};

struct GlInfo {
  int version = 0;           // major * 10 + minor, e.g. 45
  std::string version_text;  // GL_VERSION
  std::string renderer;      // GL_RENDERER, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)"
  std::string vendor;        // GL_VENDOR
};

// Thread-affine: create, use and destroy it on one thread (GLFW wants the main thread). Several
// contexts may exist at once; GLFW is initialised with the first and terminated with the last.
class GlContext {
 public:
  // Fails with a message that names the cause: no display (DISPLAY unset, no X server), no
  // GL 4.5 core context available, or a window the system refused.
  static Result<std::unique_ptr<GlContext>> create(const GlContextOptions& options);
  ~GlContext();
  GlContext(const GlContext&) = delete;
  GlContext& operator=(const GlContext&) = delete;

  GLFWwindow* window() const { return window_; }
  const GlInfo& info() const { return info_; }
  void make_current();
  bool should_close() const;
  void swap_buffers();
  void poll_events();
  // The default framebuffer's size in pixels (differs from the window size on HiDPI screens).
  void framebuffer_size(int& width, int& height) const;

 private:
  explicit GlContext(GLFWwindow* window) : window_(window) {}
  GLFWwindow* window_ = nullptr;
  GlInfo info_;
};

}  // namespace vts::renderer
