// A UniformSink (scene.hpp) that writes into one GL program with glProgramUniform*: how the GL
// renderer hands a scene its program. Locations are looked up once per name and remembered (the
// names a scene passes are string literals, so the pointer is the key).
//
// Thread safety: GL-thread only, with a current context.
#pragma once

#include <unordered_map>

#include "vts/renderer/scene.hpp"

namespace vts::renderer {

class GlProgramUniforms final : public UniformSink {
 public:
  explicit GlProgramUniforms(unsigned program) : program_(program) {}
  unsigned program() const { return program_; }

  void set(const char* name, float x) override;
  void set(const char* name, float x, float y) override;
  void set(const char* name, float x, float y, float z) override;
  void set_int(const char* name, int x, int y) override;
  void set_int(const char* name, int x);
  void set_uint(const char* name, unsigned x);
  // The location of `name` (-1 when the program has no such active uniform; setting -1 is a
  // no-op in GL).
  int location(const char* name);

 private:
  unsigned program_;
  std::unordered_map<const char*, int> locations_;
};

}  // namespace vts::renderer
