// GlContext's EGL side (gl_context.hpp): a 4.5 core context with no surface on the EGL device
// platform (EGL_EXT_platform_device) or Mesa's surfaceless platform. Internal to vts::renderer.
#pragma once

#include <memory>
#include <string>

#include "vts/base/result.hpp"
#include "vts/renderer/gl_context.hpp"

namespace vts::renderer {

class EglContext {
 public:
  // A context made current on the calling thread. `backend` is egl, egl_device or
  // egl_surfaceless; `device` an index into eglQueryDevicesEXT's list or -1 (the first hardware
  // device). Sets info.backend and info.device. Errors name what was missing: libEGL, a client
  // extension, a device, a display extension, the desktop OpenGL API, a 4.5 core context.
  static Result<std::unique_ptr<EglContext>> create(GlBackend backend, int device, bool debug,
                                                    GlInfo& info);
  ~EglContext();
  EglContext(const EglContext&) = delete;
  EglContext& operator=(const EglContext&) = delete;

  void make_current();
  // Whether an EGL context is current on this thread (false when libEGL was never loaded).
  static bool any_current();
  static void release_current();

 private:
  EglContext(void* display, void* context) : display_(display), context_(context) {}
  void* display_;  // EGLDisplay
  void* context_;  // EGLContext
};

}  // namespace vts::renderer
