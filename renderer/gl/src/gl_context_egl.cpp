#include "gl_context_egl.hpp"

// clang-format off
#include <epoxy/egl.h>  // in place of EGL/egl.h; no X11 headers (eglplatform.h without USE_X11)
// clang-format on

#include <dlfcn.h>

#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <sstream>
#include <vector>

namespace vts::renderer {
namespace {

// Displays this process initialised, with the contexts on each: eglTerminate would end every
// context of a display, so it waits for the last one.
std::mutex g_egl_mutex;
std::map<EGLDisplay, int> g_displays;

bool has_token(const char* list, const char* name) {
  if (list == nullptr) return false;
  const std::size_t n = std::strlen(name);
  for (const char* p = list; (p = std::strstr(p, name)) != nullptr; p += n) {
    const bool starts = p == list || p[-1] == ' ';
    const bool ends = p[n] == '\0' || p[n] == ' ';
    if (starts && ends) return true;
  }
  return false;
}

std::string egl_error_name(EGLint e) {
  switch (e) {
    case EGL_NOT_INITIALIZED:
      return "EGL_NOT_INITIALIZED";
    case EGL_BAD_ACCESS:
      return "EGL_BAD_ACCESS";
    case EGL_BAD_ALLOC:
      return "EGL_BAD_ALLOC";
    case EGL_BAD_ATTRIBUTE:
      return "EGL_BAD_ATTRIBUTE";
    case EGL_BAD_CONFIG:
      return "EGL_BAD_CONFIG";
    case EGL_BAD_CONTEXT:
      return "EGL_BAD_CONTEXT";
    case EGL_BAD_DISPLAY:
      return "EGL_BAD_DISPLAY";
    case EGL_BAD_MATCH:
      return "EGL_BAD_MATCH";
    case EGL_BAD_PARAMETER:
      return "EGL_BAD_PARAMETER";
    case EGL_BAD_DEVICE_EXT:
      return "EGL_BAD_DEVICE_EXT";
    default:
      break;
  }
  std::ostringstream s;
  s << "EGL error 0x" << std::hex << e;
  return s.str();
}

Error egl_failure(const std::string& what) {
  return make_error(ErrorCode::unsupported, what + " (" + egl_error_name(eglGetError()) + ")");
}

// libEGL (glvnd's or a vendor's), loaded before libepoxy would, which aborts without it.
Status load_libegl() {
  static void* handle = dlopen("libEGL.so.1", RTLD_NOW | RTLD_GLOBAL);
  if (handle == nullptr)
    return make_error(ErrorCode::unsupported,
                      "no EGL: libEGL.so.1 cannot be loaded (install libegl1 and the GPU's EGL "
                      "driver, e.g. libegl-mesa0 or NVIDIA's)");
  return {};
}

// A display of eglGetPlatformDisplayEXT, initialised (counted in g_displays).
Result<EGLDisplay> init_display(EGLenum platform, void* native, const std::string& name) {
  EGLDisplay d = eglGetPlatformDisplayEXT(platform, native, nullptr);
  if (d == EGL_NO_DISPLAY) return egl_failure("EGL gives no display for " + name);
  EGLint major = 0, minor = 0;
  if (eglInitialize(d, &major, &minor) != EGL_TRUE)
    return egl_failure("EGL cannot initialise " + name);
  std::lock_guard lock(g_egl_mutex);
  ++g_displays[d];
  return d;
}

void release_display(EGLDisplay d) {
  std::lock_guard lock(g_egl_mutex);
  auto it = g_displays.find(d);
  if (it == g_displays.end() || --it->second > 0) return;
  g_displays.erase(it);
  eglTerminate(d);
}

struct EglDevice {
  EGLDeviceEXT handle = nullptr;
  bool software = false;
  std::string text;  // "software (Mesa)" or its DRM device file, and its extensions
};

Result<std::vector<EglDevice>> list_devices(const char* client) {
  const bool enumerate =
      has_token(client, "EGL_EXT_device_enumeration") || has_token(client, "EGL_EXT_device_base");
  if (!enumerate || !has_token(client, "EGL_EXT_platform_device"))
    return make_error(ErrorCode::unsupported,
                      std::string("no EGL device platform: the EGL client lacks ") +
                          (enumerate ? "EGL_EXT_platform_device" : "EGL_EXT_device_enumeration"));
  EGLint n = 0;
  if (eglQueryDevicesEXT(0, nullptr, &n) != EGL_TRUE) return egl_failure("eglQueryDevicesEXT");
  std::vector<EGLDeviceEXT> handles(std::size_t(std::max(n, 0)));
  if (n > 0 && eglQueryDevicesEXT(n, handles.data(), &n) != EGL_TRUE)
    return egl_failure("eglQueryDevicesEXT");
  std::vector<EglDevice> out;
  for (EGLint i = 0; i < n; ++i) {
    EglDevice d;
    d.handle = handles[std::size_t(i)];
    const char* exts = eglQueryDeviceStringEXT(d.handle, EGL_EXTENSIONS);
    d.software = has_token(exts, "EGL_MESA_device_software");
    const char* file = has_token(exts, "EGL_EXT_device_drm")
                           ? eglQueryDeviceStringEXT(d.handle, EGL_DRM_DEVICE_FILE_EXT)
                           : nullptr;
    d.text = d.software ? "software" : file ? file : "no DRM file";
    d.text += std::string(" (") + (exts ? exts : "") + ")";
    out.push_back(std::move(d));
  }
  return out;
}

struct Opened {
  EGLDisplay display = EGL_NO_DISPLAY;
  std::string backend, device;
};

// The device platform: `index`, or the first hardware device that initialises, or (with
// software_ok) a software one.
Result<Opened> open_device(const char* client, int index, bool software_ok) {
  auto devices = list_devices(client);
  if (!devices) return devices.error();
  const int n = int(devices->size());
  const std::string of = " of " + std::to_string(n);
  if (index >= n)
    return make_error(ErrorCode::invalid_argument, "EGL device " + std::to_string(index) +
                                                       " asked for, but EGL lists " +
                                                       std::to_string(n) + " devices");
  std::string tried;
  for (bool software : {false, true}) {
    for (int i = 0; i < n; ++i) {
      const EglDevice& d = (*devices)[std::size_t(i)];
      if (index >= 0 ? i != index : (d.software != software || (software && !software_ok)))
        continue;
      const std::string name = "EGL device " + std::to_string(i) + of + ": " + d.text;
      auto display = init_display(EGL_PLATFORM_DEVICE_EXT, d.handle, name);
      if (display) return Opened{*display, "egl-device", name.substr(4)};
      tried += "; " + display.error().message;
    }
    if (index >= 0) break;
  }
  std::string listed;
  for (const auto& d : *devices) listed += (listed.empty() ? "" : ", ") + d.text;
  return make_error(ErrorCode::unsupported,
                    "no usable EGL device: EGL lists " + std::to_string(n) + " device(s)" +
                        (n ? ": " + listed : "") +
                        (software_ok || index >= 0 ? "" : ", none of them hardware") + tried);
}

Result<Opened> open_surfaceless(const char* client) {
  if (!has_token(client, "EGL_MESA_platform_surfaceless"))
    return make_error(ErrorCode::unsupported,
                      "no EGL surfaceless platform: the EGL client lacks "
                      "EGL_MESA_platform_surfaceless (Mesa's)");
  auto display = init_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY,
                              "the surfaceless platform (EGL_MESA_platform_surfaceless)");
  if (!display) return display.error();
  return Opened{*display, "egl-surfaceless", ""};
}

// egl: a hardware device, else Mesa's surfaceless platform, else a software device.
// EGL_PLATFORM=surfaceless or =device (Mesa's variable) asks for that platform.
Result<Opened> open_display(GlBackend backend, int index) {
  if (Status s = load_libegl(); !s) return s.error();
  const char* client = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
  if (client == nullptr || !has_token(client, "EGL_EXT_platform_base"))
    return make_error(ErrorCode::unsupported,
                      "EGL is too old: no client extensions or no EGL_EXT_platform_base");
  const char* env = std::getenv("EGL_PLATFORM");
  const std::string platform = env ? env : "";
  if (backend == GlBackend::egl_surfaceless ||
      (backend == GlBackend::egl && index < 0 && platform == "surfaceless"))
    return open_surfaceless(client);
  if (backend == GlBackend::egl_device || index >= 0 || platform == "device")
    return open_device(client, index, true);
  auto hardware = open_device(client, -1, false);
  if (hardware) return hardware;
  auto surfaceless = open_surfaceless(client);
  if (surfaceless) return surfaceless;
  auto software = open_device(client, -1, true);
  if (software) return software;
  return make_error(ErrorCode::unsupported,
                    "no EGL platform renders here: " + hardware.error().message + "; " +
                        surfaceless.error().message);
}

// A config for desktop OpenGL (no surface is ever made of it), or EGL_NO_CONFIG_KHR.
Result<EGLConfig> choose_config(EGLDisplay d) {
  const EGLint attribs[] = {EGL_SURFACE_TYPE,
                            EGL_PBUFFER_BIT,
                            EGL_RENDERABLE_TYPE,
                            EGL_OPENGL_BIT,
                            EGL_RED_SIZE,
                            8,
                            EGL_GREEN_SIZE,
                            8,
                            EGL_BLUE_SIZE,
                            8,
                            EGL_ALPHA_SIZE,
                            8,
                            EGL_NONE};
  EGLConfig config = nullptr;
  EGLint n = 0;
  if (eglChooseConfig(d, attribs, &config, 1, &n) == EGL_TRUE && n > 0) return config;
  if (has_token(eglQueryString(d, EGL_EXTENSIONS), "EGL_KHR_no_config_context"))
    return EGLConfig(EGL_NO_CONFIG_KHR);
  return egl_failure("no EGL config renders desktop OpenGL (EGL_OPENGL_BIT, RGBA8)");
}

Result<EGLContext> core_context(EGLDisplay d, bool debug, const std::string& where) {
  const char* exts = eglQueryString(d, EGL_EXTENSIONS);
  for (const char* ext : {"EGL_KHR_surfaceless_context", "EGL_KHR_create_context"})
    if (!has_token(exts, ext))
      return make_error(ErrorCode::unsupported, where + " lacks " + ext +
                                                    " (needed for a 4.5 core context with no "
                                                    "surface)");
  if (eglBindAPI(EGL_OPENGL_API) != EGL_TRUE)
    return egl_failure(where + " offers no desktop OpenGL (eglBindAPI(EGL_OPENGL_API))");
  auto config = choose_config(d);
  if (!config) return make_error(config.error().code, where + ": " + config.error().message);
  const EGLint flags = EGL_CONTEXT_OPENGL_FORWARD_COMPATIBLE_BIT_KHR |
                       (debug ? EGL_CONTEXT_OPENGL_DEBUG_BIT_KHR : 0);
  const EGLint attribs[] = {EGL_CONTEXT_MAJOR_VERSION_KHR,
                            4,
                            EGL_CONTEXT_MINOR_VERSION_KHR,
                            5,
                            EGL_CONTEXT_OPENGL_PROFILE_MASK_KHR,
                            EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT_KHR,
                            EGL_CONTEXT_FLAGS_KHR,
                            flags,
                            EGL_NONE};
  EGLContext c = eglCreateContext(d, *config, EGL_NO_CONTEXT, attribs);
  if (c == EGL_NO_CONTEXT) return egl_failure("no OpenGL 4.5 core context from " + where);
  if (eglMakeCurrent(d, EGL_NO_SURFACE, EGL_NO_SURFACE, c) != EGL_TRUE) {
    auto e = egl_failure("cannot make the surfaceless context current on " + where);
    eglDestroyContext(d, c);
    return e;
  }
  return c;
}

}  // namespace

