#include "vts/renderer/geo_view.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numbers>

#include "vts/renderer/globe.hpp"

namespace vts::renderer {

namespace {

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

}  // namespace

Status check_globe_tiling(Tiling t) {
  if (t == Tiling::web_mercator_quad)
    return make_error(
        ErrorCode::unsupported,
        "the globe scene cannot show a WebMercatorQuad tileset (its rows are Mercator, "
        "the globe maps rows linearly to latitude); use --scene plane");
  return {};
}

Result<CameraKey> camera_at(const CameraKey& base, Tiling t, const Geometry& g, LonLat at,
                            int level) {
  if (t == Tiling::none)
    return make_error(ErrorCode::invalid_argument,
                      "the tileset is not georeferenced: it has no longitude or latitude");
  const LonLatBounds ext = scheme_extent(t);
  if (!(at.lon >= ext.west && at.lon <= ext.east && at.lat >= ext.south && at.lat <= ext.north))
    return make_error(ErrorCode::invalid_argument,
                      "center " + num(at.lon) + "," + num(at.lat) + " is outside " +
                          std::string(tiling_name(t)) + "'s extent (longitude " + num(ext.west) +
                          " to " + num(ext.east) + ", latitude " + num(ext.south) + " to " +
                          num(ext.north) + ")");
  if (level < 0 || level > g.max_zoom())
    return make_error(ErrorCode::invalid_argument, "level " + std::to_string(level) +
                                                       " is outside the tileset's levels 0-" +
                                                       std::to_string(g.max_zoom()));
  CameraKey k = base;
  const TexelPoint p = lonlat_to_texel(t, g.tile_size(), g.max_zoom(), at);
  const double zoom = std::ldexp(1.0, g.max_zoom() - level);
  k.plane.center_u = p.x;
  k.plane.center_v = p.y;
  k.plane.texels_per_pixel = zoom;
  k.globe.lon_deg = at.lon;
  k.globe.lat_deg = at.lat;
  k.globe.tilt = 0;
  // Straight down the distance to the ground is the altitude (GlobeScene::texels_per_pixel).
  const double pixel_rad = 2 * std::tan(k.globe.fov_y / 2) / kGlobeNominalHeightPx;
  k.globe.altitude_m =
      zoom * 2 * std::numbers::pi * k.globe.radius_m / (pixel_rad * double(g.width()));
  return k;
}

CameraPath plane_path_from_places(const CameraPath& path, Tiling t, const Geometry& g) {
  const LonLatBounds ext = scheme_extent(t);
  std::vector<CameraKey> keys = path.keys();
  for (CameraKey& k : keys) {
    const LonLat at{k.globe.lon_deg, std::clamp(k.globe.lat_deg, ext.south, ext.north)};
    const TexelPoint p = lonlat_to_texel(t, g.tile_size(), g.max_zoom(), at);
    k.plane.center_u = p.x;
    k.plane.center_v = p.y;
    // camera_at()'s altitude for a zoom, inverted.
    const double pixel_rad = 2 * std::tan(k.globe.fov_y / 2) / kGlobeNominalHeightPx;
    k.plane.texels_per_pixel = k.globe.altitude_m * pixel_rad * double(g.width()) /
                               (2 * std::numbers::pi * k.globe.radius_m);
    k.plane.heading = k.globe.heading;
    k.plane.tilt = k.globe.tilt;
  }
  return CameraPath(std::move(keys), true, true);
}

std::optional<std::string> fit_path_to_scene(CameraPath& path, bool globe, Tiling t,
                                             const Geometry& g) {
  if (globe ? path.has_globe() || !path.has_plane() : path.has_plane() || !path.has_globe())
    return std::nullopt;
  if (!globe && t != Tiling::none) {
    path = plane_path_from_places(path, t, g);
    return std::nullopt;
  }
  return std::string(" has only ") + (globe ? "plane" : "globe") + " fields; the " +
         (globe ? "globe" : "plane") + " camera stays where it is";
}

Status start_at_place(const std::optional<Georeference>& geo, const Geometry& g,
                      const std::string& center, int level, CameraKey& camera) {
  if (center.empty() && level < 0) return {};
  const std::string flag = center.empty() ? "--level" : "--center";
  LonLat at;
  if (!center.empty()) {
    char* end = nullptr;
    at.lon = std::strtod(center.c_str(), &end);
    const bool comma = end != center.c_str() && *end == ',';
    const char* lat_text = comma ? end + 1 : end;
    at.lat = comma ? std::strtod(lat_text, &end) : 0;
    if (!comma || end == lat_text || *end != '\0' || !std::isfinite(at.lon) ||
        !std::isfinite(at.lat))
      return make_error(ErrorCode::invalid_argument,
                        "--center '" + center + "' is not of the form LON,LAT (degrees)");
  }
  if (!geo)
    return make_error(
        ErrorCode::invalid_argument,
        flag + ": the tileset is not georeferenced (it has no longitude or latitude)");
  if (center.empty()) at = LonLat{geo->center.lon, geo->center.lat};
  auto k = camera_at(camera, geo->tiling, g, at,
                     level >= 0 ? level : std::min(geo->center.level, g.max_zoom()));
  if (!k) return make_error(k.error().code, flag + ": " + k.error().message);
  camera = *k;
  return {};
}

std::string lonlat_text(Tiling t, const Geometry& g, double u, double v) {
  const LonLat p = texel_to_lonlat(t, g.tile_size(), g.max_zoom(), TexelPoint{u, v});
  char buf[64];
  std::snprintf(buf, sizeof buf, "lon %.5f  lat %.5f", p.lon, p.lat);
  return buf;
}

std::string plane_place_text(Tiling t, const Geometry& g, const PlaneView& view, int width,
                             int height, std::optional<std::pair<double, double>> cursor) {
  if (cursor) {
    if (auto uv = PlaneCamera::from_view(view, width, height).hit(cursor->first, cursor->second))
      return lonlat_text(t, g, uv->first, uv->second) + " (cursor)";
  }
  return lonlat_text(t, g, view.center_u, view.center_v) + " (centre)";
}

}  // namespace vts::renderer
