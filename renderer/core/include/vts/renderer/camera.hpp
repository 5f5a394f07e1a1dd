// The plane scene's camera, in double precision, and the one definition of how a screen pixel maps
// to a point of the virtual texture. The GPU renderer and the CPU reference renderer both follow
// it, so their images can be compared pixel for pixel.
//
// World frame of the plane scene: u (right) and v (down) are finest-level texel coordinates of the
// image, so the image covers [0, W] x [0, H] of the plane w = 0; w grows *into* the ground (a
// camera above the plane has w < 0). With this left-handed-looking choice the image is seen
// unmirrored with its top row at the top of the screen when heading = 0.
//
// A view is given the way a map user thinks of it: the texel under the screen centre, the zoom as
// finest texels per screen pixel at that centre, a heading (radians: the direction screen-up
// points on the plane, 0 = towards the image's top row (-v), pi/2 = towards +u) and a tilt (0 looks
// straight down; towards pi/2 looks at the horizon). The eye sits on the centre ray at the distance
// that gives that zoom.
//
// Pixel (px, py) of a width x height image, rows top to bottom, is the ray through the pixel's
// centre (px + 0.5, py + 0.5). Precision: the renderer never forms one float coordinate over the
// whole texture; it works relative to an integer `anchor` texel near the centre (anchor()).
#pragma once

#include <cmath>
#include <cstdint>
#include <optional>
#include <utility>

namespace vts::renderer {

struct Vec3d {
  double x = 0, y = 0, z = 0;
};
inline Vec3d operator+(Vec3d a, Vec3d b) {
  return {a.x + b.x, a.y + b.y, a.z + b.z};
}
inline Vec3d operator-(Vec3d a, Vec3d b) {
  return {a.x - b.x, a.y - b.y, a.z - b.z};
}
inline Vec3d operator*(Vec3d a, double s) {
  return {a.x * s, a.y * s, a.z * s};
}
inline double dot(Vec3d a, Vec3d b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
inline Vec3d cross(Vec3d a, Vec3d b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

struct PlaneView {
  double center_u = 0, center_v = 0;  // finest-level texel under the screen centre
  double texels_per_pixel = 1;        // zoom at the screen centre (> 0)
  double heading = 0;                 // radians
  double tilt = 0;                    // radians, [0, 1.5]
  double fov_y = 0.8;                 // vertical field of view, radians, (0, pi)
  friend bool operator==(const PlaneView&, const PlaneView&) = default;
};

// The camera basis and eye derived from a PlaneView for a viewport; every field in world units.
struct PlaneCamera {
  Vec3d eye;      // w < 0 above the plane
  Vec3d forward;  // unit, towards the centre texel
  Vec3d right;    // unit, screen +x
  Vec3d up;       // unit, screen +y (towards the top row)
  double tan_half_fov = 0;
  double aspect = 1;  // width / height
  int width = 1, height = 1;

  static PlaneCamera from_view(const PlaneView& view, int width, int height) {
    PlaneCamera c;
    c.width = width;
    c.height = height;
    c.aspect = double(width) / double(height);
    c.tan_half_fov = std::tan(view.fov_y * 0.5);
    const Vec3d down{0, 0, 1};  // into the ground
    const Vec3d ahead{std::sin(view.heading), -std::cos(view.heading),
                      0};  // screen-up on the plane
    const double ct = std::cos(view.tilt), st = std::sin(view.tilt);
    c.forward = down * ct + ahead * st;
    c.up = down * (-st) + ahead * ct;
    c.right = cross(c.forward, c.up);
    // A pixel at the centre subtends 2 tan(fov/2) / height radians; at distance d along the
    // forward ray it covers d * that perpendicular to the ray. Tilt stretches it on the plane by
    // 1/cos(tilt) along the view direction; the zoom is defined across it (perpendicular), so it
    // does not depend on the tilt.
    const double d = view.texels_per_pixel * height / (2.0 * c.tan_half_fov);
    c.eye = Vec3d{view.center_u, view.center_v, 0} - c.forward * d;
    return c;
  }

  // Direction (not unit) of the ray through screen point (sx, sy) in pixels from the top-left
  // corner (pixel centres are at +0.5).
  Vec3d ray(double sx, double sy) const {
    const double nx = (2.0 * sx / width - 1.0) * tan_half_fov * aspect;
    const double ny = (1.0 - 2.0 * sy / height) * tan_half_fov;
    return forward + right * nx + up * ny;
  }

  // The plane point (u, v) seen at screen point (sx, sy); nullopt when the ray misses the plane
  // (looks at or above the horizon).
  std::optional<std::pair<double, double>> hit(double sx, double sy) const {
    const Vec3d d = ray(sx, sy);
    if (!(d.z > 0)) return std::nullopt;
    const double t = -eye.z / d.z;
    return std::pair<double, double>{eye.x + t * d.x, eye.y + t * d.y};
  }
};

// Sampling rules shared by the GPU shader and the CPU reference (docs/RENDERER.md, "Sampling"):
//  - footprint: rho = max(|d(u,v)/dx|, |d(u,v)/dy|) in finest texels per pixel, where the
//    derivatives are the differences of (u, v) between the two pixel centres of the 2x2 quad the
//    pixel belongs to (what dFdxFine/dFdyFine give: columns 2k and 2k+1, rows 2k and 2k+1);
//  - continuous level c = max_level - log2(rho) - bias, clamped to [0, max_level];
//  - trilinear: levels floor(c) and floor(c) + 1 (when <= max_level), weight frac(c) on the finer;
//  - at level L the texel coordinate is (u, v) / 2^(max_level - L), texel centres at +0.5,
//    bilinear with clamp to the level's image edge, filtered in linear light (sRGB decoded), the
//    result encoded back to sRGB.
//  - pixels whose ray misses the plane or hits outside [0, W) x [0, H) are the background.
inline constexpr std::uint8_t kBackground[4] = {0, 0, 0, 255};

}  // namespace vts::renderer
