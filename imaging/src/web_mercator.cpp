#include "vts/imaging/web_mercator.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <deque>
#include <string>
#include <utility>
#include <vector>

#include "vts/base/srgb.hpp"

namespace vts::imaging {
namespace {

// One axis of the bilinear footprint of an output texel: the source texels (level coordinates)
// on either side of its centre and their weights. Longitude wraps (the level spans 360 degrees);
// latitude clamps to the edge row: a centre between the last row's centre and the pole is still
// inside the image.
struct Taps {
  std::array<std::int64_t, 2> at{0, 0};
  std::array<float, 2> weight{0, 0};
};

// u is the output texel centre in source texel-centre coordinates (texel k's centre at k).
Taps axis_taps(double u, std::int64_t size, bool wrap) {
  // A centre within 1e-9 texel of a source centre (z <= max_zoom in longitude: the texels are
  // aligned) is that centre, so rounding cannot give a neighbour a 1e-15 weight and a fetch.
  if (std::abs(u - std::round(u)) < 1e-9) u = std::round(u);
  const double f = std::floor(u);
  const double frac = u - f;
  Taps t;
  t.weight = {static_cast<float>(1.0 - frac), static_cast<float>(frac)};
  for (int k = 0; k < 2; ++k) {
    const std::int64_t c = static_cast<std::int64_t>(f) + k;
    t.at[k] = wrap ? ((c % size) + size) % size : std::clamp<std::int64_t>(c, 0, size - 1);
  }
  return t;
}

// Source tiles, each fetched at most once; nullopt entries are absent tiles.
class TileCache {
 public:
  TileCache(const Geometry& g, int level, const FetchStoredTile& fetch)
      : g_(g), level_(level), fetch_(fetch) {}

  Result<const TileImage*> get(std::uint32_t tx, std::uint32_t ty) {
    const TileId id{static_cast<std::uint8_t>(level_), tx, ty};
    for (const auto& [key, image] : tiles_)
      if (key == id) return image ? &*image : nullptr;
    auto fetched = fetch_(id);
    if (!fetched) return std::move(fetched).error();
    const std::uint32_t s = g_.stored_size();
    if (*fetched &&
        ((*fetched)->format != PixelFormat::rgba8 || (*fetched)->width != s ||
         (*fetched)->height != s || (*fetched)->pixels.size() != std::size_t{s} * s * 4))
      return make_error(ErrorCode::corrupt, "source tile " + id.to_string() +
                                                " is not rgba8 of the stored size " +
                                                std::to_string(s) + "x" + std::to_string(s));
    tiles_.emplace_back(id, std::move(*fetched));
    const auto& image = tiles_.back().second;
    return image ? &*image : nullptr;
  }

