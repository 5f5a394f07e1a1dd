// GlobeScene: the virtual texture wrapped on a sphere (see globe.hpp for the mapping).
//
// Frames (double, CPU). Earth-centred: P(lon, lat) = R (cos lat cos lon, cos lat sin lon,
// sin lat); the local frame at a point is east = (-sin lon, cos lon, 0), north = (-sin lat cos lon,
// -sin lat sin lon, cos lat), up = P / R. The eye is (R + h) up(nadir). Camera basis, as the plane
// camera's with down = -up: ahead = north cos(heading) + east sin(heading) (where screen-up points
// on the ground), forward = -up cos(tilt) + ahead sin(tilt), up_s = up sin(tilt) + ahead cos(tilt),
// right = forward x up_s (east when heading = tilt = 0: the image is seen unmirrored). The ray of
// screen point (sx, sy) is forward + right nx + up_s ny with camera.hpp's nx, ny.
//
// Ray-sphere, stable form (CPU and GPU alike): with q = eye - centre = (R + h) up0 and
// s = t / (R + h), the equation |q + t d|^2 = R^2 becomes a s^2 + 2 b s + c = 0 with a = |d|^2,
// b = up0 . d (O(1), linear in nx, ny: three constants from the CPU) and
// c = h (2R + h) / (R + h)^2, computed from the altitude directly (never |q|^2 - R^2). The near
// root is s = c / (-b + sqrt(b^2 - a c)): a sum of positive terms, no cancellation, so s keeps
// float's relative precision even for h = 1 m (c ~ 3e-7). A ray hits when b < 0 and
// b^2 - a c >= 0.
//
// GPU precision scheme (no switch, one formula for every altitude). The anchor texel (an integer
// texel at the screen-centre hit, or the nadir) defines a point A on the sphere (the texel's
// corner: lon_a, lat_a exactly) and a local frame (east, north, up) at A. The CPU sends, as small
// floats in that frame: the eye relative to A (metres; small when the camera is close, since A is
// where it looks), the camera basis, b's constants and c. The shader forms the hit relative to A,
// p = (e, n, z) = eye_rel + (R + h) s d (small for close views), w = R + z, and converts it to
// exact lon/lat differences from A with formulas that never subtract large numbers:
//   x' = w cos(lat_a) - n sin(lat_a)             (towards A's meridian at the equator)
//   dlon = atan(e, x')                           in (-pi, pi]: u wraps around the anchor
//   delta = rho - x' with rho = |(x', e)|, as e^2 / (rho + x') when x' > 0, else rho - x'
//   dlat = atan(n - delta sin(lat_a), w + delta cos(lat_a))
// (rotation identities; exact, not a first-order local map, so there is no d^2 / R term), and
// rel = (dlon W / 2pi, -dlat H / pi). Every quantity is either small and absolutely accurate or
// large and only used relatively, so each result carries a float relative error of a few 2^-24.
//
// Error bound (float32, eps = 2^-24 ~ 6e-8): |rel error| <~ 8 eps (|rel| + L / texel) texels,
// where L = |eye - A| + |hit - eye| (metres) and texel = 2 pi R / W. Camera 1 m above a 2^25-wide
// image (texel 1.19 m), looking within 1 km: <~ 8 * 6e-8 * (1e3 + 2e3 / 1.19) ~ 1e-3 texel, far
// below 1/16 texel; the whole globe from 2e7 m on a 2048-wide image (texel 19.5 km):
// <~ 8 * 6e-8 * (1024 + 4e7 / 19.5e3) ~ 1.5e-3 texel. Moving the camera by 1 cm moves rel by
// 1 cm / texel and nothing else (no jitter). The ray-sphere root loses precision only at the limb
// (b^2 ~ a c, intrinsic to grazing rays), over about a pixel.
//
// Date line and poles: dlon wraps around the anchor, so rel.x is continuous near what the camera
// looks at. The virtual-texturing shader rejects anchor + rel outside [0, W), so a hit whose
// integer texel falls outside is shifted by one period (the caller unwraps the derivatives by
// u_period()); such a far-side hit is then a float of magnitude up to W (exact for W <= 2^24, to
// within W 2^-24 texels beyond) and clamped into [0, W), as the shifted float may round onto the
// edge. v is clamped to [0, H). At a pole atan(0, 0) is avoided; every path is finite.
#include "vts/renderer/globe.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace vts::renderer {

