// Camera paths: JSON keyframes, interpolated (camera_path.hpp).
#include "vts/renderer/camera_path.hpp"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

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
  if (f <= 0) return a;  // exactly the key's value on (and beyond) a key
  if (f >= 1) return b;
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
  json doc = json::parse(json_text, nullptr, /*allow_exceptions=*/false);
  if (doc.is_discarded()) return bad("not valid JSON");
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

}  // namespace vts::renderer
