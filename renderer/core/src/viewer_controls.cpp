#include "vts/renderer/viewer_controls.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <numbers>

#include "vts/base/file_io.hpp"
#include "vts/protocol/json_input.hpp"

namespace vts::renderer {

CameraKey default_camera(const Geometry& g, int width, int height) {
  CameraKey k;
  k.plane.center_u = double(g.width()) / 2;
  k.plane.center_v = double(g.height()) / 2;
  k.plane.texels_per_pixel =
      std::max(double(g.width()) / width, double(g.height()) / height) * 1.05;
  k.globe.lon_deg = 0;
  k.globe.lat_deg = 20;
  k.globe.altitude_m = 2e7;
  return k;
}

Status parse_scene(const std::string& spec, bool& globe, CameraKey& camera) {
  if (spec == "plane" || spec == "globe") {
    globe = spec == "globe";
    return {};
  }
  auto text = read_file(spec);
  if (!text) {
    return make_error(ErrorCode::invalid_argument,
                      "--scene '" + spec + "' is neither plane, globe nor a readable JSON file");
  }
  auto bad = [&](const std::string& why) {
    return make_error(ErrorCode::invalid_argument, "--scene " + spec + ": " + why);
  };
  // Depth-limited, and only the camera's known keys are copied (a scene file may come from
  // anywhere).
  auto parsed = parse_json(*text, "the file");
  if (!parsed) return bad(parsed.error().message);
  const nlohmann::json& doc = *parsed;
  if (!doc.is_object()) return bad("not a JSON object");
  auto s = doc.find("scene");
  if (s == doc.end() || !s->is_string() || (*s != "plane" && *s != "globe"))
    return bad("\"scene\" must be \"plane\" or \"globe\"");
  globe = *s == "globe";
  if (auto c = doc.find("camera"); c != doc.end()) {
    if (!c->is_object()) return bad("\"camera\" is not a JSON object");
    nlohmann::json key = nlohmann::json::object();
    for (const char* k : {"center", "texels_per_pixel", "lon", "lat", "altitude_m", "heading",
                          "tilt", "fov_y", "move"}) {
      if (auto it = c->find(k); it != c->end()) key[k] = *it;
    }
    key["frame"] = 0;
    auto path = CameraPath::parse(nlohmann::json{{"keys", {key}}}.dump(), camera);
    if (!path) {
      std::string msg = path.error().message;
      const std::string prefix = "camera path: key 0: ";
      if (msg.rfind(prefix, 0) == 0) msg = msg.substr(prefix.size());
      return bad("\"camera\": " + msg);
    }
    camera = path->keys().front();
  }
  return {};
}

std::vector<std::string> hud_lines(const HudNumbers& n, bool globe, const PlaneView& p,
                                   const GlobeView& g) {
  char buf[4][160];
  std::snprintf(buf[0], sizeof buf[0], "resident %u  pending %u  uploads %.1f/frame", n.resident,
                n.pending, n.uploads);
  std::snprintf(buf[1], sizeof buf[1], "hit %.1f%%  bias %.2f  %.1f ms/frame%s%s",
                n.hit_ratio * 100, n.mip_bias, n.frame_ms, n.debug.empty() ? "" : "  debug ",
                n.debug.c_str());
  if (globe) {
    std::snprintf(buf[2], sizeof buf[2], "lon %.4f  lat %.4f  altitude %.0f m", g.lon_deg,
                  g.lat_deg, g.altitude_m);
  } else {
    std::snprintf(buf[2], sizeof buf[2], "center %.1f, %.1f  %.3g texels/pixel%s%s", p.center_u,
                  p.center_v, p.texels_per_pixel, n.place.empty() ? "" : "  ", n.place.c_str());
  }
  std::snprintf(buf[3], sizeof buf[3], "%s slots  physical %.1f MiB  page table %.2f MiB",
                n.bc1 ? "bc1 (S3TC)" : "rgba8", double(n.physical_bytes) / (1 << 20),
                double(n.page_table_bytes) / (1 << 20));
  return {buf[0], buf[1], buf[3], buf[2]};
}

float hud_scale(int framebuffer_height) {
  // stb_easy_font's glyphs are 9 pixels tall at scale 1.
  return std::max(1.0f, std::floor(float(framebuffer_height) / 360.0f));
}

// ---- CameraControls --------------------------------------------------------------------------

CameraControls::CameraControls(bool globe, const CameraKey& start, std::uint64_t image_width,
                               std::uint64_t image_height)
    : plane(start.plane),
      globe_view(start.globe),
      globe_(globe),
      image_w_(image_width),
      image_h_(image_height) {}

void CameraControls::button(Button b, bool down, double x, double y) {
  if (b == Button::left) left_ = down;
  if (b == Button::right) right_ = down;
  if (!cursor_seen_) {
    last_x_ = x;
    last_y_ = y;
    cursor_seen_ = true;
  }
}

std::optional<std::pair<double, double>> CameraControls::cursor_pixel() const {
  if (!cursor_seen_) return std::nullopt;
  return std::pair<double, double>{last_x_ * scale_, last_y_ * scale_};
}

void CameraControls::cursor(double x, double y, double scale, int fb_width, int fb_height) {
  const double dx = (x - last_x_) * scale, dy = (y - last_y_) * scale;
  const double px = last_x_ * scale, py = last_y_ * scale;
  last_x_ = x;
  last_y_ = y;
  scale_ = scale;
  const bool first = !cursor_seen_;
  cursor_seen_ = true;
  if (first || (!left_ && !right_)) return;
  touched = true;
  drag(dx, dy, px, py, fb_width, std::max(fb_height, 1));
}

void CameraControls::drag(double dx, double dy, double px, double py, int fw, int fh) {
  if (globe_) {
    GlobeView& g = globe_view;
    if (left_) {
      // Degrees per pixel near the nadir: the ground a pixel covers at this altitude.
      const double deg =
          g.altitude_m * 2 * std::tan(g.fov_y / 2) / fh / g.radius_m * 180 / std::numbers::pi;
      const double ch = std::cos(g.heading), sh = std::sin(g.heading);
      // Screen right/up rotated by the heading into east/north.
      const double east = -(dx * ch + dy * sh) * deg, north = (dy * ch - dx * sh) * deg;
      g.lon_deg = std::remainder(
          g.lon_deg + east / std::max(std::cos(g.lat_deg * std::numbers::pi / 180), 0.05), 360.0);
      g.lat_deg = std::clamp(g.lat_deg + north, -89.0, 89.0);
    } else {
      g.heading += dx * 0.005;
      g.tilt = std::clamp(g.tilt + dy * 0.005, 0.0, 1.4);
    }
    return;
  }
  PlaneView& v = plane;
  if (left_) {
    // Keep the texel under the cursor under the cursor.
    const PlaneCamera cam = PlaneCamera::from_view(v, fw, fh);
    auto a = cam.hit(px, py), b = cam.hit(px + dx, py + dy);
    if (a && b) {
      v.center_u += a->first - b->first;
      v.center_v += a->second - b->second;
    } else {
      const double ch = std::cos(v.heading), sh = std::sin(v.heading);
      v.center_u -= (dx * ch - dy * sh) * v.texels_per_pixel;
      v.center_v -= (dx * sh + dy * ch) * v.texels_per_pixel;
    }
  } else {
    v.heading += dx * 0.005;
    v.tilt = std::clamp(v.tilt + dy * 0.005, 0.0, 1.4);
  }
}

void CameraControls::scroll(double yoffset, double x, double y, double scale, int fb_width,
                            int fb_height) {
  touched = true;
  const double f = std::pow(1.25, -yoffset);  // scroll up: closer
  if (globe_) {
    globe_view.altitude_m = std::clamp(globe_view.altitude_m * f, 1.0, 1e9);
    return;
  }
  if (cursor_seen_) {
    x = last_x_;
    y = last_y_;
  }
  const int fh = std::max(fb_height, 1);
  PlaneView& v = plane;
  const auto before = PlaneCamera::from_view(v, fb_width, fh).hit(x * scale, y * scale);
  const double max_tpp = 4.0 * double(std::max(image_w_, image_h_));
  v.texels_per_pixel = std::clamp(v.texels_per_pixel * f, 1.0 / 64, max_tpp);
  const auto after = PlaneCamera::from_view(v, fb_width, fh).hit(x * scale, y * scale);
  if (before && after) {
    v.center_u += before->first - after->first;
    v.center_v += before->second - after->second;
  }
}

void CameraControls::key(Key k, bool repeat) {
  double& heading = globe_ ? globe_view.heading : plane.heading;
  double& tilt = globe_ ? globe_view.tilt : plane.tilt;
  switch (k) {
    case Key::one:
    case Key::two:
    case Key::three:
    case Key::four:
      debug_request = int(k) - int(Key::one);
      return;
    case Key::h:
      if (!repeat) show_hud = !show_hud;
      return;
    case Key::q:
      heading -= 0.05;
      break;
    case Key::e:
      heading += 0.05;
      break;
    case Key::r:
      tilt = std::clamp(tilt + 0.05, 0.0, 1.4);
      break;
    case Key::f:
      tilt = std::clamp(tilt - 0.05, 0.0, 1.4);
      break;
    case Key::other:
      return;
  }
  touched = true;
}

// ---- CameraRecorder --------------------------------------------------------------------------

void CameraRecorder::add(double frame, const PlaneView& plane, const GlobeView& globe, bool move) {
  CameraKey k;
  k.t = frame;
  k.plane = plane;
  k.globe = globe;
  k.move = move || keys_.empty();
  if (keys_.empty()) {
    keys_.push_back(k);
  } else if (k.move || !same(k, last_)) {
    if (keys_.back().t < last_.t) keys_.push_back(last_);  // the end of a still stretch
    keys_.push_back(k);
  }
  last_ = k;
  last_.move = false;
}

CameraPath CameraRecorder::path() const {
  std::vector<CameraKey> keys = keys_;
  if (!keys.empty() && keys.back().t < last_.t) keys.push_back(last_);
  return CameraPath(std::move(keys), !globe_, globe_);
}

bool CameraRecorder::same(const CameraKey& a, const CameraKey& b) const {
  if (globe_) {
    const GlobeView &x = a.globe, &y = b.globe;
    return x.lon_deg == y.lon_deg && x.lat_deg == y.lat_deg && x.altitude_m == y.altitude_m &&
           x.heading == y.heading && x.tilt == y.tilt && x.fov_y == y.fov_y;
  }
  const PlaneView &x = a.plane, &y = b.plane;
  return x.center_u == y.center_u && x.center_v == y.center_v &&
         x.texels_per_pixel == y.texels_per_pixel && x.heading == y.heading && x.tilt == y.tilt &&
         x.fov_y == y.fov_y;
}

}  // namespace vts::renderer
