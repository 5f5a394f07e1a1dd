// The pieces WMTS and OGC API - Tiles share (router_ogc.hpp): offered tilesets, tile matrix
// sets, limits, and the mapping of a TMS tile onto the web image routes.
#include "router_ogc.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>

#include "vts/imaging/web_mercator.hpp"

namespace vts {
inline namespace server {
namespace router_detail {

namespace {

Tiling native_tiling(const Tileset& t) {
  return t.info.georeference ? t.info.georeference->tiling : Tiling::none;
}

}  // namespace

std::vector<std::shared_ptr<const Tileset>> ogc_tilesets(const TilesetRegistry& registry,
                                                         const RouterConfig& config) {
  std::vector<std::shared_ptr<const Tileset>> out;
  for (auto& t : registry.all()) {
    if (native_tiling(*t) != Tiling::none && !is_protected(config, t->name)) {
      out.push_back(std::move(t));
    }
  }
  return out;
}

std::shared_ptr<const Tileset> ogc_tileset(const TilesetRegistry& registry,
                                           const RouterConfig& config, std::string_view name,
                                           std::string& why) {
  auto t = registry.find(name);
  if (!t) {
    why = "no tileset named \"" + std::string(name) + "\"";
  } else if (native_tiling(*t) == Tiling::none) {
    why = "tileset \"" + t->name + "\" is not georeferenced: it has no tile matrix set";
  } else if (is_protected(config, t->name)) {
    why = "tileset \"" + t->name + "\" is protected: it is served only on its own routes (/" +
          t->name + "/{z}/{x}/{y}), with credentials";
  } else {
    return t;
  }
  return nullptr;
}

std::string MatrixSetKey::id() const {
  std::string id(tiling_name(tiling));
  if (tile_size != 256) id += "-" + std::to_string(tile_size);
  return id;
}

std::optional<MatrixSetKey> parse_matrix_set_id(std::string_view id) {
  for (Tiling t : {Tiling::web_mercator_quad, Tiling::world_crs84_quad}) {
    const std::string_view name = tiling_name(t);
    if (!id.starts_with(name)) continue;
    const std::string_view rest = id.substr(name.size());
    if (rest.empty()) return MatrixSetKey{t, 256};
    if (rest[0] != '-') return std::nullopt;
    const auto size = parse_u32(rest.substr(1));
    // A power of two that is not 256 (256 is the registered set's plain name).
    if (!size || *size < 16 || *size > 4096 || (*size & (*size - 1)) != 0 || *size == 256) {
      return std::nullopt;
    }
    return MatrixSetKey{t, *size};
  }
  return std::nullopt;
}

std::vector<TileMatrix> tile_matrices(MatrixSetKey key, int max_tms) {
  std::vector<TileMatrix> out;
  for (int k = 0; k <= max_tms; ++k) {
    const int level = level_from_tms(key.tiling, k);
    const std::uint64_t side = std::uint64_t(1) << level;
    const bool crs84 = key.tiling == Tiling::world_crs84_quad;
    out.push_back({k, level_scale_denominator(key.tiling, key.tile_size, level),
                   level_cell_size(key.tiling, key.tile_size, level), side,
                   crs84 ? side / 2 : side});
  }
  return out;
}

int matrix_set_depth(MatrixSetKey key, const std::vector<std::shared_ptr<const Tileset>>& offered) {
  int depth = -1;
  for (const auto& t : offered) {
    for (const Offer& o : ogc_offers(*t)) {
      if (o.set == key) depth = std::max(depth, o.max_tms);
    }
  }
  if (depth >= 0) return depth;
  return key.tiling == Tiling::web_mercator_quad ? 24 : 23;
}

std::vector<Offer> ogc_offers(const Tileset& t) {
  std::vector<Offer> out;
  const Tiling native = native_tiling(t);
  if (native == Tiling::none) return out;
  const Geometry& g = t.info.geometry;
  const MatrixSetKey own{native, g.tile_size()};
  if (native == Tiling::web_mercator_quad) {
    out.push_back({own, false, 0, g.max_zoom()});
    return out;
  }
  if (g.max_zoom() >= 1) out.push_back({own, false, 0, tms_level(native, g.max_zoom())});
  if (auto range = imaging::web_mercator_range(t.info)) {
    out.push_back(
        {{Tiling::web_mercator_quad, g.tile_size()}, true, range->min_zoom, range->max_zoom});
  }
  return out;
}

std::optional<Offer> find_offer(const Tileset& t, std::string_view set_id) {
  for (const Offer& o : ogc_offers(t)) {
    if (o.set.id() == set_id) return o;
  }
  return std::nullopt;
}

LonLatBounds offer_bounds(const Tileset& t, const Offer& offer) {
  LonLatBounds b = t.info.georeference->bounds;
  if (offer.set.tiling == Tiling::web_mercator_quad) {
    b.south = std::max(b.south, -kWebMercatorMaxLat);
    b.north = std::min(b.north, kWebMercatorMaxLat);
  }
  return b;
}

std::vector<TileLimits> offer_limits(const Tileset& t, const Offer& offer) {
  std::vector<TileLimits> out;
  const Geometry& own = t.info.geometry;
  // The pyramid the offer's tiles come from: the tileset's own, or the WebMercatorQuad pyramid
  // the reprojection route serves (same T and border, its zooms).
  Result<Geometry> pyramid = own;
  if (offer.reprojected) {
    pyramid =
        tiling_geometry(Tiling::web_mercator_quad, offer.max_tms, own.tile_size(), own.border());
    if (!pyramid) return out;
  }
  const LonLatBounds b = offer_bounds(t, offer);
  for (int k = offer.min_tms; k <= offer.max_tms; ++k) {
    const TileRect r =
        footprint_tiles(offer.set.tiling, *pyramid, level_from_tms(offer.set.tiling, k), b);
    if (r.count() == 0) continue;
    out.push_back({k, r.y0, r.y1 - 1, r.x0, r.x1 - 1});
  }
  return out;
}

bool offer_has_tile(const Offer& offer, int tms, std::uint64_t row, std::uint64_t col) {
  if (tms < offer.min_tms || tms > offer.max_tms) return false;
  const TileMatrix m = tile_matrices(offer.set, tms).back();
  return row < m.matrix_height && col < m.matrix_width;
}

HttpResponse offer_tile(const HttpRequest& request, std::shared_ptr<const Tileset> t,
                        const Offer& offer, int tms, std::uint32_t row, std::uint32_t col,
                        imaging::WebFormat format, const RouterConfig& config) {
  // The web routes read z/x/y as the validated decimals of a path.
  const std::string z = std::to_string(level_from_tms(offer.set.tiling, tms));
  const std::string x = std::to_string(col), y = std::to_string(row);
  const std::string_view zxy[] = {z, x, y};
  if (offer.reprojected) return web_mercator_tile_route(request, t, "", zxy, format, config, false);
  return web_tile_route(request, std::move(t), "", zxy, format, config, false);
}

std::optional<imaging::WebFormat> format_from_media_type(std::string_view type) {
  if (type == "image/png") return imaging::WebFormat::png;
  if (type == "image/webp") return imaging::WebFormat::webp;
  if (type == "image/jpeg" || type == "image/jpg") return imaging::WebFormat::jpeg;
  return std::nullopt;
}

std::optional<imaging::WebFormat> format_from_extension(std::string_view ext) {
  if (ext == "png") return imaging::WebFormat::png;
  if (ext == "webp") return imaging::WebFormat::webp;
  if (ext == "jpg" || ext == "jpeg") return imaging::WebFormat::jpeg;
  return std::nullopt;
}

std::string number_text(double v) {
  char buf[32];
  const auto end = std::to_chars(buf, buf + sizeof buf, v).ptr;
  return std::string(buf, end);
}

}  // namespace router_detail
}  // namespace server
}  // namespace vts
