// Move-only owners of GL object names: the name is deleted (glDelete*) when the handle is
// destroyed, reset or assigned over. Name 0 is "none" and is never deleted.
//
// Thread safety: GL-thread only; destroy a non-empty handle with its context current.
#pragma once

#include <utility>

namespace vts::renderer {

enum class GlKind { texture, buffer, framebuffer, vertex_array, program, shader };

// Deletes one name of `kind` (0: nothing).
void gl_delete(GlKind kind, unsigned name);

template <GlKind K>
class GlHandle {
 public:
  GlHandle() = default;
  explicit GlHandle(unsigned name) : name_(name) {}
  ~GlHandle() { reset(); }
  GlHandle(GlHandle&& o) noexcept : name_(std::exchange(o.name_, 0)) {}
  GlHandle& operator=(GlHandle&& o) noexcept {
    if (this != &o) reset(std::exchange(o.name_, 0));
    return *this;
  }
  GlHandle(const GlHandle&) = delete;
  GlHandle& operator=(const GlHandle&) = delete;

  unsigned get() const { return name_; }
  explicit operator bool() const { return name_ != 0; }
  // Deletes the name held, then owns `name`.
  void reset(unsigned name = 0) {
    if (name_ != 0) gl_delete(K, name_);
    name_ = name;
  }
  // For glCreate*(1, h.out()): deletes the name held, then receives the new one.
  unsigned* out() {
    reset();
    return &name_;
  }
  unsigned release() { return std::exchange(name_, 0); }

 private:
  unsigned name_ = 0;
};

using GlTexture = GlHandle<GlKind::texture>;
using GlBuffer = GlHandle<GlKind::buffer>;
using GlFramebuffer = GlHandle<GlKind::framebuffer>;
using GlVertexArray = GlHandle<GlKind::vertex_array>;
using GlProgram = GlHandle<GlKind::program>;
using GlShader = GlHandle<GlKind::shader>;

}  // namespace vts::renderer