namespace {

using std::numbers::pi;

struct LocalFrame {
  Vec3d east, north, up;
};

LocalFrame frame_at(double lon, double lat) {
  const double cl = std::cos(lon), sl = std::sin(lon), cp = std::cos(lat), sp = std::sin(lat);
  return {{-sl, cl, 0}, {-sp * cl, -sp * sl, cp}, {cp * cl, cp * sl, sp}};
}

struct GlobeCamera {
  LocalFrame nadir;
  Vec3d forward, right, up;  // Earth-centred, unit
  double tan_half_fov = 0;
  double rh = 0;  // R + h: the eye's distance from the centre
  double c = 0;   // h (2R + h) / (R + h)^2
};

GlobeCamera camera_of(const GlobeView& v) {
  GlobeCamera cam;
  cam.nadir = frame_at(v.lon_deg * pi / 180, v.lat_deg * pi / 180);
  const Vec3d ahead = cam.nadir.north * std::cos(v.heading) + cam.nadir.east * std::sin(v.heading);
  const double ct = std::cos(v.tilt), st = std::sin(v.tilt);
  cam.forward = cam.nadir.up * (-ct) + ahead * st;
  cam.up = cam.nadir.up * st + ahead * ct;
  cam.right = cross(cam.forward, cam.up);
  cam.tan_half_fov = std::tan(v.fov_y * 0.5);
  const double h = std::max(v.altitude_m, 0.0), r = v.radius_m;
  cam.rh = r + h;
  cam.c = h * (2 * r + h) / (cam.rh * cam.rh);
  return cam;
}

// s = t / (R + h) of the near hit of direction d, or nullopt.
std::optional<double> ray_param(const GlobeCamera& cam, Vec3d d) {
  const double a = dot(d, d);
  const double b = dot(cam.nadir.up, d);
  const double disc = b * b - a * cam.c;
  if (!(b < 0) || !(disc >= 0)) return std::nullopt;
  return cam.c / (-b + std::sqrt(disc));
}

std::int64_t clamp_index(double x, std::uint64_t n) {
  return std::int64_t(std::clamp(std::floor(x), 0.0, double(n) - 1));
}

}  // namespace

struct GlobeScene::Camera : GlobeCamera {};

GlobeScene::GlobeScene(const GlobeView& view, std::uint64_t image_width, std::uint64_t image_height)
    : view_(view),
      width_(std::max<std::uint64_t>(image_width, 1)),
      height_(std::max<std::uint64_t>(image_height, 1)),
      camera_(std::make_shared<const Camera>(Camera{camera_of(view)})) {}

namespace {

// (u, v) of the point eye + d s (R + h), absolute, u in [0, W), v in [0, H).
UvHit uv_at(const GlobeCamera& cam, Vec3d d, double s, double w, double h) {
  const Vec3d p = cam.nadir.up * cam.rh + d * (s * cam.rh);
  const double lon = std::atan2(p.y, p.x);
  const double lat = std::atan2(p.z, std::hypot(p.x, p.y));
  double u = (lon / (2 * pi) + 0.5) * w;
  u = std::fmod(u, w);
  if (u < 0) u += w;
  if (u >= w) u -= w;
  double v = (0.5 - lat / pi) * h;
  v = std::clamp(v, 0.0, std::nextafter(h, 0.0));
  if (!std::isfinite(u) || !std::isfinite(v)) return std::nullopt;
  return std::pair<double, double>{u, v};
}

// (u, v) of the direction d from the eye, absolute, u in [0, W), v in [0, H).
UvHit hit_dir(const GlobeCamera& cam, Vec3d d, double w, double h) {
  const auto s = ray_param(cam, d);
  if (!s) return std::nullopt;
  return uv_at(cam, d, *s, w, h);
}

Vec3d pixel_dir(const GlobeCamera& cam, double sx, double sy, int width, int height) {
  const double aspect = double(width) / double(height);
  const double nx = (2.0 * sx / width - 1.0) * cam.tan_half_fov * aspect;
  const double ny = (1.0 - 2.0 * sy / height) * cam.tan_half_fov;
  return cam.forward + cam.right * nx + cam.up * ny;
}

}  // namespace

