// What the OGC entry points (WMTS 1.0.0: router_wmts.cpp; OGC API - Tiles: router_ogcapi.cpp)
// share: which tilesets they offer, in which tile matrix sets, at which TMS levels, and how a TMS
// tile maps onto the web image routes that make its bytes (router_web.cpp). Pure but for the
// tile answer, which is the web route's. docs/PROTOCOL.md §15.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "router_internal.hpp"
#include "vts/imaging/web_image.hpp"
#include "vts/protocol/tiling.hpp"

namespace vts {
inline namespace server {
namespace router_detail {

// The georeferenced archive tilesets of the registry, sorted by name, that are not protected
// (bearer tokens or signed URLs: those are served only on their own routes, with credentials,
// and are never listed here). Provided tilesets (vts cache serve) are not offered.
std::vector<std::shared_ptr<const Tileset>> ogc_tilesets(const TilesetRegistry& registry,
                                                         const RouterConfig& config);
// One of ogc_tilesets() by name; nullptr with `why` set (no such tileset, not georeferenced,
// or protected).
std::shared_ptr<const Tileset> ogc_tileset(const TilesetRegistry& registry,
                                           const RouterConfig& config, std::string_view name,
                                           std::string& why);

// A tile matrix set of OGC 17-083r4 on a scheme with T x T tiles. Its identifier is the scheme's
// name for T = 256 (the registered set), else "<name>-<T>" (our own set, same origin and cell
// sizes per level times 256 / T).
struct MatrixSetKey {
  Tiling tiling = Tiling::web_mercator_quad;
  std::uint32_t tile_size = 256;
  bool operator==(const MatrixSetKey&) const = default;
  std::string id() const;
};
// Inverse of MatrixSetKey::id(); nullopt for anything else.
std::optional<MatrixSetKey> parse_matrix_set_id(std::string_view id);

// One tile matrix of a set: TMS level `tms`, its scale, cell size and matrix size.
struct TileMatrix {
  int tms = 0;
  double scale_denominator = 0, cell_size = 0;
  std::uint64_t matrix_width = 0, matrix_height = 0;
};
// Levels 0..max_tms of the set (max_tms >= 0).
std::vector<TileMatrix> tile_matrices(MatrixSetKey key, int max_tms);
// The deepest TMS level a definition of the set lists: the deepest of the offered tilesets'
// (clients such as GDAL's WMTS driver read every level the set defines, whatever a layer's
// limits say), or the registered set's (WebMercatorQuad 24, WorldCRS84Quad 23) when none is.
int matrix_set_depth(MatrixSetKey key, const std::vector<std::shared_ptr<const Tileset>>& offered);

// How a tileset is offered in one tile matrix set: natively (its own scheme) or, for a
// WorldCRS84Quad tileset, as WebMercatorQuad through the reprojection route.
struct Offer {
  MatrixSetKey set;
  bool reprojected = false;
  int min_tms = 0, max_tms = 0;  // the TMS levels the tileset has in this set
};
// Native first. A WorldCRS84Quad tileset also offers WebMercatorQuad when its footprint reaches
// inside +-85.05 degrees (imaging::web_mercator_range).
std::vector<Offer> ogc_offers(const Tileset& t);
// The offer of `t` in the set named `set_id`; nullopt when it has none.
std::optional<Offer> find_offer(const Tileset& t, std::string_view set_id);

// Per TMS level of the offer, the tiles holding any of the footprint (inclusive bounds).
struct TileLimits {
  int tms = 0;
  std::uint32_t min_row = 0, max_row = 0, min_col = 0, max_col = 0;
};
std::vector<TileLimits> offer_limits(const Tileset& t, const Offer& offer);
// The footprint in degrees as the offer shows it (latitudes clipped for WebMercatorQuad).
LonLatBounds offer_bounds(const Tileset& t, const Offer& offer);

// Whether TMS tile (tms, row, col) lies inside the offer's levels and that level's matrix.
bool offer_has_tile(const Offer& offer, int tms, std::uint64_t row, std::uint64_t col);
// The web image of TMS tile (tms, row, col), which offer_has_tile(): the answer of
// web_tile_route (native; our level = the TMS level, + 1 for WorldCRS84Quad) or of
// web_mercator_tile_route (reprojected), unversioned.
HttpResponse offer_tile(const HttpRequest& request, std::shared_ptr<const Tileset> t,
                        const Offer& offer, int tms, std::uint32_t row, std::uint32_t col,
                        imaging::WebFormat format, const RouterConfig& config);

// "image/png", "image/webp", "image/jpeg" (and "image/jpg"); nullopt otherwise.
std::optional<imaging::WebFormat> format_from_media_type(std::string_view type);
// "png", "webp", "jpg" / "jpeg"; nullopt otherwise.
std::optional<imaging::WebFormat> format_from_extension(std::string_view ext);
inline constexpr imaging::WebFormat kOgcFormats[] = {
    imaging::WebFormat::png, imaging::WebFormat::webp, imaging::WebFormat::jpeg};

// A number as the capabilities and JSON documents write it: the shortest text that reads back
// as the same double.
std::string number_text(double v);

}  // namespace router_detail
}  // namespace server
}  // namespace vts
