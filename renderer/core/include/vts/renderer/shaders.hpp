// GLSL of the virtual-texturing passes (internal). One fragment source serves the colour pass and
// the feedback pass (#define FEEDBACK), so both compute the same coordinates and the same level;
// the scene (Scene::glsl()) answers which texel each pixel sees.
//
// Precision (docs/RENDERER.md, "Precision"): the CPU sends the eye relative to an integer anchor
// texel near the view centre, so the ray-plane hit `rel` is a small float whatever the image
// size; the shader then carries texel positions as integer (uint) texel + float fraction at every
// level. Derivatives are taken from `rel`, continuous, before any split or wrap.
#pragma once

namespace vts::renderer::detail {

inline constexpr const char* kFullscreenVertex = R"(#version 450 core
void main() {
  // One triangle covering the viewport: (-1,-1), (3,-1), (-1,3).
  vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
  gl_Position = vec4(p, 0.0, 1.0);
}
)";

// The virtual-texturing fragment code. Prepended: "#version 450 core", optionally
// "#define FEEDBACK" and "#define ANISOTROPIC" (anisotropy > 1: the tap loop and its level),
// "uniform vec2 u_viewport;" and the scene's GLSL (Scene::glsl()).
inline constexpr const char* kVirtualTextureFragment = R"(
const int kMaxLevels = 24;

uniform ivec2 u_anchor;      // integer finest texel the camera works relative to
uniform ivec2 u_image;       // finest image size in texels
uniform int u_max_level;
uniform float u_period;      // u period in finest texels (0: u does not wrap)
uniform int u_tile_shift;    // log2 T (tiles are powers of two: shifts, no integer division,
                             // which software rasterisers cannot vectorise)
uniform float u_level_offset;  // colour pass: -bias; feedback: +log2(k)
uniform int u_max_aniso;       // most taps along the footprint's major axis (1: isotropic)

#ifdef FEEDBACK
layout(location = 0) out uvec2 o_feedback;
#else
uniform usampler2DArray u_page_table;
uniform uvec2 u_origin[kMaxLevels];
uniform uint u_window;
uniform sampler2D u_physical;
uniform int u_slots_per_row;
uniform float u_slot_size;   // T + 2B
uniform float u_border;      // B
uniform vec2 u_atlas_inv;    // 1 / atlas size in texels
uniform bool u_trilinear;
uniform int u_debug;         // 0 none, 1 level tint
layout(location = 0) out vec4 o_color;

const vec3 kLevelTint[8] = vec3[8](vec3(1, 0.2, 0.2), vec3(1, 0.6, 0.1), vec3(0.9, 0.9, 0.1),
                                   vec3(0.3, 1, 0.3), vec3(0.1, 0.9, 0.9), vec3(0.3, 0.4, 1),
                                   vec3(0.7, 0.3, 1), vec3(1, 0.3, 0.8));

// Colour of level L at the finest texel anchor + ip + fr, through the page table: one table
// fetch at the finest level whose window holds the tile, then one bilinear sample in the slot of
// the nearest resident ancestor-or-self that entry names.
vec4 sample_level(int L, ivec2 abs_i, vec2 fr, out int mapped_level) {
  uint s = uint(u_max_level - L);
  uvec2 ai = uvec2(abs_i);
  uvec2 ti = ai >> s;                                                    // level-L texel
  vec2 tf = (vec2(ai & uvec2((1u << s) - 1u)) + fr) / float(1u << s);  // its fraction
  uvec2 tile = ti >> uint(u_tile_shift);
  int lvl = L;
  for (; lvl > 0; --lvl) {
    uvec2 o = u_origin[lvl];
    if (all(lessThan(tile - o, uvec2(u_window)))) break;  // unsigned: below origin wraps high
    tile >>= 1u;
  }
  uint e = texelFetch(u_page_table, ivec3(tile & uvec2(u_window - 1u), lvl), 0).r;
  if ((e & 0x80000000u) == 0u) {
    mapped_level = -1;
    return vec4(1, 0, 1, 1);  // nothing resident yet, not even the root
  }
  int m = int((e >> 26) & 31u);
  uint slot = e & 0x3ffffffu;
  uint d = uint(L - m);
  uvec2 tm = ti >> d;                                                  // texel at level m
  vec2 fm = (vec2(ti & uvec2((1u << d) - 1u)) + tf) / float(1u << d);  // its fraction
  vec2 pos = vec2(tm & ((1u << uint(u_tile_shift)) - 1u)) + fm;                             // inside the tile, [0, T)
  // The bilinear footprint stays inside the slot: a no-op for tiles with a border (B >= 1 covers
  // the half texel), and for borderless tiles (third-party images, B = 0) it keeps filtering
  // inside the tile's content instead of blending in the neighbouring slot's unrelated texels.
  float tile_size = float(1u << uint(u_tile_shift));
  pos = clamp(pos, vec2(0.5 - u_border), vec2(tile_size + u_border - 0.5));
  // slot < 2^24: exact in float, so row = floor((slot + 0.5) / per_row) needs no integer division.
  float row = floor((float(slot) + 0.5) / float(u_slots_per_row));
  vec2 slot_xy = vec2(float(slot) - row * float(u_slots_per_row), row);
  vec2 uv = (slot_xy * u_slot_size + u_border + pos) * u_atlas_inv;
  mapped_level = m;
  return textureLod(u_physical, uv, 0.0);
}