Result<std::unique_ptr<EglContext>> EglContext::create(GlBackend backend, int device, bool debug,
                                                       GlInfo& info) {
  auto opened = open_display(backend, device);
  if (!opened) return opened.error();
  const std::string where =
      opened->device.empty() ? "the EGL surfaceless platform" : "EGL " + opened->device;
  auto context = core_context(opened->display, debug, where);
  if (!context) {
    release_display(opened->display);
    return context.error();
  }
  info.backend = opened->backend;
  info.device = opened->device;
  return std::unique_ptr<EglContext>(new EglContext(opened->display, *context));
}

EglContext::~EglContext() {
  if (eglGetCurrentContext() == context_)
    eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
  eglDestroyContext(display_, context_);
  release_display(display_);
}

void EglContext::make_current() {
  eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, context_);
}

bool EglContext::any_current() {
  // Without libEGL in the process no EGL context can be current (and libepoxy would abort).
  void* loaded = dlopen("libEGL.so.1", RTLD_LAZY | RTLD_NOLOAD);
  if (loaded == nullptr) return false;
  dlclose(loaded);
  return eglGetCurrentContext() != EGL_NO_CONTEXT;
}

void EglContext::release_current() {
  if (!any_current()) return;
  eglMakeCurrent(eglGetCurrentDisplay(), EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
}

}  // namespace vts::renderer
