#include "vts/renderer/gl_context.hpp"

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

Result<std::unique_ptr<GlContext>> GlContext::create(const GlContextOptions& o) {
  if (o.width <= 0 || o.height <= 0)
    return make_error(ErrorCode::invalid_argument, "window size must be positive, not " +
                                                       std::to_string(o.width) + "x" +
                                                       std::to_string(o.height));
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
                            "; without a screen, run under xvfb-run");
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
  std::unique_ptr<GlContext> c(new GlContext(w));
  glfwMakeContextCurrent(w);
#if VTS_GL_CHECKS
  gl_check::set_gl_thread();
#endif
  glfwSwapInterval(o.vsync ? 1 : 0);
  c->info_.version = epoxy_gl_version();
  c->info_.version_text = gl_string(GL_VERSION);
  c->info_.renderer = gl_string(GL_RENDERER);
  c->info_.vendor = gl_string(GL_VENDOR);
  if (c->info_.version < 45)
    return make_error(ErrorCode::unsupported, "OpenGL 4.5 core is needed; the driver gives " +
                                                  c->info_.version_text + " on " +
                                                  c->info_.renderer);
  if (o.debug) {
    glEnable(GL_DEBUG_OUTPUT);
    glEnable(GL_DEBUG_OUTPUT_SYNCHRONOUS);
    glDebugMessageCallback(on_gl_debug, nullptr);
  }
  return c;
}

GlContext::~GlContext() {
  std::lock_guard lock(g_mutex);
  glfwDestroyWindow(window_);
  if (--g_users == 0) glfwTerminate();
}

void GlContext::make_current() {
  glfwMakeContextCurrent(window_);
#if VTS_GL_CHECKS
  gl_check::set_gl_thread();
#endif
}
bool GlContext::should_close() const {
  return glfwWindowShouldClose(window_) == GLFW_TRUE;
}
void GlContext::swap_buffers() {
  glfwSwapBuffers(window_);
}
void GlContext::poll_events() {
  glfwPollEvents();
}
void GlContext::framebuffer_size(int& width, int& height) const {
  glfwGetFramebufferSize(window_, &width, &height);
}

}  // namespace vts::renderer
