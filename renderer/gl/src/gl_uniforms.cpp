#include "vts/renderer/gl_uniforms.hpp"

#include <epoxy/gl.h>

namespace vts::renderer {

int GlProgramUniforms::location(const char* name) {
  auto it = locations_.find(name);
  if (it == locations_.end())
    it = locations_.emplace(name, glGetUniformLocation(program_, name)).first;
  return it->second;
}

void GlProgramUniforms::set(const char* name, float x) {
  glProgramUniform1f(program_, location(name), x);
}

void GlProgramUniforms::set(const char* name, float x, float y) {
  glProgramUniform2f(program_, location(name), x, y);
}

void GlProgramUniforms::set(const char* name, float x, float y, float z) {
  glProgramUniform3f(program_, location(name), x, y, z);
}

void GlProgramUniforms::set_int(const char* name, int x, int y) {
  glProgramUniform2i(program_, location(name), x, y);
}

void GlProgramUniforms::set_int(const char* name, int x) {
  glProgramUniform1i(program_, location(name), x);
}

void GlProgramUniforms::set_uint(const char* name, unsigned x) {
  glProgramUniform1ui(program_, location(name), x);
}

}  // namespace vts::renderer