UvHit GlobeScene::hit(double sx, double sy, int width, int height) const {
  const GlobeCamera& cam = *camera_;
  return hit_dir(cam, pixel_dir(cam, sx, sy, width, height), double(width_), double(height_));
}

UvHit GlobeScene::miss_uv(double sx, double sy, int width, int height) const {
  const GlobeCamera& cam = *camera_;
  const Vec3d d = pixel_dir(cam, sx, sy, width, height);
  const double a = dot(d, d), b = dot(cam.nadir.up, d);
  const double disc = b * b - a * cam.c;
  const double s = b < 0 ? cam.c / (-b + std::sqrt(std::max(disc, 0.0))) : 0.0;
  return uv_at(cam, d, s, double(width_), double(height_));
}

std::pair<double, double> GlobeScene::focus() const {
  const GlobeCamera& cam = *camera_;
  if (auto h = hit_dir(cam, cam.forward, double(width_), double(height_))) return *h;
  // The centre looks past the limb: the nadir.
  return *hit_dir(cam, cam.nadir.up * -1.0, double(width_), double(height_));
}

std::array<std::int64_t, 2> GlobeScene::anchor() const {
  const auto [u, v] = focus();
  return {clamp_index(u, width_), clamp_index(v, height_)};
}

double GlobeScene::texels_per_pixel() const {
  const GlobeCamera& cam = *camera_;
  const auto s = ray_param(cam, cam.forward);
  const double dist = s ? *s * cam.rh : std::max(view_.altitude_m, 0.0);
  const double pixel_rad = 2 * cam.tan_half_fov / kGlobeNominalHeightPx;
  return dist * pixel_rad * double(width_) / (2 * pi * view_.radius_m);
}

std::string GlobeScene::glsl() const {
  return R"(
uniform vec3 u_g_eye;        // eye - A in A's (east, north, up) frame, metres
uniform vec3 u_g_forward;    // camera basis in A's frame
uniform vec3 u_g_right;
uniform vec3 u_g_up;
uniform vec3 u_g_b;          // b = up0 . d = dot(u_g_b, vec3(1, nx, ny))
uniform float u_g_c;         // h (2R + h) / (R + h)^2
uniform float u_g_rh;        // R + h
uniform float u_g_radius;    // R
uniform vec2 u_g_sincos;     // sin, cos of A's latitude
uniform vec2 u_g_scale;      // W / 2pi, H / pi
uniform ivec2 u_g_wrap;      // -anchor.u, W - anchor.u: where rel.x leaves [0, W)
uniform float u_g_period;    // W
uniform vec2 u_g_urange;     // floats inside [-anchor.u, W - anchor.u): rel.x's final clamp
uniform vec2 u_g_vrange;     // floats inside [-anchor.v, H - anchor.v): rel.y's clamp
uniform float u_g_tan_half_fov;
uniform float u_g_aspect;

bool scene_hit(vec2 px, out vec2 rel) {
  float nx = (2.0 * px.x / u_viewport.x - 1.0) * u_g_tan_half_fov * u_g_aspect;
  float ny = (1.0 - 2.0 * px.y / u_viewport.y) * u_g_tan_half_fov;
  vec3 d = u_g_forward + u_g_right * nx + u_g_up * ny;
  float a = 1.0 + nx * nx + ny * ny;
  float b = u_g_b.x + u_g_b.y * nx + u_g_b.z * ny;
  float disc = b * b - a * u_g_c;
  bool hit = b < 0.0 && disc >= 0.0;
  // A miss past the limb still gets the ray's closest point, so derivatives stay sensible.
  float s = b < 0.0 ? u_g_c / (-b + sqrt(max(disc, 0.0))) : 0.0;
  vec3 p = u_g_eye + d * (s * u_g_rh);
  float w = u_g_radius + p.z;
  float xm = w * u_g_sincos.y - p.y * u_g_sincos.x;
  float rho = length(vec2(xm, p.x));
  float delta = xm > 0.0 ? p.x * p.x / (rho + xm) : rho - xm;
  float dlon = (p.x == 0.0 && xm == 0.0) ? 0.0 : atan(p.x, xm);
  float dlat = atan(p.y - delta * u_g_sincos.x, w + delta * u_g_sincos.y);
  rel = vec2(dlon * u_g_scale.x, -dlat * u_g_scale.y);
  int iu = int(floor(rel.x));
  if (iu < u_g_wrap.x) rel.x += u_g_period;
  else if (iu >= u_g_wrap.y) rel.x -= u_g_period;
  rel.x = clamp(rel.x, u_g_urange.x, u_g_urange.y);  // the shifted float may round onto the edge
  rel.y = clamp(rel.y, u_g_vrange.x, u_g_vrange.y);
  return hit;
}
)";
}

