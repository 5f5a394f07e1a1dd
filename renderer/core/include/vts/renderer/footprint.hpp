// The per-pixel footprint rule shared by everything that decides which texels a pixel sees: the
// GPU shader (shaders.hpp, in GLSL), the reference renderer (reference.hpp) and the load test's
// demand simulator (demand.hpp), the last two through this header so they cannot drift apart.
//
// For a pixel: (u, v) is the finest texel its centre sees; its derivatives are the fine 2x2-quad
// differences (columns px & ~1 and px | 1 for d/dx, rows py & ~1 and py | 1 for d/dy, a partner
// beyond the grid's edge still evaluated, as GPU helper invocations are), u differences unwrapped
// by the surface's period; where a partner misses the surface a caller-given fallback derivative
// is used (a scene may say what the GPU computes there instead: Scene::miss_uv). From the
// derivative lengths lx, ly: taps = anisotropic_taps(lx, ly, max_taps), rho =
// max(lx, ly) with one tap else max(major / taps, minor), and the continuous level
// c = max_level - log2(rho) + level_offset clamped to [0, max_level] (rho 0 or NaN, or NaN c: the
// finest level; an infinite rho: the coarsest).
//
// Thread safety: pure functions.
#pragma once

#include <algorithm>
#include <cmath>
#include <optional>
#include <utility>
#include <vector>

#include "vts/renderer/scene.hpp"

namespace vts::renderer {

// Taps along the major axis for a footprint of derivative lengths lx, ly under a limit of
// max_taps: ceil(major / minor) clamped to [1, max_taps] (max_taps when minor is 0), and 1 when
// max_taps <= 1 or the major length is 0, infinite or NaN.
inline int anisotropic_taps(double lx, double ly, int max_taps) {
  const double major = std::max(lx, ly), minor = std::min(lx, ly);
  if (max_taps <= 1 || !(major > 0) || !std::isfinite(major)) return 1;
  const double ratio = minor > 0 ? major / minor : double(max_taps);
  return static_cast<int>(std::clamp(std::ceil(ratio), 1.0, double(max_taps)));
}

struct FootprintLevel {
  double c = 0;  // continuous level, in [0, max_level]
  int taps = 1;  // anisotropic taps along the major axis
};

inline FootprintLevel footprint_level(double lx, double ly, int max_level, double level_offset,
                                      int max_taps) {
  FootprintLevel f;
  f.taps = anisotropic_taps(lx, ly, max_taps);
  const double rho =
      f.taps == 1 ? std::max(lx, ly) : std::max(std::max(lx, ly) / f.taps, std::min(lx, ly));
  f.c = rho > 0 ? max_level - std::log2(rho) + level_offset : double(max_level);
  if (std::isnan(f.c)) f.c = max_level;
  f.c = std::clamp(f.c, 0.0, double(max_level));
  return f;
}

// One pixel of a walk: its centre's hit (u, v) and its derivatives, in finest texels per pixel.
struct PixelFootprint {
  int x = 0, y = 0;
  double u = 0, v = 0;
  double dudx = 0, dvdx = 0, dudy = 0, dvdy = 0;
};

using SurfaceHit = std::optional<std::pair<double, double>>;

// A scene's derivative at a screen point of a width x height view where a quad partner misses the
// surface: a central difference of a thousandth of a pixel (in double, far below any level's
// texel), or zero when that misses too (the finest level, like a zero footprint).
inline std::pair<double, double> scene_derivative(const Scene& scene, double sx, double sy,
                                                  int width, int height, int axis) {
  constexpr double e = 1e-3;
  const UvHit a =
      axis == 0 ? scene.hit(sx - e, sy, width, height) : scene.hit(sx, sy - e, width, height);
  const UvHit b =
      axis == 0 ? scene.hit(sx + e, sy, width, height) : scene.hit(sx, sy + e, width, height);
  if (!a || !b) return {0, 0};
  return {(b->first - a->first) / (2 * e), (b->second - a->second) / (2 * e)};
}

// A grid point of a walk: the surface hit of its ray, and the (u, v) a quad partner's derivative
// takes from it (the hit, or what the GPU computes for a miss: Scene::miss_uv).
struct GridPoint {
  SurfaceHit hit;
  SurfaceHit uv;
};

// The grid point of `scene` at (sx, sy) of a width x height view.
inline GridPoint scene_point(const Scene& scene, double sx, double sy, int width, int height) {
  GridPoint g;
  g.hit = scene.hit(sx, sy, width, height);
  g.uv = g.hit ? g.hit : scene.miss_uv(sx, sy, width, height);
  return g;
}

// Walks a w x h pixel grid in quad-row pairs. point_at(sx, sy) gives the GridPoint at a grid
// point (pixel centres at +0.5); fallback(sx, sy, axis) the derivative (axis 0: d/dx, 1: d/dy) at
// a pixel whose quad partner has no uv. visit(const PixelFootprint&) is called for every pixel
// whose centre hits inside [0, W) x [0, H) (NaN rejected), miss(x, y) for every other pixel;
// either may return false to stop the walk (the walk then returns false).
template <typename PointFn, typename FallbackFn, typename VisitFn, typename MissFn>
bool for_each_footprint(int w, int h, double W, double H, double period, PointFn&& point_at,
                        FallbackFn&& fallback, VisitFn&& visit, MissFn&& miss) {
  const auto unwrap = [period](double du) {
    return period > 0 ? du - period * std::round(du / period) : du;
  };
  const auto quad_difference = [&](const GridPoint& a, const GridPoint& b, double sx, double sy,
                                   int axis) {
    std::pair<double, double> d =
        a.uv && b.uv ? std::pair{b.uv->first - a.uv->first, b.uv->second - a.uv->second}
                     : fallback(sx, sy, axis);
    d.first = unwrap(d.first);
    return d;
  };
  // The points of both rows' pixel centres are kept, plus one column beyond the grid (the
  // partner of an odd last column); the second row of an odd last pair lies beyond it and is
  // only a partner.
  const int gw = w + 1;
  std::vector<GridPoint> rows[2] = {std::vector<GridPoint>(gw), std::vector<GridPoint>(gw)};
  for (int y0 = 0; y0 < h; y0 += 2) {
    for (int r = 0; r < 2; ++r)
      for (int x = 0; x < gw; ++x) rows[r][x] = point_at(x + 0.5, y0 + r + 0.5);
    for (int py = y0; py < std::min(y0 + 2, h); ++py) {
      const std::vector<GridPoint>& row = rows[py - y0];
      for (int px = 0; px < w; ++px) {
        const SurfaceHit& self = row[px].hit;
        if (!self || !(self->first >= 0 && self->first < W && self->second >= 0 &&
                       self->second < H)) {  // also rejects NaN
          if (!miss(px, py)) return false;
          continue;
        }
        PixelFootprint p;
        p.x = px;
        p.y = py;
        p.u = self->first;
        p.v = self->second;
        const double sx = px + 0.5, sy = py + 0.5;
        std::tie(p.dudx, p.dvdx) = quad_difference(row[px & ~1], row[px | 1], sx, sy, 0);
        std::tie(p.dudy, p.dvdy) = quad_difference(rows[0][px], rows[1][px], sx, sy, 1);
        if (!visit(p)) return false;
      }
    }
  }
  return true;
}

}  // namespace vts::renderer
