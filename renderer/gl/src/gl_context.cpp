#include "vts/renderer/gl_context.hpp"

#include "gl_context_egl.hpp"
#include "vts/renderer/gl_check.hpp"

// clang-format off
#include <epoxy/gl.h>  // before GLFW, which must not include a GL header of its own

#include <chrono>
#include <cstdlib>
#include <thread>
#include <GLFW/glfw3.h>
// clang-format on

#include <cstdio>
#include <mutex>

namespace vts::renderer {
namespace {

// GLFW reports errors through a callback; keep the last one to put in our own error message.
std::mutex g_mutex;
int g_users = 0;  // live contexts (GLFW stays initialised while there is one)
std::string g_last_error;

void on_glfw_error(int code, const char* message) {
  g_last_error = std::string(message ? message : "unknown error") + " (GLFW error " +
                 std::to_string(code) + ")";
}

std::string take_glfw_error() {
  std::string e = g_last_error.empty() ? "no reason given" : g_last_error;
  g_last_error.clear();
  return e;
}

std::string gl_string(GLenum name) {
  const auto* s = reinterpret_cast<const char*>(glGetString(name));
  return s ? s : "";
}

void GLAPIENTRY on_gl_debug(GLenum, GLenum type, GLuint, GLenum severity, GLsizei,
                            const GLchar* message, const void*) {
  if (severity == GL_DEBUG_SEVERITY_NOTIFICATION) return;
  std::fprintf(stderr, "vts: GL %s: %s\n", type == GL_DEBUG_TYPE_ERROR ? "error" : "debug",
               message);
}

}  // namespace

std::optional<GlBackend> gl_backend_from_name(const std::string& name) {
  for (GlBackend b : {GlBackend::automatic, GlBackend::glfw, GlBackend::egl, GlBackend::egl_device,
                      GlBackend::egl_surfaceless})
    if (name == gl_backend_name(b)) return b;
  return std::nullopt;
}

const char* gl_backend_name(GlBackend b) {
  switch (b) {
    case GlBackend::glfw:
      return "glfw";
    case GlBackend::egl:
      return "egl";
    case GlBackend::egl_device:
      return "egl-device";
    case GlBackend::egl_surfaceless:
      return "egl-surfaceless";
    case GlBackend::automatic:
      break;
  }
  return "auto";
}

Result<GlBackend> resolve_gl_backend(const GlContextOptions& o) {
  GlBackend b = o.backend;
  if (b == GlBackend::automatic) {
    if (const char* env = std::getenv("VTS_GL"); env && *env) {
      auto named = gl_backend_from_name(env);
      if (!named)
        return make_error(ErrorCode::invalid_argument,
                          std::string("VTS_GL=") + env +
                              " is none of auto, glfw, egl, egl-device, egl-surfaceless");
      b = *named;
    }
  }
  if (b == GlBackend::automatic) {
    const bool display_named = std::getenv("DISPLAY") || std::getenv("WAYLAND_DISPLAY");
    b = o.visible || display_named ? GlBackend::glfw : GlBackend::egl;
  }
  if (o.visible && b != GlBackend::glfw)
    return make_error(ErrorCode::invalid_argument,
                      std::string("a visible window needs GLFW and a display, not ") +
                          gl_backend_name(b) + " (EGL renders headless only)");
  return b;
}

namespace {

Result<GLFWwindow*> open_glfw_window(const GlContextOptions& o) {
  std::lock_guard lock(g_mutex);
  if (g_users == 0) {
    glfwSetErrorCallback(on_glfw_error);
    // A display that is named but refuses the connection is retried briefly: an X server under
    // load (Xvfb in CI included) turns a connection away now and then. No display at all fails
    // at once.
    const bool display_named = std::getenv("DISPLAY") || std::getenv("WAYLAND_DISPLAY");
    bool ok = glfwInit() == GLFW_TRUE;
    for (int attempt = 0; !ok && display_named && attempt < 5; ++attempt) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20 << attempt));
      take_glfw_error();
      ok = glfwInit() == GLFW_TRUE;
    }
    if (!ok)
      return make_error(ErrorCode::unsupported,
                        "cannot open a display for OpenGL: " + take_glfw_error() +
                            "; without a screen, run under xvfb-run, or headless through EGL "
                            "(VTS_GL=egl)");
  }
  glfwDefaultWindowHints();
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 4);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 5);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  glfwWindowHint(GLFW_OPENGL_DEBUG_CONTEXT, o.debug ? GLFW_TRUE : GLFW_FALSE);
  glfwWindowHint(GLFW_VISIBLE, o.visible ? GLFW_TRUE : GLFW_FALSE);
  GLFWwindow* w = glfwCreateWindow(o.width, o.height, o.title.c_str(), nullptr, nullptr);
  if (w == nullptr) {
    const std::string why = take_glfw_error();
    if (g_users == 0) glfwTerminate();
    return make_error(ErrorCode::unsupported, "cannot create an OpenGL 4.5 core context: " + why);
  }
  ++g_users;
  glfwMakeContextCurrent(w);
  glfwSwapInterval(o.vsync ? 1 : 0);
  return w;
}

}  // namespace