void GlobeScene::set_uniforms(UniformSink& sink, int width, int height) const {
  const GlobeCamera& cam = *camera_;
  const auto an = anchor();
  const double lon_a = (double(an[0]) / double(width_) - 0.5) * 2 * pi;
  const double lat_a = (0.5 - double(an[1]) / double(height_)) * pi;
  const LocalFrame fa = frame_at(lon_a, lat_a);
  const double r = view_.radius_m;
  const auto local = [&fa](Vec3d v) {
    return Vec3d{dot(v, fa.east), dot(v, fa.north), dot(v, fa.up)};
  };
  // The only place the eye meets A: in double. eye - A = (R + h) up0 - R upA; its up component
  // (R + h) cos(theta) - R is formed as h cos(theta) - R (1 - cos(theta)) with
  // 1 - cos(theta) = |up0 - upA|^2 / 2, so nothing large cancels.
  const double cos_t = dot(cam.nadir.up, fa.up);
  const Vec3d du = cam.nadir.up - fa.up;
  const Vec3d eye_rel{cam.rh * dot(cam.nadir.up, fa.east), cam.rh * dot(cam.nadir.up, fa.north),
                      (cam.rh - r) * cos_t - r * 0.5 * dot(du, du)};
  const auto set3 = [&sink](const char* name, Vec3d v) {
    sink.set(name, float(v.x), float(v.y), float(v.z));
  };
  const auto set1 = [&sink](const char* name, double v) { sink.set(name, float(v)); };
  set3("u_g_eye", eye_rel);
  set3("u_g_forward", local(cam.forward));
  set3("u_g_right", local(cam.right));
  set3("u_g_up", local(cam.up));
  set3("u_g_b", Vec3d{dot(cam.nadir.up, cam.forward), dot(cam.nadir.up, cam.right),
                      dot(cam.nadir.up, cam.up)});
  set1("u_g_c", cam.c);
  set1("u_g_rh", cam.rh);
  set1("u_g_radius", r);
  sink.set("u_g_sincos", float(std::sin(lat_a)), float(std::cos(lat_a)));
  sink.set("u_g_scale", float(double(width_) / (2 * pi)), float(double(height_) / pi));
  sink.set_int("u_g_wrap", int(-an[0]), int(std::int64_t(width_) - an[0]));
  set1("u_g_period", double(width_));
  // [-a, n - a) as floats that stay inside it once rounded.
  const auto set_range = [&sink](const char* name, std::int64_t a, std::uint64_t n) {
    const double lo = -double(a), hi = double(n) - double(a);
    float lo_f = float(lo), hi_f = float(hi);
    if (double(lo_f) < lo) lo_f = std::nextafter(lo_f, std::numeric_limits<float>::infinity());
    if (double(hi_f) >= hi) hi_f = std::nextafter(hi_f, -std::numeric_limits<float>::infinity());
    sink.set(name, lo_f, hi_f);
  };
  set_range("u_g_urange", an[0], width_);
  set_range("u_g_vrange", an[1], height_);
  set1("u_g_tan_half_fov", cam.tan_half_fov);
  set1("u_g_aspect", double(width) / double(height));
}

}  // namespace vts::renderer