// One filtered sample at finest texel q + qf: bilinear at the finer level only, or trilinear
// between L0 and L0 + 1 with weight w on the coarser. a, b: the levels actually mapped.
vec4 filtered(ivec2 q, vec2 qf, float c, int L0, float w, out int a, out int b) {
  a = -1;
  b = -1;
  if (!u_trilinear) return sample_level(int(ceil(c)), q, qf, a);
  if (L0 >= u_max_level || w == 0.0) return sample_level(L0, q, qf, a);
  return mix(sample_level(L0, q, qf, a), sample_level(L0 + 1, q, qf, b), w);
}
#endif

// The texel (integer + fraction) a filter tap lands on, brought into the image: u wrapped where
// the surface wraps, else clamped to the edge texel's centre (clamp-to-edge at every level).
void tap_into_image(inout ivec2 q, inout vec2 f) {
  if (u_period > 0.0) {
    int period = int(u_period);
    q.x -= period * int(floor(float(q.x) / u_period));
    q.x = q.x < 0 ? q.x + period : (q.x >= period ? q.x - period : q.x);
  } else if (q.x < 0 || q.x >= u_image.x) {
    q.x = clamp(q.x, 0, u_image.x - 1);
    f.x = 0.5;
  }
  if (q.y < 0 || q.y >= u_image.y) {
    q.y = clamp(q.y, 0, u_image.y - 1);
    f.y = 0.5;
  }
}

void main() {
  // Rows top to bottom, as the scene's camera counts them.
  vec2 px = vec2(gl_FragCoord.x, u_viewport.y - gl_FragCoord.y);
  vec2 rel;
  bool hit = scene_hit(px, rel);
  // Derivatives first, in uniform control flow, from the continuous coordinate; a surface that
  // wraps in u (the globe's date line) is unwrapped so the seam does not look like a huge step.
  vec2 ddx = dFdxFine(rel);
  vec2 ddy = dFdyFine(rel);
  if (u_period > 0.0) {
    ddx.x -= u_period * round(ddx.x / u_period);
    ddy.x -= u_period * round(ddy.x / u_period);
  }

  hit = hit && !any(isnan(rel)) && !any(isinf(rel)) && all(lessThan(abs(rel), vec2(1.0e9)));
  ivec2 ip = hit ? ivec2(floor(rel)) : ivec2(0);
  vec2 fr = rel - floor(rel);
  ivec2 abs_i = u_anchor + ip;
  if (u_period > 0.0) {  // a surface that wraps in u: back into [0, W)
    int period = int(u_period);
    abs_i.x -= period * int(floor(float(abs_i.x) / u_period));  // exact: |abs_i.x| << 2^24 here
    abs_i.x = abs_i.x < 0 ? abs_i.x + period : (abs_i.x >= period ? abs_i.x - period : abs_i.x);
  }
  hit = hit && all(greaterThanEqual(abs_i, ivec2(0))) && all(lessThan(abs_i, u_image));

  // The footprint: its major axis gets up to u_max_aniso taps, and the level is chosen for what
  // one tap covers, max(major / taps, minor) (reference.hpp states the same rule in double).
  float lx = length(ddx), ly = length(ddy);
  float major = max(lx, ly), minor = min(lx, ly);
  int taps = 1;
#ifdef ANISOTROPIC
  if (major > 0.0 && !isinf(major)) {
    float ratio = minor > 0.0 ? major / minor : float(u_max_aniso);
    taps = int(clamp(ceil(ratio), 1.0, float(u_max_aniso)));
  }
#endif
  float rho = max(major / float(taps), minor);
  float c = float(u_max_level) - log2(rho) + u_level_offset;  // rho = 0 gives +inf: finest
  if (isnan(c)) c = float(u_max_level);
  c = clamp(c, 0.0, float(u_max_level));

#ifdef FEEDBACK
  if (!hit) {
    o_feedback = uvec2(0xffffffffu);
    return;
  }
  int L = int(ceil(c));
  uint f = min(uint((float(L) - c) * 256.0), 255u);
  uint s = uint(u_max_level - L);
  uvec2 tile = (uvec2(abs_i) >> s) >> uint(u_tile_shift);
  o_feedback = uvec2(tile.x | (uint(L) << 24), tile.y | (f << 24));
#else
  if (!hit) {
    o_color = vec4(0, 0, 0, 1);
    return;
  }
  int L0 = int(floor(c));
  float w = c - float(L0);
  vec4 col;
  int m0 = -1, m1 = -1;
#ifndef ANISOTROPIC
  {
    // Isotropic: the pixel itself. A variant of its own: a software rasteriser runs a loop it
    // never enters under a mask (it doubled llvmpipe's frame).
    col = filtered(abs_i, fr, c, L0, w, m0, m1);
  }
#else
  {
    vec2 axis = lx >= ly ? ddx : ddy;
    col = vec4(0);
    for (int i = 0; i < taps; ++i) {
      // Taps spread evenly over the major axis, centred on the pixel.
      vec2 p = fr + axis * ((float(i) + 0.5) / float(taps) - 0.5);
      p = clamp(p, vec2(-1.0e9), vec2(1.0e9));  // a horizon footprint: keep int conversion defined
      vec2 pf = floor(p);
      ivec2 q = abs_i + ivec2(pf);
      vec2 qf = p - pf;
      tap_into_image(q, qf);
      int a, b;
      col += filtered(q, qf, c, L0, w, a, b);
      m0 = max(m0, a);
      m1 = max(m1, b);
    }
    col /= float(taps);
  }
#endif
  if (u_debug == 1) {
    int m = max(m0, m1);
    col.rgb = m < 0 ? vec3(1, 0, 1) : mix(col.rgb, kLevelTint[m % 8], 0.5);
  }
  // Straight alpha (docs/FORMAT.md) over the viewer's black background (kBackground, the colour
  // outside the image): a transparent texel shows what lies outside the image, never its own RGB.
  // `col` is the filtered straight colour and alpha; the reference composites the same way.
  o_color = vec4(col.rgb * col.a, 1.0);
#endif
}
)";

