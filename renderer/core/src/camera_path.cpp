// Camera paths: JSON keyframes, interpolated (camera_path.hpp).
#include "vts/renderer/camera_path.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <sstream>
#include <string>

#include "vts/protocol/json_input.hpp"

namespace vts::renderer {

namespace {

using nlohmann::json;

Error bad(std::string message) {
  return make_error(ErrorCode::invalid_argument, "camera path: " + std::move(message));
}

std::string where(std::size_t i) {
  return "key " + std::to_string(i);
}

// Reads key[name] as a finite number into out; false (with `err` set) when present but wrong.
bool number(const json& key, std::size_t i, const char* name, double& out, bool& seen,
            std::optional<Error>& err) {
  auto it = key.find(name);
  if (it == key.end()) return true;
  if (!it->is_number()) {
    err = bad(where(i) + ": \"" + name + "\" is not a number");
    return false;
  }
  const double v = it->get<double>();
  if (!std::isfinite(v)) {
    err = bad(where(i) + ": \"" + name + "\" is not finite");
    return false;
  }
  out = v;
  seen = true;
  return true;
}

double lerp(double a, double b, double f) {
  return a + (b - a) * f;
}
double log_lerp(double a, double b, double f) {
  if (f <= 0) return a;            // exactly the key's value on (and beyond) a key
  if (f >= 1 || a == b) return b;  // a held value stays exactly itself (exp(log(a)) may not)
  return std::exp(lerp(std::log(a), std::log(b), f));
}

// The two keys around `frame` and the fraction between them (clamped outside the range).
template <typename F>
auto between(const std::vector<CameraKey>& keys, double frame, F&& mix) {
  if (keys.size() == 1 || !(frame > keys.front().t)) return mix(keys.front(), keys.front(), 0.0);
  if (frame >= keys.back().t) return mix(keys.back(), keys.back(), 0.0);
  auto hi = std::upper_bound(keys.begin(), keys.end(), frame,
                             [](double f, const CameraKey& k) { return f < k.t; });
  auto lo = hi - 1;
  const double f = (frame - lo->t) / (hi->t - lo->t);
  return mix(*lo, *hi, f);
}

}  // namespace

Result<CameraPath> CameraPath::parse(std::string_view json_text, const CameraKey& defaults) {
  // Depth-limited: a camera file may come from anywhere.
  auto parsed = parse_json(json_text, "the document");
  if (!parsed) return bad(parsed.error().message);
  const json& doc = *parsed;
  if (!doc.is_object()) return bad("the top level is not a JSON object");
  auto keys_it = doc.find("keys");
  if (keys_it == doc.end()) return bad("no \"keys\" array");
  if (!keys_it->is_array()) return bad("\"keys\" is not an array");
  if (keys_it->empty()) return bad("\"keys\" is empty");

  CameraPath path;
  CameraKey prev = defaults;  // each key inherits what it leaves out
  std::optional<Error> err;
  for (std::size_t i = 0; i < keys_it->size(); ++i) {
    const json& k = (*keys_it)[i];
    if (!k.is_object()) return bad(where(i) + " is not a JSON object");
    CameraKey key = prev;
    bool has_frame = false, plane = false, globe = false, shared = false;
    if (!number(k, i, "frame", key.t, has_frame, err)) return *err;
    if (!has_frame) return bad(where(i) + ": no \"frame\"");
    if (i > 0 && !(key.t > prev.t))
      return bad(where(i) + ": \"frame\" " + k.at("frame").dump() +
                 " is not after the previous key's frame (frames must increase)");

    // Plane fields.
    if (auto c = k.find("center"); c != k.end()) {
      if (!c->is_array() || c->size() != 2 || !(*c)[0].is_number() || !(*c)[1].is_number())
        return bad(where(i) + ": \"center\" is not an array of two numbers [u, v]");
      key.plane.center_u = (*c)[0].get<double>();
      key.plane.center_v = (*c)[1].get<double>();
      if (!std::isfinite(key.plane.center_u) || !std::isfinite(key.plane.center_v))
        return bad(where(i) + ": \"center\" is not finite");
      plane = true;
    }
    if (!number(k, i, "texels_per_pixel", key.plane.texels_per_pixel, plane, err)) return *err;
    if (!(key.plane.texels_per_pixel > 0))
      return bad(where(i) + ": \"texels_per_pixel\" must be > 0");

    // Globe fields.
    if (!number(k, i, "lon", key.globe.lon_deg, globe, err)) return *err;
    if (!number(k, i, "lat", key.globe.lat_deg, globe, err)) return *err;
    if (key.globe.lat_deg < -90 || key.globe.lat_deg > 90)
      return bad(where(i) + ": \"lat\" is outside [-90, 90]");
    if (!number(k, i, "altitude_m", key.globe.altitude_m, globe, err)) return *err;
    if (!(key.globe.altitude_m > 0)) return bad(where(i) + ": \"altitude_m\" must be > 0");

    // Shared by both views.
    double heading = key.plane.heading, tilt = key.plane.tilt, fov = key.plane.fov_y;
    if (!number(k, i, "heading", heading, shared, err)) return *err;
    if (!number(k, i, "tilt", tilt, shared, err)) return *err;
    if (tilt < 0 || tilt > 1.5) return bad(where(i) + ": \"tilt\" is outside [0, 1.5] radians");
    if (!number(k, i, "fov_y", fov, shared, err)) return *err;
    if (!(fov > 0 && fov < 3.14159))
      return bad(where(i) + ": \"fov_y\" is outside (0, pi) radians");
    key.plane.heading = key.globe.heading = heading;
    key.plane.tilt = key.globe.tilt = tilt;
    key.plane.fov_y = key.globe.fov_y = fov;

    // Per key, not carried over.
    key.move = i == 0;
    if (auto m = k.find("move"); m != k.end()) {
      if (!m->is_boolean()) return bad(where(i) + ": \"move\" is not true or false");
      key.move = key.move || m->get<bool>();
    }

    path.has_plane_ = path.has_plane_ || plane;
    path.has_globe_ = path.has_globe_ || globe;
    path.keys_.push_back(key);
    prev = key;
  }
  return path;
}

PlaneView CameraPath::plane_at(double frame) const {
  if (keys_.empty()) return PlaneView{};
  return between(keys_, frame, [](const CameraKey& a, const CameraKey& b, double f) {
    PlaneView v = a.plane;
    v.center_u = lerp(a.plane.center_u, b.plane.center_u, f);
    v.center_v = lerp(a.plane.center_v, b.plane.center_v, f);
    v.texels_per_pixel = log_lerp(a.plane.texels_per_pixel, b.plane.texels_per_pixel, f);
    v.heading = lerp(a.plane.heading, b.plane.heading, f);
    v.tilt = lerp(a.plane.tilt, b.plane.tilt, f);
    v.fov_y = lerp(a.plane.fov_y, b.plane.fov_y, f);
    return v;
  });
}

GlobeView CameraPath::globe_at(double frame) const {
  if (keys_.empty()) return GlobeView{};
  return between(keys_, frame, [](const CameraKey& a, const CameraKey& b, double f) {
    GlobeView v = a.globe;
    v.lon_deg = lerp(a.globe.lon_deg, b.globe.lon_deg, f);
    v.lat_deg = lerp(a.globe.lat_deg, b.globe.lat_deg, f);
    v.altitude_m = log_lerp(a.globe.altitude_m, b.globe.altitude_m, f);
    v.heading = lerp(a.globe.heading, b.globe.heading, f);
    v.tilt = lerp(a.globe.tilt, b.globe.tilt, f);
    v.fov_y = lerp(a.globe.fov_y, b.globe.fov_y, f);
    return v;
  });
}

std::vector<double> CameraPath::move_frames() const {
  std::vector<double> out;
  for (std::size_t i = 0; i < keys_.size(); ++i)
    if (i == 0 || keys_[i].move) out.push_back(keys_[i].t);
  return out;
}

std::string CameraPath::to_json() const {
  const bool plane = has_plane_ || !has_globe_, globe = has_globe_ || !has_plane_;
  // Frames that are whole numbers print as integers; every other number as a double with
  // max_digits10 digits (nlohmann's default), which reads back bit for bit.
  auto number = [](double x) {
    if (x == std::floor(x) && std::fabs(x) < 9007199254740992.0)
      return nlohmann::ordered_json(std::int64_t(x));
    return nlohmann::ordered_json(x);
  };
  std::string out = "{\"keys\": [\n";
  for (std::size_t i = 0; i < keys_.size(); ++i) {
    const CameraKey& k = keys_[i];
    nlohmann::ordered_json j;
    j["frame"] = number(k.t);
    if (plane) {
      j["center"] = {k.plane.center_u, k.plane.center_v};
      j["texels_per_pixel"] = k.plane.texels_per_pixel;
    }
    if (globe) {
      j["lon"] = k.globe.lon_deg;
      j["lat"] = k.globe.lat_deg;
      j["altitude_m"] = k.globe.altitude_m;
    }
    // parse() gives both views one heading, tilt and fov; a path of one kind writes its own.
    const bool from_globe = globe && !plane;
    j["heading"] = from_globe ? k.globe.heading : k.plane.heading;
    j["tilt"] = from_globe ? k.globe.tilt : k.plane.tilt;
    j["fov_y"] = from_globe ? k.globe.fov_y : k.plane.fov_y;
    if (i == 0 || k.move) j["move"] = true;
    out += "  " + j.dump() + (i + 1 < keys_.size() ? ",\n" : "\n");
  }
  out += "]}\n";
  return out;
}

// ---- Built-in paths ----------------------------------------------------------------------------

namespace {

using std::numbers::pi;
constexpr double kDeg = 180 / pi;
// Zooms the presets aim at: the globe's finest-level views and the plane's map scale.
constexpr double kFinestTexelsPerPixel = 1.5;
constexpr double kPanTexelsPerPixel = 1;
constexpr double kFlyoverTilt = 0.3;  // radians, at the ground (see flyover())
constexpr double kOrbitAltitudeM = 2e7;
constexpr double kFov = 0.8;  // the views' default
// Caps that keep a path's size bounded whatever the options.
constexpr double kMaxFps = 1000, kMaxDurationS = 86400;
constexpr std::size_t kMaxKeys = 200000;

// splitmix64: the same numbers on every platform and standard library (the <random>
// distributions are not specified bit for bit).
class Rng {
 public:
  explicit Rng(std::uint64_t seed) : state_(seed) {}
  std::uint64_t next() {
    std::uint64_t z = (state_ += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  }
  double uniform() { return double(next() >> 11) * 0x1.0p-53; }  // [0, 1)
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }

