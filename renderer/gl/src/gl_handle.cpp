#include "vts/renderer/gl_handle.hpp"

#include "vts/renderer/gl_check.hpp"

#include <epoxy/gl.h>

namespace vts::renderer {

void gl_delete(GlKind kind, unsigned name) {
  VTS_GL_CALL_SITE("gl_delete");
  if (name == 0) return;
  const GLuint n = name;
  switch (kind) {
    case GlKind::texture:
      glDeleteTextures(1, &n);
      break;
    case GlKind::buffer:
      glDeleteBuffers(1, &n);
      break;
    case GlKind::framebuffer:
      glDeleteFramebuffers(1, &n);
      break;
    case GlKind::vertex_array:
      glDeleteVertexArrays(1, &n);
      break;
    case GlKind::program:
      glDeleteProgram(n);
      break;
    case GlKind::shader:
      glDeleteShader(n);
      break;
  }
}

}  // namespace vts::renderer
