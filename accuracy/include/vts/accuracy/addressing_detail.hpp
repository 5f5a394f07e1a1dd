// Internal to the addressing table (accuracy_addressing.cpp) and its test: the lines of the
// virtual-texturing fragment shader (renderer/core/include/vts/renderer/shaders.hpp, main()) that
// the table's "ours" pass runs, kept here word for word. The table checks at run time that each is
// still a part of the production shader (whitespace aside), so it never publishes figures for code
// that is not shipped.
#pragma once

#include <string>
#include <string_view>

namespace vts::accuracy::detail_addressing {

// The pixel and the scene's hit, relative to the anchor.
inline constexpr const char* kOursHit = R"(
  vec2 px = vec2(gl_FragCoord.x, u_viewport.y - gl_FragCoord.y);
  vec2 rel;
  bool hit = scene_hit(px, rel);
)";

// The footprint's derivatives, from the continuous rel.
inline constexpr const char* kOursDerivatives = R"(
  vec2 ddx = dFdxFine(rel);
  vec2 ddy = dFdyFine(rel);
)";

// The split into integer texel + fraction.
inline constexpr const char* kOursSplit = R"(
  hit = hit && !any(isnan(rel)) && !any(isinf(rel)) && all(lessThan(abs(rel), vec2(1.0e9)));
  ivec2 ip = hit ? ivec2(floor(rel)) : ivec2(0);
  vec2 fr = rel - floor(rel);
  ivec2 abs_i = u_anchor + ip;
)";

// `s` without spaces, tabs and line breaks.
std::string squeeze(std::string_view s);
// Whether the production virtual-texturing fragment shader contains `snippet` (whitespace aside).
bool production_has(std::string_view snippet);

}  // namespace vts::accuracy::detail_addressing