// The physical texture over the whole screen (DebugView::physical), and the page-table layer
// (DebugView::page_table) as one colour per slot.
inline constexpr const char* kDebugFragment = R"(#version 450 core
uniform sampler2D u_physical;
uniform usampler2DArray u_page_table;
uniform int u_mode;   // 2 physical, 3 page table
uniform int u_layer;
uniform vec2 u_viewport;
layout(location = 0) out vec4 o_color;
void main() {
  vec2 uv = vec2(gl_FragCoord.x / u_viewport.x, 1.0 - gl_FragCoord.y / u_viewport.y);
  if (u_mode == 2) {
    o_color = vec4(textureLod(u_physical, uv, 0.0).rgb, 1.0);
    return;
  }
  ivec3 size = textureSize(u_page_table, 0);
  uint e = texelFetch(u_page_table, ivec3(uv * vec2(size.xy), u_layer), 0).r;
  if ((e & 0x80000000u) == 0u) {
    o_color = vec4(0, 0, 0, 1);
    return;
  }
  uint slot = e & 0x3ffffffu;
  uint h = slot * 2654435761u;
  o_color = vec4(float(h & 255u) / 255.0, float((h >> 8) & 255u) / 255.0,
                 float((e >> 26) & 31u) / 24.0, 1.0);
}
)";

// The plane scene (PlaneScene::glsl()): a ray from the eye through the pixel meets w = 0.
inline constexpr const char* kPlaneScene = R"(
uniform vec3 u_eye_rel;  // eye - anchor, finest texels (u right, v down, w into the ground)
uniform vec3 u_forward;
uniform vec3 u_right;
uniform vec3 u_up;
uniform float u_tan_half_fov;
uniform float u_aspect;

bool scene_hit(vec2 px, out vec2 rel) {
  float nx = (2.0 * px.x / u_viewport.x - 1.0) * u_tan_half_fov * u_aspect;
  float ny = (1.0 - 2.0 * px.y / u_viewport.y) * u_tan_half_fov;
  vec3 d = u_forward + u_right * nx + u_up * ny;
  float t = -u_eye_rel.z / d.z;
  rel = u_eye_rel.xy + t * d.xy;
  return d.z > 0.0;
}
)";

}  // namespace vts::renderer::detail
