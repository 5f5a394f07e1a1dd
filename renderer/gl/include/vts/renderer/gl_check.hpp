// Debug checks of GL use: every GL-using entry point of the renderer opens a VTS_GL_CALL_SITE(),
// which asserts that it runs on the GL thread (the thread that created the context or last made
// it current) and reports GL errors raised before it (by the caller) and inside it, naming the
// call site. On when VTS_GL_CHECKS is 1, which it is by default in builds without NDEBUG;
// otherwise VTS_GL_CALL_SITE() is nothing and costs nothing. A translation unit may define
// VTS_GL_CHECKS itself before including this header.
#pragma once

#ifndef VTS_GL_CHECKS
#ifdef NDEBUG
#define VTS_GL_CHECKS 0
#else
#define VTS_GL_CHECKS 1
#endif
#endif

#include <string>

namespace vts::renderer::gl_check {

// Records the calling thread as the GL thread (GlContext::create and make_current call it).
void set_gl_thread();
// Aborts, naming `where` and both threads, when the caller is not the GL thread (or none was
// recorded yet: then the caller becomes the GL thread).
void assert_gl_thread(const char* where);
// Reads every pending GL error and reports each as "<where>: GL error <NAME> (0x....) <when>".
// Returns how many there were. Needs the GL thread.
int report_gl_errors(const char* where, const char* when);

// Where reports go: stderr by default. Returns the previous reporter; nullptr restores stderr.
using Reporter = void (*)(const std::string& message);
Reporter set_reporter(Reporter reporter);

// The scope of a GL-using entry point; `where` must outlive it (a string literal).
class CallSite {
 public:
  explicit CallSite(const char* where) : where_(where) {
    assert_gl_thread(where_);
    report_gl_errors(where_, "raised before it");
  }
  ~CallSite() { report_gl_errors(where_, "raised in it"); }
  CallSite(const CallSite&) = delete;
  CallSite& operator=(const CallSite&) = delete;

 private:
  const char* where_;
};

}  // namespace vts::renderer::gl_check

#define VTS_GL_STRINGIFY_(x) #x
#define VTS_GL_STRINGIFY(x) VTS_GL_STRINGIFY_(x)
#if VTS_GL_CHECKS
#define VTS_GL_CALL_SITE(name)                            \
  ::vts::renderer::gl_check::CallSite vts_gl_call_site_ { \
    name " (" __FILE__ ":" VTS_GL_STRINGIFY(__LINE__) ")" \
  }
#else
#define VTS_GL_CALL_SITE(name) static_cast<void>(0)
#endif
