// One hidden GL context for every renderer test of the process: opening a display per test adds
// nothing to what is tested and makes X connections the test's busiest resource.
#pragma once

#include <gtest/gtest.h>

#include <memory>
#include <string>

#include "vts/renderer/gl_context.hpp"

namespace vts::test {

// The context, current on the calling (main) thread; nullptr with the reason in `error`. Created
// on first use and kept until the process exits.
inline renderer::GlContext* shared_gl_context(std::string* error = nullptr) {
  static std::string failure;
  static renderer::GlContext* context = [] {
    renderer::GlContextOptions o;
    o.width = 64;
    o.height = 64;
    o.visible = false;
    o.vsync = false;
    auto c = renderer::GlContext::create(o);
    if (!c.ok()) {
      failure = c.error().to_string();
      return static_cast<renderer::GlContext*>(nullptr);
    }
    return c->release();  // lives until exit: no GLFW teardown in static destructors
  }();
  if (context) context->make_current();
  if (error) *error = failure;
  return context;
}

}  // namespace vts::test
