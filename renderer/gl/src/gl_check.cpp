#include "vts/renderer/gl_check.hpp"

#include <epoxy/gl.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <thread>

namespace vts::renderer::gl_check {

namespace {

std::atomic<std::thread::id> g_gl_thread{};
std::atomic<Reporter> g_reporter{nullptr};

const char* error_name(GLenum e) {
  switch (e) {
    case GL_INVALID_ENUM:
      return "GL_INVALID_ENUM";
    case GL_INVALID_VALUE:
      return "GL_INVALID_VALUE";
    case GL_INVALID_OPERATION:
      return "GL_INVALID_OPERATION";
    case GL_INVALID_FRAMEBUFFER_OPERATION:
      return "GL_INVALID_FRAMEBUFFER_OPERATION";
    case GL_OUT_OF_MEMORY:
      return "GL_OUT_OF_MEMORY";
    case GL_STACK_UNDERFLOW:
      return "GL_STACK_UNDERFLOW";
    case GL_STACK_OVERFLOW:
      return "GL_STACK_OVERFLOW";
    default:
      return "unknown";
  }
}

void report(const std::string& message) {
  if (Reporter r = g_reporter.load()) {
    r(message);
  } else {
    std::fprintf(stderr, "vts: %s\n", message.c_str());
  }
}

}  // namespace

void set_gl_thread() {
  g_gl_thread.store(std::this_thread::get_id());
}

void assert_gl_thread(const char* where) {
  const std::thread::id self = std::this_thread::get_id();
  std::thread::id expected{};
  if (g_gl_thread.compare_exchange_strong(expected, self) || expected == self) return;
  std::ostringstream msg;
  msg << where << ": called on thread " << self << ", not the GL thread " << expected;
  std::fprintf(stderr, "vts: %s\n", msg.str().c_str());
  std::abort();
}

int report_gl_errors(const char* where, const char* when) {
  int n = 0;
  // A lost context keeps returning GL_CONTEXT_LOST; a bound keeps the loop finite.
  for (GLenum e = glGetError(); e != GL_NO_ERROR && n < 32; e = glGetError(), ++n) {
    char code[16];
    std::snprintf(code, sizeof code, "0x%04x", unsigned(e));
    report(std::string(where) + ": GL error " + error_name(e) + " (" + code + ") " + when);
  }
  return n;
}

Reporter set_reporter(Reporter reporter) {
  return g_reporter.exchange(reporter);
}

}  // namespace vts::renderer::gl_check