 private:
  const Geometry& g_;
  int level_;
  const FetchStoredTile& fetch_;
  // A deque: get() hands out pointers that must survive later insertions.
  std::deque<std::pair<TileId, std::optional<TileImage>>> tiles_;
};

// Premultiplied accumulation of weighted texels.
struct Accum {
  float rgb[3] = {0, 0, 0};
  float alpha = 0;
  void add(const std::uint8_t* texel, float w, bool linear) {
    const float a = w * (texel[3] / 255.0f);
    const Srgb8Tables& srgb = srgb8_tables();
    for (int k = 0; k < 3; ++k) rgb[k] += a * (linear ? srgb.decode(texel[k]) : texel[k] / 255.0f);
    alpha += a;
  }
  void store(std::uint8_t* out, bool linear) const {
    if (!(alpha > 0)) {
      out[0] = out[1] = out[2] = out[3] = 0;
      return;
    }
    const Srgb8Tables& srgb = srgb8_tables();
    for (int k = 0; k < 3; ++k) {
      const float c = rgb[k] / alpha;
      out[k] = linear ? srgb.encode(c)
                      : static_cast<std::uint8_t>(std::clamp(std::lround(c * 255.0f), 0L, 255L));
    }
    out[3] = static_cast<std::uint8_t>(std::clamp(std::lround(alpha * 255.0f), 0L, 255L));
  }
};

// Blends the (up to) four source texels of one output texel. The top-left one's tile (the
// "primary") serves every texel its stored area holds without crossing the antimeridian; the
// others come from their own tiles. An absent tile's texels are transparent.
Status blend(TileCache& cache, const Geometry& g, const Taps& cols, const Taps& rows, bool linear,
             std::uint8_t* out) {
  const std::int64_t T = g.tile_size(), B = g.border(), S = g.stored_size();
  const std::int64_t px = cols.at[0] / T, py = rows.at[0] / T;
  auto primary = cache.get(static_cast<std::uint32_t>(px), static_cast<std::uint32_t>(py));
  if (!primary) return primary.error();
  Accum acc;
  for (int j = 0; j < 2; ++j) {
    for (int i = 0; i < 2; ++i) {
      const float w = cols.weight[i] * rows.weight[j];
      if (w == 0) continue;
      const std::int64_t c = cols.at[i], r = rows.at[j];
      std::int64_t sx = c - px * T + B, sy = r - py * T + B;
      const TileImage* tile = *primary;
      if (!(tile && sx >= 0 && sx < S && sy >= 0 && sy < S)) {
        auto owner =
            cache.get(static_cast<std::uint32_t>(c / T), static_cast<std::uint32_t>(r / T));
        if (!owner) return owner.error();
        tile = *owner;
        sx = c % T + B, sy = r % T + B;
      }
      if (!tile) continue;  // absent: transparent, its weight kept
      acc.add(&tile->pixels[static_cast<std::size_t>((sy * S + sx) * 4)], w, linear);
    }
  }
  acc.store(out, linear);
  return {};
}

bool overlaps(const LonLatBounds& a, const LonLatBounds& b) {
  return a.west < b.east && a.east > b.west && a.south < b.north && a.north > b.south;
}

Status check_crs84(const TilesetInfo& info) {
  if (!info.georeference || info.georeference->tiling != Tiling::world_crs84_quad)
    return make_error(ErrorCode::invalid_argument,
                      "Web Mercator tiles are made from a WorldCRS84Quad tileset, not " +
                          std::string(info.georeference ? tiling_name(info.georeference->tiling)
                                                        : "a tileset without a georeference"));
  return {};
}

}  // namespace

int web_mercator_source_level(const Geometry& g, int z) noexcept {
  return std::clamp(z, 0, g.max_zoom());
}

Result<std::optional<TileImage>> render_web_mercator_tile(const TilesetInfo& info, int z,
                                                          std::uint32_t x, std::uint32_t y,
                                                          const FetchStoredTile& fetch) {
  return render_web_mercator_tile(info, z, x, y, fetch, WebMercatorOptions{});
}

Result<std::optional<TileImage>> render_web_mercator_tile(const TilesetInfo& info, int z,
                                                          std::uint32_t x, std::uint32_t y,
                                                          const FetchStoredTile& fetch,
                                                          const WebMercatorOptions& options) {
  if (Status s = check_crs84(info); !s) return s.error();
  if (z < 0 || z > Geometry::kMaxZoom)
    return make_error(ErrorCode::invalid_argument, "WebMercatorQuad zoom " + std::to_string(z) +
                                                       " is not within 0.." +
                                                       std::to_string(Geometry::kMaxZoom));
  const std::uint64_t n = std::uint64_t{1} << z;
  if (x >= n || y >= n)
    return make_error(ErrorCode::invalid_argument,
                      "WebMercatorQuad tile " + std::to_string(z) + "/" + std::to_string(x) + "/" +
                          std::to_string(y) + " is outside level " + std::to_string(z) + " (0.." +
                          std::to_string(n - 1) + ")");
  const Geometry& g = info.geometry;
  const std::uint32_t T = g.tile_size();
  const TileId out_id{static_cast<std::uint8_t>(z), x, y};
  if (!overlaps(tile_bounds_degrees(Tiling::web_mercator_quad, T, out_id),
                info.georeference->bounds))
    return std::optional<TileImage>{};

  // The mapping is separable: longitude depends on the column only, latitude on the row only.
  const int level = web_mercator_source_level(g, z);
  const auto W = static_cast<std::int64_t>(g.level_width(level));
  const auto H = static_cast<std::int64_t>(g.level_height(level));
  std::vector<Taps> cols(T), rows(T);
  for (std::uint32_t k = 0; k < T; ++k) {
    const double centre = k + 0.5;
    const LonLat p = texel_to_lonlat(Tiling::web_mercator_quad, T, z,
                                     {double(x) * T + centre, double(y) * T + centre});
    const TexelPoint s = lonlat_to_texel(Tiling::world_crs84_quad, T, level, p);
    cols[k] = axis_taps(s.x - 0.5, W, true);
    rows[k] = axis_taps(s.y - 0.5, H, false);
  }
  TileCache cache(g, level, fetch);
  TileImage out{T, T, PixelFormat::rgba8, std::vector<std::uint8_t>(std::size_t{T} * T * 4)};
  for (std::uint32_t j = 0; j < T; ++j) {
    for (std::uint32_t i = 0; i < T; ++i) {
      std::uint8_t* texel = &out.pixels[(std::size_t{j} * T + i) * 4];
      if (Status s = blend(cache, g, cols[i], rows[j], options.linear_light, texel); !s)
        return s.error();
    }
  }
  return std::optional<TileImage>(std::move(out));
}

Result<WebMercatorRange> web_mercator_range(const TilesetInfo& info) {
  if (Status s = check_crs84(info); !s) return s.error();
  LonLatBounds b = info.georeference->bounds;
  b.south = std::max(b.south, -kWebMercatorMaxLat);
  b.north = std::min(b.north, kWebMercatorMaxLat);
  if (!(b.south < b.north))
    return make_error(ErrorCode::invalid_argument,
                      "the footprint (latitudes " +
                          std::to_string(info.georeference->bounds.south) + ".." +
                          std::to_string(info.georeference->bounds.north) +
                          ") lies wholly beyond Web Mercator's +-85.0511 degrees");
  return WebMercatorRange{0, info.geometry.max_zoom(), b};
}

}  // namespace vts::imaging
