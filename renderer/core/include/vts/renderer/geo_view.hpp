// The viewer on a georeferenced tileset (docs/FORMAT.md §6, tiling.hpp): a start camera given in
// degrees, and which schemes the globe scene can show. Pure functions, no GL.
//
// The globe scene maps the finest level's W x H texels to longitude [-180, 180) and latitude
// [90, -90] (globe.hpp). A WorldCRS84Quad image is exactly that: W = 2H, (-180, 90) at its
// top-left, 360 / W degrees per texel on both axes, so the globe puts every texel of a sparse
// regional archive where lonlat_to_texel() says it is. A WebMercatorQuad image has a Mercator y:
// the globe refuses it (the plane scene shows it).
#pragma once

#include <optional>
#include <string>
#include <utility>

#include "vts/base/result.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/protocol/tileset.hpp"
#include "vts/protocol/tiling.hpp"
#include "vts/renderer/camera.hpp"
#include "vts/renderer/camera_path.hpp"

namespace vts::renderer {

// OK for Tiling::none (a plain image: the globe wraps it as equirectangular) and WorldCRS84Quad;
// unsupported naming the scheme for WebMercatorQuad.
Status check_globe_tiling(Tiling t);

// `base` with both cameras looking at `at`, at about one texel of level `level` per pixel: the
// plane's centre is lonlat_to_texel(t, T, maxz, at) and its zoom 2^(maxz - level) finest texels per
// pixel; the globe's nadir is `at`, straight down (tilt 0), at the altitude whose
// GlobeScene::texels_per_pixel() is that zoom. Errors (invalid_argument): Tiling::none (no
// georeference), a longitude outside [-180, 180] or a latitude outside the scheme's extent, a
// level outside 0..maxz.
Result<CameraKey> camera_at(const CameraKey& base, Tiling t, const Geometry& g, LonLat at,
                            int level);

// A camera path in geographic units on the plane of a georeferenced tileset: every key's plane
// view from its globe fields (lon, lat in degrees, altitude_m, heading, tilt): centre
// lonlat_to_texel() of the place (latitude clamped to the scheme's extent), zoom the one
// camera_at() pairs with that altitude (GlobeScene::texels_per_pixel() straight down). So one
// path of places flies both scenes of a georeferenced archive.
CameraPath plane_path_from_places(const CameraPath& path, Tiling t, const Geometry& g);

// vts view's --camera-path on a scene: a path of places alone (globe keys) on the plane of a
// georeferenced tileset becomes plane_path_from_places(); a path without the scene's kind of keys
// otherwise stays as it is and the result says so (" has only plane fields; the globe camera
// stays where it is"), nullopt when the path fits.
std::optional<std::string> fit_path_to_scene(CameraPath& path, bool globe, Tiling t,
                                             const Geometry& g);

// vts view's --center / --level: `camera` moved by camera_at() to `center` ("LON,LAT" in degrees;
// empty: the georeference's center) at `level` (-1: the georeference's level). Neither given:
// nothing changes. Errors (invalid_argument) name the flag: a center not of the form LON,LAT, no
// georeference, or camera_at()'s.
Status start_at_place(const std::optional<Georeference>& geo, const Geometry& g,
                      const std::string& center, int level, CameraKey& camera);

// The HUD's place on a georeferenced plane: lonlat_text() of the texel under `cursor` (framebuffer
// pixels of a width x height frame) with " (cursor)", or when there is no cursor or it is above
// the horizon, of the screen centre with " (centre)".
std::string plane_place_text(Tiling t, const Geometry& g, const PlaneView& view, int width,
                             int height, std::optional<std::pair<double, double>> cursor);

// "lon 12.34567  lat -45.67890": the place under finest texel (u, v) of the scheme.
std::string lonlat_text(Tiling t, const Geometry& g, double u, double v);

}  // namespace vts::renderer