 private:
  std::uint64_t state_;
};

// A place on the globe, uniform by area between latitudes -80 and 80 (degrees).
std::pair<double, double> random_place(Rng& rng) {
  const double s = std::sin(80 / kDeg);
  const double lon = rng.uniform(-180, 180);
  const double lat = std::asin(rng.uniform(-s, s)) * kDeg;
  return {lon, lat};
}

// Distance along the screen-centre ray at which a pixel covers `tpp` finest texels: the zoom
// GlobeScene::texels_per_pixel() defines, for a viewport of o.viewport_height rows.
double centre_distance_m(const PresetOptions& o, double tpp) {
  const double texel_m = 2 * pi * kEarthRadiusM / double(o.image_width);
  const double pixel_rad = 2 * std::tan(kFov / 2) / double(o.viewport_height);
  return tpp * texel_m / pixel_rad;
}

CameraKey globe_key(double frame, double lon, double lat, double altitude, double heading,
                    double tilt, bool move) {
  CameraKey k;
  k.t = frame;
  k.globe.lon_deg = lon;
  k.globe.lat_deg = lat;
  k.globe.altitude_m = altitude;
  k.globe.heading = k.plane.heading = heading;
  k.globe.tilt = k.plane.tilt = tilt;
  k.globe.fov_y = k.plane.fov_y = kFov;
  k.move = move;
  return k;
}

std::vector<CameraKey> flyover(const PresetOptions& o, double frames, Rng& rng) {
  // Ground speed: half a screen height per second at the centre, as an angle (radians of
  // great circle per second).
  const double omega =
      0.5 * o.viewport_height * kFinestTexelsPerPixel * 2 * pi / double(o.image_width);
  // The centre ray meets the ground at kFlyoverTilt from the vertical there. (From high above,
  // as a coarse image's finest level is seen, the camera's own tilt must be smaller for that:
  // the triangle centre-eye-hit has sides R and d around the angle pi - incidence.)
  const double d = centre_distance_m(o, kFinestTexelsPerPixel), r = kEarthRadiusM;
  const double rh = std::sqrt(r * r + d * d + 2 * r * d * std::cos(kFlyoverTilt));
  const double tilt = std::asin(r * std::sin(kFlyoverTilt) / rh);
  const double altitude = rh - r;

  // The route, by travelled angle s: the latitude meanders, phi(s) = phi0 + A (sin(k s + p) -
  // sin p), every 30 s, with a slope |dphi/ds| <= 0.3 (so at most 0.3 rad off due east) and an
  // amplitude A of at most 10 degrees (so |phi| <= 60 + 2 A); the longitude follows from a unit
  // ground speed, dlambda/ds = sqrt(1 - phi'^2) / cos(phi), and the heading is the direction of
  // motion.
  const double period_angle = omega * 30;
  const double amp = std::min(0.3 * period_angle / (2 * pi), 10 / kDeg);
  const double wave = 2 * pi / period_angle;
  const double phase = rng.uniform(0, 2 * pi);
  const double phi0 = rng.uniform(-60, 60) / kDeg;
  const double lon_u = rng.uniform();
  auto phi = [&](double s) { return phi0 + amp * (std::sin(wave * s + phase) - std::sin(phase)); };
  auto slope = [&](double s) { return amp * wave * std::cos(wave * s + phase); };
  auto dlambda = [&](double s) {
    const double p = slope(s);
    return std::sqrt(std::max(0.0, 1 - p * p)) / std::cos(phi(s));
  };

  // Keys every half second or closer (at most 0.05 rad apart, at least a frame), at most
  // kMaxKeys of them.
  double step = std::max(1.0, std::floor(o.fps * std::min(0.5, 0.05 / omega)));
  step = std::max(step, std::ceil(frames / double(kMaxKeys - 1)));
  std::vector<double> ts;
  for (double t = 0; t < frames; t += step) ts.push_back(t);
  ts.push_back(frames);

  std::vector<CameraKey> keys;
  double lambda = 0, prev_s = 0;
  for (std::size_t i = 0; i < ts.size(); ++i) {
    const double s = omega * ts[i] / o.fps;
    if (i > 0) {  // Simpson's rule over [prev_s, s] in 8 parts
      constexpr int n = 8;
      const double h = (s - prev_s) / n;
      double sum = dlambda(prev_s) + dlambda(s);
      for (int j = 1; j < n; ++j) sum += (j % 2 ? 4 : 2) * dlambda(prev_s + j * h);
      lambda += sum * h / 3;
    }
    prev_s = s;
    const double heading = pi / 2 - std::asin(std::clamp(slope(s), -1.0, 1.0));
    keys.push_back(globe_key(ts[i], lambda * kDeg, phi(s) * kDeg, altitude, heading, tilt, i == 0));
  }
  // Start where the whole route fits in [-180, 180] when it can (it heads east: the longitude
  // only grows); a longer route runs past 180 (unwrapped, see the header).
  const double sweep = keys.back().globe.lon_deg;
  const double lon0 = -180 + lon_u * std::max(0.0, 360 - sweep);
  for (auto& k : keys) k.globe.lon_deg += lon0;
  return keys;
}

std::vector<CameraKey> zoom(const PresetOptions& o, double frames, Rng& rng) {
  const double low = centre_distance_m(o, kFinestTexelsPerPixel);
  const double high = std::max(kOrbitAltitudeM, 4 * low);
  const auto [lon, lat] = random_place(rng);
  return {globe_key(0, lon, lat, high, 0, 0, true), globe_key(frames, lon, lat, low, 0, 0, false)};
}

std::vector<CameraKey> jumps(const PresetOptions& o, double frames, double dwell, Rng& rng) {
  const double altitude = centre_distance_m(o, kFinestTexelsPerPixel);
  std::vector<CameraKey> keys;
  for (double f = 0;;) {
    const auto [lon, lat] = random_place(rng);
    keys.push_back(globe_key(f, lon, lat, altitude, 0, 0, true));
    const double end = f + dwell - 1;
    if (end + 1 >= frames) {  // the last place is held to the end
      keys.push_back(globe_key(frames, lon, lat, altitude, 0, 0, false));
      break;
    }
    keys.push_back(globe_key(end, lon, lat, altitude, 0, 0, false));
    f = end + 1;  // the jump: the next place one frame later
  }
  return keys;
}

std::vector<CameraKey> pan(const PresetOptions& o, double frames, Rng& rng) {
  const double w = double(o.image_width), h = double(o.image_height);
  // The centre stays half a screen inside the image, or in its middle half when the image is
  // smaller than two screens.
  const double mx = std::min(0.5 * o.viewport_width * kPanTexelsPerPixel, w / 4);
  const double my = std::min(0.5 * o.viewport_height * kPanTexelsPerPixel, h / 4);
  const double lo[2] = {mx, my}, len[2] = {w - 2 * mx, h - 2 * my};
  // Half a screen width per second, but not faster than crossing the inner image in a second,
  // so a small image does not make a path of countless bounces.
  const double speed =
      std::min(0.5 * o.viewport_width * kPanTexelsPerPixel, std::min(len[0], len[1]));
  const double angle = rng.uniform(0, 2 * pi);
  const double vel[2] = {speed * std::cos(angle) / o.fps, speed * std::sin(angle) / o.fps};
  const double start[2] = {rng.uniform(0, len[0]), rng.uniform(0, len[1])};

  // Each axis moves as a triangle wave between lo and lo + len: linear between bounces, so keys
  // at frame 0, at every bounce and at the end give the path exactly.
  auto at = [&](int axis, double t) {
    const double y = std::fmod(std::fabs(start[axis] + vel[axis] * t), 2 * len[axis]);
    return lo[axis] + (y <= len[axis] ? y : 2 * len[axis] - y);
  };
  std::vector<double> ts = {0, frames};
  for (int axis = 0; axis < 2; ++axis) {
    if (vel[axis] == 0) continue;
    // Bounces where start + vel t is a multiple of len.
    const double x0 = start[axis], v = vel[axis], l = len[axis];
    const double first = v > 0 ? std::floor(x0 / l) + 1 : std::ceil(x0 / l) - 1;
    for (double m = first;; m += v > 0 ? 1 : -1) {
      const double t = (m * l - x0) / v;
      if (!(t < frames)) break;
      if (t > 0) ts.push_back(t);
    }
  }
  std::sort(ts.begin(), ts.end());
  std::vector<CameraKey> keys;
  for (double t : ts) {
    if (!keys.empty() && !(t > keys.back().t + 1e-6)) continue;  // bounces in both axes at once
    CameraKey k;
    k.t = t;
    k.plane.center_u = at(0, t);
    k.plane.center_v = at(1, t);
    k.plane.texels_per_pixel = kPanTexelsPerPixel;
    k.plane.heading = k.globe.heading = 0;
    k.plane.tilt = k.globe.tilt = 0;
    k.plane.fov_y = k.globe.fov_y = kFov;
    k.move = keys.empty();
    keys.push_back(k);
  }
  if (keys.back().t != frames) keys.back().t = frames;  // a bounce within 1e-6 of the end
  return keys;
}

}  // namespace

std::vector<std::string_view> CameraPath::preset_names() {
  return {"flyover", "zoom", "jumps", "pan"};
}

Result<CameraPath> CameraPath::preset(std::string_view name, const PresetOptions& o) {
  const auto names = preset_names();
  if (std::find(names.begin(), names.end(), name) == names.end()) {
    std::string known;
    for (auto n : names) known += (known.empty() ? "" : ", ") + std::string(n);
    return bad("unknown preset \"" + std::string(name) + "\" (known: " + known + ")");
  }
  auto wrong = [&](const std::string& what) {
    return bad("preset \"" + std::string(name) + "\": " + what);
  };
  auto num = [](double x) {
    std::ostringstream s;
    s << x;
    return s.str();
  };
  if (o.image_width < 1 || o.image_height < 1)
    return wrong("the image size " + std::to_string(o.image_width) + "x" +
                 std::to_string(o.image_height) + " is empty");
  if (!(o.fps > 0 && o.fps <= kMaxFps))
    return wrong("fps " + num(o.fps) + " is outside (0, " + num(kMaxFps) + "]");
  if (!(o.duration_s > 0 && o.duration_s <= kMaxDurationS))
    return wrong("duration_s " + num(o.duration_s) + " is outside (0, " + num(kMaxDurationS) + "]");
  if (o.viewport_width < 1 || o.viewport_width > 16384 || o.viewport_height < 1 ||
      o.viewport_height > 16384)
    return wrong("the viewport " + std::to_string(o.viewport_width) + "x" +
                 std::to_string(o.viewport_height) + " is outside 1 to 16384 pixels");
  // The last frame: the duration's, rounded up (but not for a product that missed a whole
  // number by rounding, 0.1 s at 30 fps).
  const double frames = std::max(1.0, std::ceil(o.duration_s * o.fps - 1e-9));
  const double dwell = std::round(o.dwell_s * o.fps);
  if (name == "jumps" && !(std::isfinite(o.dwell_s) && dwell >= 2))
    return wrong("dwell_s " + num(o.dwell_s) + " at " + num(o.fps) + " fps is less than 2 frames");
  if (name == "jumps" && frames / dwell > double(kMaxKeys / 2))
    return wrong("duration_s / dwell_s gives more than " + std::to_string(kMaxKeys / 2) +
                 " places");

  Rng rng(o.seed);
  CameraPath path;
  if (name == "flyover") {
    path.keys_ = flyover(o, frames, rng);
  } else if (name == "zoom") {
    path.keys_ = zoom(o, frames, rng);
  } else if (name == "jumps") {
    path.keys_ = jumps(o, frames, dwell, rng);
  } else {
    path.keys_ = pan(o, frames, rng);
  }
  path.has_plane_ = name == "pan";
  path.has_globe_ = !path.has_plane_;
  return path;
}

}  // namespace vts::renderer
