// Tiling schemes: how a georeferenced pyramid sits on an OGC 2D Tile Matrix Set (OGC 17-083r4,
// docs/FORMAT.md "Georeference"). Our pyramid (geometry.hpp) is a square quadtree with the image at
// the top-left of the finest level; the two schemes map onto it as follows.
//
//   WebMercatorQuad (EPSG:3857): TMS level k = our level k. The image is 2^k*T x 2^k*T texels, the
//     square from (-20037508.342789244, 20037508.342789244) metres (top-left), x east, y south.
//   WorldCRS84Quad (OGC:CRS84, plate carree, poles included): TMS level k has 2^(k+1) x 2^k tiles,
//     which is the top half of our level k+1: our level = TMS level + 1, the image is 2^(k+1)*T x
//     2^k*T texels from (-180, 90). Our level 0 (the whole globe in the top half of one tile) is a
//     downsampled root the TMS does not have. Tile (z, x, y) of ours is TMS tile (z-1, col x, row
//     y).
//
// Every function is pure and thread-safe. Functions taking a Tiling require one other than none
// (asserted); "level" always means our level unless the name says tms.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/protocol/geometry.hpp"

namespace vts {
inline namespace protocol {

enum class Tiling { none, world_crs84_quad, web_mercator_quad };

// "none", "WorldCRS84Quad", "WebMercatorQuad" (OGC's spelling).
std::string_view tiling_name(Tiling t) noexcept;
// Inverse of tiling_name(); case-insensitive. Error invalid_argument naming the known schemes.
Result<Tiling> parse_tiling(std::string_view text);
// The CRS as a short code ("OGC:CRS84", "EPSG:3857") and as the OGC URI the TMS JSON uses.
std::string_view tiling_crs(Tiling t) noexcept;
std::string_view tiling_crs_uri(Tiling t) noexcept;

// Half of the Web Mercator square's side, in metres: pi * 6378137.
inline constexpr double kWebMercatorHalfSide = 20037508.342789244;
// The latitude at which the Web Mercator square ends (atan(sinh(pi)), degrees).
inline constexpr double kWebMercatorMaxLat = 85.05112877980659;
// OGC's "standardized rendering pixel size", metres, used by scaleDenominator.
inline constexpr double kOgcPixelSize = 0.00028;

struct LonLat {
  double lon = 0, lat = 0;
};
// A box in degrees (west < east, south < north; no antimeridian crossing).
struct LonLatBounds {
  double west = 0, south = 0, east = 0, north = 0;
  bool operator==(const LonLatBounds&) const = default;
};
// A box in the scheme's CRS units (metres for EPSG:3857, degrees for OGC:CRS84).
struct CrsBounds {
  double min_x = 0, min_y = 0, max_x = 0, max_y = 0;
};
// A position in level-z texel coordinates: (0, 0) is the top-left corner of the level, texel
// (i, j) spans [i, i+1) x [j, j+1).
struct TexelPoint {
  double x = 0, y = 0;
};
// A half-open rectangle of tiles [x0, x1) x [y0, y1) at one level.
struct TileRect {
  std::uint32_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  std::uint64_t count() const { return std::uint64_t(x1 - x0) * (y1 - y0); }
  bool operator==(const TileRect&) const = default;
};

// The whole area the scheme covers, in degrees: the globe, or Web Mercator's +-85.0511 degrees.
LonLatBounds scheme_extent(Tiling t) noexcept;

// Our level for a TMS level and back. tms_level() of WorldCRS84Quad level 0 is -1 (no TMS level).
int level_from_tms(Tiling t, int tms_level) noexcept;
int tms_level(Tiling t, int level) noexcept;

// The pyramid of a scheme whose finest TMS level is tms_max_level, with T x T tiles of content
// and the given border. Errors (invalid_argument): Tiling::none, a negative level, or a geometry
// Geometry::create() refuses (tile size, border, too many levels).
Result<Geometry> tiling_geometry(Tiling t, int tms_max_level, std::uint32_t tile_size,
                                 std::uint32_t border);
// Whether the geometry is exactly a scheme's pyramid (WebMercatorQuad: W = H = 2^maxz * T;
// WorldCRS84Quad: W = 2H = 2^maxz * T with maxz >= 1). The error (invalid_argument) says which
// dimension disagrees and what it should be.
Status check_tiling_geometry(Tiling t, const Geometry& g);

// Degrees <-> level-z texel coordinates for tiles of T content texels. Coordinates outside the
// scheme's extent map outside the level (no clamping); Web Mercator maps the poles far outside.
TexelPoint lonlat_to_texel(Tiling t, std::uint32_t tile_size, int level, LonLat p) noexcept;
LonLat texel_to_lonlat(Tiling t, std::uint32_t tile_size, int level, TexelPoint p) noexcept;

// The area a tile's T x T content covers (its border not included).
LonLatBounds tile_bounds_degrees(Tiling t, std::uint32_t tile_size, TileId id) noexcept;
CrsBounds tile_bounds_crs(Tiling t, std::uint32_t tile_size, TileId id) noexcept;

// Size of one texel at a level in CRS units (TMS "cellSize"): metres for WebMercatorQuad (true
// on the ground at the equator only), degrees for WorldCRS84Quad.
double level_cell_size(Tiling t, std::uint32_t tile_size, int level) noexcept;
// The TMS scaleDenominator of a level: cellSize * metres per CRS unit / 0.28 mm.
double level_scale_denominator(Tiling t, std::uint32_t tile_size, int level) noexcept;

// The texels of the finest level that a footprint touches: floor of its top-left corner, ceil of
// its bottom-right corner (a value within 1e-6 texel of an integer counts as that integer),
// clipped to the image. Every level's tiles follow from it (footprint_tiles), so this is the
// region a sparse build writes.
TexelRect footprint_texels(Tiling t, const Geometry& g, const LonLatBounds& b) noexcept;
// The tiles of a level that hold any part of the footprint: footprint_texels() mapped to the
// level (rounded outwards) and divided into tiles. Never empty for a footprint inside the extent.
TileRect footprint_tiles(Tiling t, const Geometry& g, int level, const LonLatBounds& b) noexcept;
// Sum of footprint_tiles() over every level: the tile count of a sparse archive of the footprint.
std::uint64_t footprint_tile_count(Tiling t, const Geometry& g, const LonLatBounds& b) noexcept;

// A reasonable initial view of a footprint: its centre, at the coarsest level where its longer
// side spans at least one tile (T texels), at most max_zoom.
struct LonLatLevel {
  double lon = 0, lat = 0;
  int level = 0;
  bool operator==(const LonLatLevel&) const = default;
};
LonLatLevel default_center(Tiling t, const Geometry& g, const LonLatBounds& b) noexcept;

// The OGC 2D Tile Matrix Set JSON (OGC 17-083r4 §7.3, JSON encoding) of a tileset on the scheme:
// id, title, uri (only when T = 256: with other tile sizes it is not the registered set), crs,
// orderedAxes, and one tileMatrix per TMS level the archive has (WorldCRS84Quad: our levels
// 1..maxz), each with id (the TMS level), scaleDenominator, cellSize, cornerOfOrigin "topLeft",
// pointOfOrigin, tileWidth/tileHeight = T, matrixWidth/matrixHeight. Then "tileMatrixSetLimits"
// (as in OGC API - Tiles tileset metadata): per TMS level, the footprint's minTileRow, maxTileRow,
// minTileCol, maxTileCol (inclusive). Pretty-printed, trailing newline. g must pass
// check_tiling_geometry().
std::string tile_matrix_set_json(Tiling t, const Geometry& g, const LonLatBounds& footprint);

}  // namespace protocol
}  // namespace vts
