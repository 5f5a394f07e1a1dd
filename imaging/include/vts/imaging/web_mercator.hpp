// WebMercatorQuad tiles resampled on the fly from a WorldCRS84Quad pyramid, so one archive built
// for the globe also serves every web map (docs/FORMAT.md §6 "Reprojection to WebMercatorQuad";
// agreement with gdalwarp in docs/ACCURACY.md §7). Every function is pure and thread-safe; the
// fetch callback is called on the caller's thread.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>

#include "vts/base/result.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/protocol/tileset.hpp"
#include "vts/protocol/tiling.hpp"

namespace vts::imaging {

// Decoded stored texels of tile `id` of the source pyramid: rgba8, stored_size() x stored_size()
// (border included), sRGB, straight alpha; std::nullopt when the archive holds no such tile
// (sparse archive, outside the footprint). Errors pass through.
using FetchStoredTile = std::function<Result<std::optional<TileImage>>(TileId id)>;

// The source level for WebMercatorQuad zoom z: min(z, max_zoom). The output's coarser axis is
// longitude everywhere (a Web Mercator texel spans 360 / (2^z T) degrees of longitude and cos(lat)
// times that of latitude), and our CRS84 level L has 2^L T texels over 360 degrees, so longitude
// matches exactly at L = z: a finer level would alias, a coarser one would blur. Beyond max_zoom
// the finest level is magnified. z must be >= 0.
int web_mercator_source_level(const Geometry& g, int z) noexcept;

// How source texels are blended (docs/ACCURACY.md §7 measures both against gdalwarp).
struct WebMercatorOptions {
  // true: bilinear weights applied to linear-light colour (sRGB decoded, premultiplied by alpha,
  // re-encoded), as the GL globe's sRGB textures filter. false: applied to the sRGB codes, as
  // gdalwarp does.
  bool linear_light = true;
};

// WebMercatorQuad tile (z, x, y): T x T rgba8 texels (T = the source geometry's tile_size()),
// sRGB, straight alpha, resampled from a pyramid whose info.georeference->tiling is
// world_crs84_quad, at level web_mercator_source_level(z).
//
// Each output texel centre is mapped to degrees and onto the source level; its value is the
// bilinear blend of the four source texels whose centres surround it. A source texel is read from
// the stored texels (border included) of the tile holding the top-left of the four when they
// reach it, else from the tile whose content holds it. Longitude wraps at the antimeridian (the
// level spans exactly 360 degrees) and latitude clamps to the polar rows (a centre between the
// last row's centre and the pole is still inside the image), so no texel falls outside the
// level. A texel whose tile is absent is transparent (alpha 0): it keeps its weight, so it lowers
// the alpha and not the colour. Zero weights are skipped, so an output tile at z <= max_zoom
// reads one source tile column.
//
// std::nullopt when the tile lies wholly outside info.georeference->bounds (sharing only an
// edge counts as outside): nothing to draw. invalid_argument for a tileset that is not
// WorldCRS84Quad, z outside 0..Geometry::kMaxZoom, or x or y >= 2^z. corrupt, naming the tile,
// when fetch returns an image that is not rgba8 of the stored size. Calls fetch at most once per
// source tile per call, and not for tiles whose texels all have zero weight.
Result<std::optional<TileImage>> render_web_mercator_tile(const TilesetInfo& info, int z,
                                                          std::uint32_t x, std::uint32_t y,
                                                          const FetchStoredTile& fetch);
Result<std::optional<TileImage>> render_web_mercator_tile(const TilesetInfo& info, int z,
                                                          std::uint32_t x, std::uint32_t y,
                                                          const FetchStoredTile& fetch,
                                                          const WebMercatorOptions& options);

// What a CRS84 tileset serves as WebMercatorQuad.
struct WebMercatorRange {
  // 0..info.geometry.max_zoom(): at max_zoom the output's longitude resolution is the finest
  // level's; a deeper zoom would only magnify it (web maps overzoom their last level themselves).
  int min_zoom = 0;
  int max_zoom = 0;
  // The footprint with its latitudes clipped to +-kWebMercatorMaxLat.
  LonLatBounds bounds;
  bool operator==(const WebMercatorRange&) const = default;
};
// invalid_argument for a tileset that is not WorldCRS84Quad, or whose footprint lies wholly
// beyond +-kWebMercatorMaxLat (nothing of it shows on Web Mercator).
Result<WebMercatorRange> web_mercator_range(const TilesetInfo& info);

}  // namespace vts::imaging
