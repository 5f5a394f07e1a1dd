#include "vts/renderer/gl_program.hpp"

#include "vts/renderer/gl_check.hpp"

#include <epoxy/gl.h>

#include <algorithm>

namespace vts::renderer {

namespace {

Error driver_error(std::string what) {
  return Error{ErrorCode::unsupported, std::move(what)};
}

Result<GlShader> compile(GLenum type, const std::string& source, const std::string& what) {
  GlShader s(glCreateShader(type));
  const char* text = source.c_str();
  glShaderSource(s.get(), 1, &text, nullptr);
  glCompileShader(s.get());
  GLint ok = 0;
  glGetShaderiv(s.get(), GL_COMPILE_STATUS, &ok);
  if (!ok) {
    GLint len = 0;
    glGetShaderiv(s.get(), GL_INFO_LOG_LENGTH, &len);
    std::string log(std::size_t(std::max(len, 1)), '\0');
    glGetShaderInfoLog(s.get(), GLsizei(log.size()), nullptr, log.data());
    return driver_error("compiling the " + what +
                        (type == GL_VERTEX_SHADER ? " vertex" : " fragment") +
                        " shader failed: " + log.c_str());
  }
  return s;
}

}  // namespace

Result<GlProgram> link_program(const std::string& vertex, const std::string& fragment,
                               const std::string& what) {
  VTS_GL_CALL_SITE("link_program");
  auto v = compile(GL_VERTEX_SHADER, vertex, what);
  if (!v) return v.error();
  auto f = compile(GL_FRAGMENT_SHADER, fragment, what);
  if (!f) return f.error();
  GlProgram p(glCreateProgram());
  glAttachShader(p.get(), v->get());
  glAttachShader(p.get(), f->get());
  glLinkProgram(p.get());
  v->reset();  // flagged for deletion; freed with the program
  f->reset();
  GLint ok = 0;
  glGetProgramiv(p.get(), GL_LINK_STATUS, &ok);
  if (!ok) {
    GLint len = 0;
    glGetProgramiv(p.get(), GL_INFO_LOG_LENGTH, &len);
    std::string log(std::size_t(std::max(len, 1)), '\0');
    glGetProgramInfoLog(p.get(), GLsizei(log.size()), nullptr, log.data());
    return driver_error("linking the " + what + " program failed: " + log.c_str());
  }
  return p;
}

}  // namespace vts::renderer
