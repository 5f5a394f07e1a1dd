#include "vts/protocol/tiling.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <numbers>

#include "vts/base/file_io.hpp"

namespace vts {
inline namespace protocol {
namespace {

using nlohmann::ordered_json;

constexpr double kDeg = std::numbers::pi / 180.0;
// Metres per degree on the WGS 84 semi-major axis (the TMS scaleDenominator convention).
constexpr double kMetresPerDegree = 2.0 * std::numbers::pi * 6378137.0 / 360.0;

// Texels across the whole level (both axes for Web Mercator, the width for CRS84).
double level_side(std::uint32_t tile_size, int level) {
  return std::ldexp(double(tile_size), level);
}

// v rounded when within 1e-6 of an integer, so a footprint edge on a texel boundary computed with
// a rounding error does not take in one more texel.
double snap(double v) {
  const double r = std::round(v);
  return std::abs(v - r) < 1e-6 ? r : v;
}

std::uint64_t clamp_to(double v, std::uint64_t max) {
  if (!(v > 0)) return 0;  // also NaN
  if (v >= double(max)) return max;
  return static_cast<std::uint64_t>(v);
}

}  // namespace

std::string_view tiling_name(Tiling t) noexcept {
  switch (t) {
    case Tiling::world_crs84_quad:
      return "WorldCRS84Quad";
    case Tiling::web_mercator_quad:
      return "WebMercatorQuad";
    case Tiling::none:
      break;
  }
  return "none";
}

Result<Tiling> parse_tiling(std::string_view text) {
  for (Tiling t : {Tiling::none, Tiling::world_crs84_quad, Tiling::web_mercator_quad}) {
    if (iequals(text, tiling_name(t))) return t;
  }
  return make_error(ErrorCode::invalid_argument,
                    "unknown tiling scheme \"" + std::string(text) +
                        "\" (known: WorldCRS84Quad, WebMercatorQuad, none)");
}

std::string_view tiling_crs(Tiling t) noexcept {
  switch (t) {
    case Tiling::world_crs84_quad:
      return "OGC:CRS84";
    case Tiling::web_mercator_quad:
      return "EPSG:3857";
    case Tiling::none:
      break;
  }
  return "";
}

std::string_view tiling_crs_uri(Tiling t) noexcept {
  switch (t) {
    case Tiling::world_crs84_quad:
      return "http://www.opengis.net/def/crs/OGC/1.3/CRS84";
    case Tiling::web_mercator_quad:
      return "http://www.opengis.net/def/crs/EPSG/0/3857";
    case Tiling::none:
      break;
  }
  return "";
}

LonLatBounds scheme_extent(Tiling t) noexcept {
  if (t == Tiling::web_mercator_quad) return {-180, -kWebMercatorMaxLat, 180, kWebMercatorMaxLat};
  return {-180, -90, 180, 90};
}

int level_from_tms(Tiling t, int tms_level) noexcept {
  return t == Tiling::world_crs84_quad ? tms_level + 1 : tms_level;
}

int tms_level(Tiling t, int level) noexcept {
  return t == Tiling::world_crs84_quad ? level - 1 : level;
}

Result<Geometry> tiling_geometry(Tiling t, int tms_max_level, std::uint32_t tile_size,
                                 std::uint32_t border) {
  if (t == Tiling::none)
    return make_error(ErrorCode::invalid_argument, "tiling scheme \"none\" has no geometry");
  if (tms_max_level < 0 || tms_max_level > Geometry::kMaxZoom)
    return make_error(ErrorCode::invalid_argument, "TMS level " + std::to_string(tms_max_level) +
                                                       " is not within 0.." +
                                                       std::to_string(Geometry::kMaxZoom));
  const int z = level_from_tms(t, tms_max_level);
  if (z > Geometry::kMaxZoom)
    return make_error(ErrorCode::invalid_argument,
                      std::string(tiling_name(t)) + " TMS level " + std::to_string(tms_max_level) +
                          " needs pyramid level " + std::to_string(z) + ", beyond " +
                          std::to_string(Geometry::kMaxZoom));
  const std::uint64_t side = std::uint64_t{tile_size} << z;
  const std::uint64_t height = t == Tiling::world_crs84_quad ? side / 2 : side;
  return Geometry::create(side, height, tile_size, border);
}

Status check_tiling_geometry(Tiling t, const Geometry& g) {
  if (t == Tiling::none) return {};
  const std::uint64_t side = std::uint64_t{g.tile_size()} << g.max_zoom();
  const std::uint64_t height = t == Tiling::world_crs84_quad ? side / 2 : side;
  const std::string scheme(tiling_name(t));
  const std::string size = std::to_string(g.width()) + "x" + std::to_string(g.height());
  if (t == Tiling::world_crs84_quad && g.max_zoom() < 1)
    return make_error(ErrorCode::invalid_argument,
                      scheme + " needs at least two tiles across (image " + size + ", tile " +
                          std::to_string(g.tile_size()) + ")");
  if (g.width() != side || g.height() != height)
    return make_error(ErrorCode::invalid_argument,
                      scheme + " at tile size " + std::to_string(g.tile_size()) +
                          " needs an image of " + std::to_string(side) + "x" +
                          std::to_string(height) + " texels (2^" + std::to_string(g.max_zoom()) +
                          " tiles across" +
                          (t == Tiling::world_crs84_quad ? ", width = 2 x height" : ", square") +
                          "), not " + size);
  return {};
}

TexelPoint lonlat_to_texel(Tiling t, std::uint32_t tile_size, int level, LonLat p) noexcept {
  assert(t != Tiling::none);
  const double n = level_side(tile_size, level);
  const double x = (p.lon + 180.0) / 360.0 * n;
  if (t == Tiling::world_crs84_quad) return {x, (90.0 - p.lat) / 360.0 * n};
  const double merc = std::asinh(std::tan(p.lat * kDeg));  // northing / R
  return {x, (1.0 - merc / std::numbers::pi) / 2.0 * n};
}

LonLat texel_to_lonlat(Tiling t, std::uint32_t tile_size, int level, TexelPoint p) noexcept {
  assert(t != Tiling::none);
  const double n = level_side(tile_size, level);
  const double lon = p.x / n * 360.0 - 180.0;
  if (t == Tiling::world_crs84_quad) return {lon, 90.0 - p.y / n * 360.0};
  return {lon, std::atan(std::sinh(std::numbers::pi * (1.0 - 2.0 * p.y / n))) / kDeg};
}

LonLatBounds tile_bounds_degrees(Tiling t, std::uint32_t tile_size, TileId id) noexcept {
  const double T = tile_size;
  const LonLat nw = texel_to_lonlat(t, tile_size, id.z, {id.x * T, id.y * T});
  const LonLat se = texel_to_lonlat(t, tile_size, id.z, {(id.x + 1.0) * T, (id.y + 1.0) * T});
  return {nw.lon, se.lat, se.lon, nw.lat};
}

CrsBounds tile_bounds_crs(Tiling t, std::uint32_t tile_size, TileId id) noexcept {
  if (t == Tiling::world_crs84_quad) {
    const LonLatBounds b = tile_bounds_degrees(t, tile_size, id);
    return {b.west, b.south, b.east, b.north};
  }
  const double span = level_cell_size(t, tile_size, id.z) * tile_size;
  return {-kWebMercatorHalfSide + id.x * span, kWebMercatorHalfSide - (id.y + 1.0) * span,
          -kWebMercatorHalfSide + (id.x + 1.0) * span, kWebMercatorHalfSide - id.y * span};
}

double level_cell_size(Tiling t, std::uint32_t tile_size, int level) noexcept {
  const double n = level_side(tile_size, level);
  return t == Tiling::world_crs84_quad ? 360.0 / n : 2.0 * kWebMercatorHalfSide / n;
}

double level_scale_denominator(Tiling t, std::uint32_t tile_size, int level) noexcept {
  const double metres_per_unit = t == Tiling::world_crs84_quad ? kMetresPerDegree : 1.0;
  return level_cell_size(t, tile_size, level) * metres_per_unit / kOgcPixelSize;
}

TexelRect footprint_texels(Tiling t, const Geometry& g, const LonLatBounds& b) noexcept {
  const int z = g.max_zoom();
  const TexelPoint nw = lonlat_to_texel(t, g.tile_size(), z, {b.west, b.north});
  const TexelPoint se = lonlat_to_texel(t, g.tile_size(), z, {b.east, b.south});
  TexelRect r{
      clamp_to(std::floor(snap(nw.x)), g.width()), clamp_to(std::floor(snap(nw.y)), g.height()),
      clamp_to(std::ceil(snap(se.x)), g.width()), clamp_to(std::ceil(snap(se.y)), g.height())};
  // A footprint thinner than a texel still touches the texel it lies in.
  if (r.x1 <= r.x0) r.x0 = std::min(r.x0, g.width() - 1), r.x1 = r.x0 + 1;
  if (r.y1 <= r.y0) r.y0 = std::min(r.y0, g.height() - 1), r.y1 = r.y0 + 1;
  return r;
}

TileRect footprint_tiles(Tiling t, const Geometry& g, int level, const LonLatBounds& b) noexcept {
  const TexelRect r = g.map_rect(g.max_zoom(), footprint_texels(t, g, b), level);
  const std::uint64_t T = g.tile_size();
  return {static_cast<std::uint32_t>(r.x0 / T), static_cast<std::uint32_t>(r.y0 / T),
          static_cast<std::uint32_t>((r.x1 + T - 1) / T),
          static_cast<std::uint32_t>((r.y1 + T - 1) / T)};
}

std::uint64_t footprint_tile_count(Tiling t, const Geometry& g, const LonLatBounds& b) noexcept {
  std::uint64_t n = 0;
  for (int z = 0; z <= g.max_zoom(); ++z) n += footprint_tiles(t, g, z, b).count();
  return n;
}

LonLatLevel default_center(Tiling t, const Geometry& g, const LonLatBounds& b) noexcept {
  LonLatLevel c{(b.west + b.east) / 2, (b.south + b.north) / 2, g.max_zoom()};
  const TexelRect finest = footprint_texels(t, g, b);
  for (int z = 0; z < g.max_zoom(); ++z) {
    const TexelRect r = g.map_rect(g.max_zoom(), finest, z);
    if (std::max(r.width(), r.height()) >= g.tile_size()) {
      c.level = z;
      break;
    }
  }
  return c;
}

std::string tile_matrix_set_json(Tiling t, const Geometry& g, const LonLatBounds& footprint) {
  assert(t != Tiling::none && check_tiling_geometry(t, g).ok());
  const std::uint32_t T = g.tile_size();
  const bool crs84 = t == Tiling::world_crs84_quad;
  const ordered_json origin =
      crs84 ? ordered_json::array({-180.0, 90.0})
            : ordered_json::array({-kWebMercatorHalfSide, kWebMercatorHalfSide});
  ordered_json matrices = ordered_json::array();
  ordered_json limits = ordered_json::array();
  for (int z = crs84 ? 1 : 0; z <= g.max_zoom(); ++z) {
    const std::string id = std::to_string(tms_level(t, z));
    matrices.push_back({{"id", id},
                        {"scaleDenominator", level_scale_denominator(t, T, z)},
                        {"cellSize", level_cell_size(t, T, z)},
                        {"cornerOfOrigin", "topLeft"},
                        {"pointOfOrigin", origin},
                        {"tileWidth", T},
                        {"tileHeight", T},
                        {"matrixWidth", g.tiles_x(z)},
                        {"matrixHeight", g.tiles_y(z)}});
    const TileRect r = footprint_tiles(t, g, z, footprint);
    limits.push_back({{"tileMatrix", id},
                      {"minTileRow", r.y0},
                      {"maxTileRow", r.y1 - 1},
                      {"minTileCol", r.x0},
                      {"maxTileCol", r.x1 - 1}});
  }
  ordered_json j;
  j["id"] = std::string(tiling_name(t));
  j["title"] = crs84 ? "CRS84 for the World" : "Google Maps Compatible for the World";
  if (T == 256)
    j["uri"] = std::string("http://www.opengis.net/def/tilematrixset/OGC/1.0/") +
               std::string(tiling_name(t));
  j["crs"] = std::string(tiling_crs_uri(t));
  j["orderedAxes"] = crs84 ? ordered_json::array({"Lon", "Lat"}) : ordered_json::array({"X", "Y"});
  j["tileMatrices"] = std::move(matrices);
  j["tileMatrixSetLimits"] = std::move(limits);
  return j.dump(2) + "\n";
}

}  // namespace protocol
}  // namespace vts
