#include "vts/renderer/gl_program.hpp"

#include <epoxy/gl.h>

#include <algorithm>

namespace vts::renderer {

namespace {

Error driver_error(std::string what) {
  return Error{ErrorCode::unsupported, std::move(what)};
}

Result<GLuint> compile(GLenum type, const std::string& source, const std::string& what) {
  GLuint s = glCreateShader(type);
  const char* text = source.c_str();
  glShaderSource(s, 1, &text, nullptr);
  glCompileShader(s);
  GLint ok = 0;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    GLint len = 0;
    glGetShaderiv(s, GL_INFO_LOG_LENGTH, &len);
    std::string log(std::size_t(std::max(len, 1)), '\0');
    glGetShaderInfoLog(s, GLsizei(log.size()), nullptr, log.data());
    glDeleteShader(s);
    return driver_error("compiling the " + what +
                        (type == GL_VERTEX_SHADER ? " vertex" : " fragment") +
                        " shader failed: " + log.c_str());
  }
  return s;
}

}  // namespace

Result<unsigned> link_program(const std::string& vertex, const std::string& fragment,
                              const std::string& what) {
  auto v = compile(GL_VERTEX_SHADER, vertex, what);
  if (!v) return v.error();
  auto f = compile(GL_FRAGMENT_SHADER, fragment, what);
  if (!f) {
    glDeleteShader(*v);
    return f.error();
  }
  GLuint p = glCreateProgram();
  glAttachShader(p, *v);
  glAttachShader(p, *f);
  glLinkProgram(p);
  glDeleteShader(*v);
  glDeleteShader(*f);
  GLint ok = 0;
  glGetProgramiv(p, GL_LINK_STATUS, &ok);
  if (!ok) {
    GLint len = 0;
    glGetProgramiv(p, GL_INFO_LOG_LENGTH, &len);
    std::string log(std::size_t(std::max(len, 1)), '\0');
    glGetProgramInfoLog(p, GLsizei(log.size()), nullptr, log.data());
    glDeleteProgram(p);
    return driver_error("linking the " + what + " program failed: " + log.c_str());
  }
  return unsigned(p);
}

}  // namespace vts::renderer
