// Building a GL program from vertex + fragment GLSL, with the driver's log in the error: what the
// virtual texture, the HUD and the renderer benchmark share.
//
// Thread safety: GL-thread only, with a current context.
#pragma once

#include <string>

#include "vts/base/result.hpp"
#include "vts/renderer/gl_handle.hpp"

namespace vts::renderer {

// The linked program. unsupported naming `what` (e.g. "plane colour") and carrying the compile or
// link log when the driver refuses either shader or the link; nothing is left behind.
Result<GlProgram> link_program(const std::string& vertex, const std::string& fragment,
                               const std::string& what);

}  // namespace vts::renderer