Result<std::unique_ptr<GlContext>> GlContext::create(const GlContextOptions& o) {
  if (o.width <= 0 || o.height <= 0)
    return make_error(ErrorCode::invalid_argument, "window size must be positive, not " +
                                                       std::to_string(o.width) + "x" +
                                                       std::to_string(o.height));
  auto backend = resolve_gl_backend(o);
  if (!backend) return backend.error();
  std::unique_ptr<GlContext> c(new GlContext());
  c->width_ = o.width;
  c->height_ = o.height;
  if (*backend == GlBackend::glfw) {
    auto w = open_glfw_window(o);
    if (!w) return w.error();
    c->window_ = *w;
    c->info_.backend = "glfw";
  } else {
    int device = o.egl_device;
    if (const char* env = std::getenv("VTS_EGL_DEVICE"); device < 0 && env && *env) {
      char* end = nullptr;
      device = int(std::strtol(env, &end, 10));
      if (*end != '\0' || device < 0)
        return make_error(ErrorCode::invalid_argument,
                          std::string("VTS_EGL_DEVICE=") + env + " is not a device index");
    }
    auto egl = EglContext::create(*backend, device, o.debug, c->info_);
    if (!egl) return egl.error();
    c->egl_ = std::move(*egl);
  }
  if (Status s = c->finish(o); !s) return s.error();
  return c;
}

Status GlContext::finish(const GlContextOptions& o) {
#if VTS_GL_CHECKS
  gl_check::set_gl_thread();
#endif
  info_.version = epoxy_gl_version();
  info_.version_text = gl_string(GL_VERSION);
  info_.renderer = gl_string(GL_RENDERER);
  info_.vendor = gl_string(GL_VENDOR);
  if (info_.version < 45)
    return make_error(ErrorCode::unsupported, "OpenGL 4.5 core is needed; the driver gives " +
                                                  info_.version_text + " on " + info_.renderer +
                                                  " (" + info_.backend + ")");
  if (o.debug) {
    glEnable(GL_DEBUG_OUTPUT);
    glEnable(GL_DEBUG_OUTPUT_SYNCHRONOUS);
    glDebugMessageCallback(on_gl_debug, nullptr);
  }
  return {};
}

GlContext::~GlContext() {
  egl_.reset();
  if (window_ == nullptr) return;  // EGL, or a GLFW context that never got its window
  std::lock_guard lock(g_mutex);
  glfwDestroyWindow(window_);
  if (--g_users == 0) glfwTerminate();
}

void GlContext::make_current() {
  if (egl_)
    egl_->make_current();
  else
    glfwMakeContextCurrent(window_);
#if VTS_GL_CHECKS
  gl_check::set_gl_thread();
#endif
}
bool GlContext::should_close() const {
  return window_ && glfwWindowShouldClose(window_) == GLFW_TRUE;
}
void GlContext::swap_buffers() {
  if (window_) glfwSwapBuffers(window_);
}
void GlContext::poll_events() {
  if (window_) glfwPollEvents();
}
void GlContext::framebuffer_size(int& width, int& height) const {
  if (window_) {
    glfwGetFramebufferSize(window_, &width, &height);
  } else {
    width = width_;
    height = height_;
  }
}

bool GlContext::any_current() {
  // glfwGetCurrentContext is safe whether or not GLFW is initialised.
  return glfwGetCurrentContext() != nullptr || EglContext::any_current();
}

void GlContext::release_current() {
  std::lock_guard lock(g_mutex);
  if (g_users > 0) glfwMakeContextCurrent(nullptr);
  EglContext::release_current();
}

}  // namespace vts::renderer
