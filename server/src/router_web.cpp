// Web images of tiles (docs/PROTOCOL.md §12): /{ts}[@{version}]/{z}/{x}/{y}.png|.webp|.jpg and the
// TileJSON that points stock web maps at them. A cached image answers at once; otherwise the
// route's answer is the plan to make it (what to encode from the stored tile: decode, crop the
// border, encode), which the answer pipeline (answer_pipeline.cpp) carries out on the shared
// encode pool, once per key however many requests want it at the same time.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <nlohmann/json.hpp>

#include "router_internal.hpp"
#include "tile_tag_memo.hpp"
#include "vts/imaging/web_mercator.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/protocol/tilejson.hpp"
#include "vts/protocol/tiling.hpp"
#include "web_tile_cache.hpp"

namespace vts {
inline namespace server {
namespace router_detail {
namespace {

using http_detail::WebTile;
using http_detail::WebTileCache;
using http_detail::WebTilePtr;

// What the encoding options change in the bytes of `f`: part of the ETag and the cache key, so
// a server restarted with other options never answers a stale client copy with 304.
std::string options_tag(imaging::WebFormat f, const imaging::WebEncodeOptions& o) {
  switch (f) {
    case imaging::WebFormat::png:  // level and row filter: "png4a" is level 4, average
      return "png" + std::to_string(o.png_level) + "nsuapx"[static_cast<int>(o.png_filter)];
    case imaging::WebFormat::webp:
      return o.webp_lossless
                 ? "webpll" + std::to_string(o.webp_method)
                 : "webp" + std::to_string(o.webp_quality) + "m" + std::to_string(o.webp_method);
    case imaging::WebFormat::jpeg:
      return "jpg" + std::to_string(o.jpeg_quality);
  }
  return "";
}

std::string hex16(std::uint64_t v) {
  std::string s(16, '0');
  for (int i = 0; i < 16; ++i) s[std::size_t(i)] = "0123456789abcdef"[(v >> (60 - 4 * i)) & 0xf];
  return s;
}

}  // namespace

HttpResponse web_image_response(const WebTilePtr& tile, std::string_view if_none_match,
                                const std::string& cc) {
  HttpResponse r;
  r.route = Route::tile;
  add(r, "ETag", tile->etag);
  add(r, "Cache-Control", cc);
  if (none_match(if_none_match, tile->etag)) {
    r.status = 304;
    return r;
  }
  add(r, "Content-Type", tile->content_type);
  r.view = tile->bytes;
  r.content_length = r.view.size();
  r.keep = tile;
  return r;
}

namespace {

using Encoder = std::function<Result<std::vector<std::uint8_t>>()>;

// The image under `key`: from the cache when it holds it, else the plan to make it (a pending
// answer the pipeline carries out: the cache again, single flight, the encode pool).
HttpResponse encoded(const RouterConfig& config, std::string key, std::string etag,
                     const char* type, Encoder encode, std::string_view if_none_match,
                     const std::string& cc, std::uint64_t owner) {
  if (config.web.cache) {
    if (WebTilePtr hit = config.web.cache->peek(key))
      return web_image_response(hit, if_none_match, cc);
  }
  auto p = std::make_shared<PendingAnswer>();
  p->image = WebImageJob{std::move(key), std::move(etag), type, std::move(encode)};
  p->cache = config.web.cache;
  p->if_none_match = std::string(if_none_match);
  p->cache_control = cc;
  p->connection = owner;
  HttpResponse r;
  r.route = Route::tile;
  r.pending = std::move(p);
  return r;
}

// A tile with nothing to show (beyond the image's edge, or absent from a sparse archive): a
// fully transparent T x T image, 200, cacheable like a tile. For .jpg (no alpha in JPEG) it is a
// PNG, with Content-Type image/png: browsers decode images by their bytes, and a black square
// would hide what lies under the layer.
HttpResponse empty_tile(const Tileset& t, imaging::WebFormat f, const RouterConfig& config,
                        const HttpRequest& request, const std::string& cc) {
  return web_filler(t.info.geometry.tile_size(), f, config, request.if_none_match, cc,
                    request.connection);
}

}  // namespace

HttpResponse web_filler(std::uint32_t size, imaging::WebFormat f, const RouterConfig& config,
                        std::string_view if_none_match, const std::string& cc,
                        std::uint64_t owner) {
  const std::string tag = options_tag(f, config.web.encode);
  const imaging::WebFormat as = f == imaging::WebFormat::jpeg ? imaging::WebFormat::png : f;
  Encoder encode = [size, as, options = config.web.encode] {
    const TileImage clear{size, size, PixelFormat::rgba8,
                          std::vector<std::uint8_t>(std::size_t(size) * size * 4, 0)};
    return imaging::encode_web_image(clear, as, options);
  };
  const std::string key = "empty/" + std::to_string(size) + "/" + tag;
  return encoded(config, key, "\"empty-" + std::to_string(size) + "-" + tag + "\"",
                 imaging::web_format_content_type(as).data(), std::move(encode), if_none_match, cc,
                 owner);
}

std::optional<TileId> web_tile_id(std::span<const std::string_view> zxy, const Geometry& g,
                                  const std::string& name, std::optional<HttpResponse>& rejection) {
  const std::uint32_t z = *parse_u32(zxy[0]), x = *parse_u32(zxy[1]), y = *parse_u32(zxy[2]);
  if (z > static_cast<std::uint32_t>(g.max_zoom())) {
    rejection = outside_pyramid(z, x, y, name);
    return std::nullopt;
  }
  const TileId id{static_cast<std::uint8_t>(z), x, y};
  const std::uint32_t side = std::uint32_t(1) << z;
  if (x >= std::max(side, g.tiles_x(id.z)) || y >= std::max(side, g.tiles_y(id.z))) {
    rejection = outside_pyramid(z, x, y, name);
    return std::nullopt;
  }
  return id;
}

HttpResponse web_tile_route(const HttpRequest& request, std::shared_ptr<const Tileset> t,
                            std::string_view version, std::span<const std::string_view> zxy,
                            imaging::WebFormat format, const RouterConfig& config, bool priv) {
  if (!version.empty() && version != t->version) return not_current(version, t->name, t->version);
  const Geometry& g = t->info.geometry;
  std::optional<HttpResponse> rejection;
  const auto tile = web_tile_id(zxy, g, t->name, rejection);
  if (!tile) return std::move(*rejection);
  const TileId id = *tile;
  if (config.web.cache) {
    config.web.cache->requests_by_format[static_cast<std::size_t>(format)].fetch_add(
        1, std::memory_order_relaxed);
  }
  const std::string cc = version.empty() ? cache_control(priv, config.max_age_seconds, false)
                                         : cache_control(priv, kImmutableMaxAge, true);
  auto finish = [&t](HttpResponse r) {
    r.hold = t;  // names the tileset in access logs
    return r;
  };
  if (!g.exists(id)) return finish(empty_tile(*t, format, config, request, cc));

  const std::string tag = options_tag(format, config.web.encode);
  auto etag_of = [&tag](std::uint64_t checksum) {
    return "\"" + hex16(checksum) + "-" + tag + "\"";
  };
  const std::uint64_t tile_id = archive::zxy_to_tile_id(id.z, id.x, id.y);
  const std::string key = t->name + "@" + t->version + "/" + std::to_string(tile_id) + "/" + tag;
  if (config.web.cache) {
    // A cached image answers without reading the archive (its key names the archive's version).
    if (auto hit = config.web.cache->peek(key)) {
      return finish(web_image_response(hit, request.if_none_match, cc));
    }
  }
  http_detail::TileTagMemo* memo = t->tags.get();
  if (!request.if_none_match.empty() && memo) {
    // A tag read before from this file answers without touching it.
    if (auto known = memo->find(tile_id);
        known && none_match(request.if_none_match, etag_of(*known))) {
      HttpResponse r;
      r.status = 304;
      r.route = Route::tile;
      add(r, "ETag", etag_of(*known));
      add(r, "Cache-Control", cc);
      return finish(std::move(r));
    }
  }
  // What the stored tile gives: the image to encode, or the status its error means. Built here,
  // run now for a local archive, or by the answer pipeline once a store has answered.
  RouterConfig web_config;  // only the web settings: the closure may outlive this call
  web_config.web = config.web;
  auto answer = [t, id, format, key, etag_of, web_config, inm = std::string(request.if_none_match),
                 cc, owner = request.connection,
                 tile_id](Result<std::vector<std::uint8_t>> payload) -> HttpResponse {
    auto held = [&t](HttpResponse r) {
      r.hold = t;  // names the tileset in access logs
      return r;
    };
    if (!payload) {
      const Error& e = payload.error();
      if (e.code == ErrorCode::changed) {
        HttpResponse r = archive_changed(t, e);
        r.route = Route::tile;
        return r;
      }
      if (e.code == ErrorCode::unavailable) {  // an object store that did not answer: retry
        HttpResponse r =
            tile_error(503, "the store holding tileset " + t->name +
                                " did not answer; try again shortly (" + e.message + ")");
        add(r, "Retry-After", "1");
        return r;
      }
      if (http_status(e.code) == 404 && t->info.sparse) {
        return held(web_filler(t->info.geometry.tile_size(), format, web_config, inm, cc, owner));
      }
      if (http_status(e.code) == 404) {
        return tile_error(404, "tile " + id.to_string() + " is missing from the archive of " +
                                   t->name + " (archive incomplete)");
      }
      return tile_error(http_status(e.code),
                        "archive of " + t->name + " is damaged: " + e.to_string());
    }
    auto header = parse_tile_header(*payload);
    if (!header) {
      return tile_error(500, "tile " + id.to_string() + " of " + t->name +
                                 " is damaged: " + header.error().to_string());
    }
    if (http_detail::TileTagMemo* tags = t->tags.get()) tags->remember(tile_id, header->checksum);
    Encoder encode = [stored_payload =
                          std::make_shared<const std::vector<std::uint8_t>>(std::move(*payload)),
                      tileset = t, id, format,
                      options = web_config.web.encode]() -> Result<std::vector<std::uint8_t>> {
      auto stored = decode_tile(*stored_payload);
      if (!stored) return stored.error();
      auto content = imaging::tile_content(*stored, tileset->info.geometry, id);
      if (!content) return content.error();
      return imaging::encode_web_image(*content, format, options);
    };
    return held(encoded(web_config, key, etag_of(header->checksum),
                        imaging::web_format_content_type(format).data(), std::move(encode), inm, cc,
                        owner));
  };
  if (t->remote) return finish(stored_read_plan(t, id, request, cc, std::move(answer)));
  return answer(t->reader->get(id));
}

HttpResponse web_mercator_tile_route(const HttpRequest& request, std::shared_ptr<const Tileset> t,
                                     std::string_view version,
                                     std::span<const std::string_view> zxy,
                                     imaging::WebFormat format, const RouterConfig& config,
                                     bool priv) {
  if (!version.empty() && version != t->version) return not_current(version, t->name, t->version);
  const std::uint32_t z = *parse_u32(zxy[0]), x = *parse_u32(zxy[1]), y = *parse_u32(zxy[2]);
  auto range = imaging::web_mercator_range(t->info);
  if (!range) {
    return tile_error(404, "tileset \"" + t->name + "\" has no WebMercatorQuad tiles (" +
                               range.error().message + "); use /" + t->name + "/{z}/{x}/{y}." +
                               std::string(imaging::web_format_extension(format)));
  }
  if (z > std::uint32_t(range->max_zoom) || x >= (std::uint32_t(1) << z) ||
      y >= (std::uint32_t(1) << z)) {
    return tile_error(404, "WebMercatorQuad tile " + std::to_string(z) + "/" + std::to_string(x) +
                               "/" + std::to_string(y) + " is outside the pyramid of " + t->name);
  }
  if (config.web.cache) {
    config.web.cache->requests_by_format[static_cast<std::size_t>(format)].fetch_add(
        1, std::memory_order_relaxed);
  }
  const std::string cc = version.empty() ? cache_control(priv, config.max_age_seconds, false)
                                         : cache_control(priv, kImmutableMaxAge, true);
  // Wholly outside the footprint: the transparent filler, without reading the archive.
  const double n = std::ldexp(1.0, int(z)), pi = std::acos(-1.0);
  auto lat = [&](double row) {
    return std::atan(std::sinh(pi * (1.0 - 2.0 * row / n))) * 180 / pi;
  };
  const LonLatBounds& b = range->bounds;
  if (x / n * 360 - 180 >= b.east || (x + 1) / n * 360 - 180 <= b.west || lat(y) <= b.south ||
      lat(y + 1.0) >= b.north) {
    HttpResponse r = empty_tile(*t, format, config, request, cc);
    r.hold = std::move(t);
    return r;
  }
  // The tile is a function of the archive's content (its version) and of z/x/y and the options.
  const std::string tag = options_tag(format, config.web.encode);
  const std::string zxy_text =
      std::to_string(z) + "-" + std::to_string(x) + "-" + std::to_string(y);
  const std::string etag = "\"" + t->version + "-wmq-" + zxy_text + "-" + tag + "\"";
  HttpResponse r;
  if (none_match(request.if_none_match, etag)) {
    r.status = 304;
    r.route = Route::tile;
    add(r, "ETag", etag);
    add(r, "Cache-Control", cc);
  } else {
    Encoder encode = [tileset = t, z, x, y, format,
                      options = config.web.encode]() -> Result<std::vector<std::uint8_t>> {
      const imaging::FetchStoredTile fetch =
          [&tileset](TileId id) -> Result<std::optional<TileImage>> {
        auto payload = tileset->reader->get(id);
        if (!payload) {
          if (http_status(payload.error().code) == 404) return std::optional<TileImage>();
          return payload.error();
        }
        auto stored = decode_tile(*payload);
        if (!stored) return stored.error();
        if (stored->format == PixelFormat::bc1) {
          auto rgba = bc1_to_rgba8(*stored);
          if (!rgba) return rgba.error();
          return std::optional<TileImage>(std::move(*rgba));
        }
        return std::optional<TileImage>(std::move(*stored));
      };
      auto tile = imaging::render_web_mercator_tile(tileset->info, int(z), x, y, fetch);
      if (!tile) return tile.error();
      if (!*tile) {  // only an edge shared with the footprint: nothing to draw
        const std::uint32_t s = tileset->info.geometry.tile_size();
        *tile =
            TileImage{s, s, PixelFormat::rgba8, std::vector<std::uint8_t>(std::size_t(s) * s * 4)};
      }
      return imaging::encode_web_image(**tile, format, options);
    };
    r = encoded(config, t->name + "@" + t->version + "/wmq/" + zxy_text + "/" + tag, etag,
                imaging::web_format_content_type(format).data(), std::move(encode),
                request.if_none_match, cc, request.connection);
  }
  r.hold = std::move(t);
  return r;
}

HttpResponse provided_web_image(const PendingAnswer& d, const std::vector<std::uint8_t>* payload) {
  RouterConfig config;  // the parts encoded() reads
  config.web.encode = d.web_options;
  config.web.cache = d.cache;
  const std::string& name = d.provided->name;
  if (payload == nullptr) {
    return web_filler(d.provided->info.geometry.tile_size(), *d.web, config, d.if_none_match,
                      d.cache_control, d.connection);
  }
  auto header = parse_tile_header(*payload);
  if (!header) {
    return tile_error(502, "tile " + d.id.to_string() + " of " + name +
                               " is damaged: " + header.error().to_string());
  }
  const std::string tag = options_tag(*d.web, d.web_options);
  const std::string etag = "\"" + hex16(header->checksum) + "-" + tag + "\"";
  if (none_match(d.if_none_match, etag)) {
    HttpResponse r;
    r.status = 304;
    r.route = Route::tile;
    add(r, "ETag", etag);
    add(r, "Cache-Control", d.cache_control);
    return r;
  }
  // Keyed by content (the checksum) and tile: a provided tileset's version may be unknown.
  const std::string key =
      "provided/" + name + "/" + d.id.to_string() + "/" + hex16(header->checksum) + "/" + tag;
  Encoder encode = [stored_payload = std::make_shared<const std::vector<std::uint8_t>>(*payload),
                    tileset = d.provided, id = d.id, format = *d.web,
                    options = d.web_options]() -> Result<std::vector<std::uint8_t>> {
    auto stored = decode_tile(*stored_payload);
    if (!stored) return stored.error();
    auto content = imaging::tile_content(*stored, tileset->info.geometry, id);
    if (!content) return content.error();
    return imaging::encode_web_image(*content, format, options);
  };
  return encoded(config, key, etag, imaging::web_format_content_type(*d.web).data(),
                 std::move(encode), d.if_none_match, d.cache_control, d.connection);
}

namespace {

// The TileJSON of a WorldCRS84Quad tileset served as WebMercatorQuad (web_mercator_tile_route).
HttpResponse web_mercator_tilejson(const std::string& name, const TilesetInfo& info,
                                   const std::string& version, bool versioned,
                                   imaging::WebFormat format, const std::string& base, bool priv) {
  auto range = imaging::web_mercator_range(info);
  if (!range) {
    HttpResponse r = error(400, "tileset \"" + name + "\": " + range.error().message);
    r.route = Route::tilejson;
    return r;
  }
  const std::string tiles = base + "/" + name + (versioned ? "@" + version : std::string()) +
                            "/WebMercatorQuad/{z}/{x}/{y}." +
                            std::string(imaging::web_format_extension(format));
  auto j = nlohmann::ordered_json::parse(
      write_tilejson({.tileset = name, .info = &info, .version = version, .tiles_url = tiles}));
  j.erase("vtstream");
  const LonLatBounds& b = range->bounds;
  j["tileSize"] = info.geometry.tile_size();
  j["tileMatrixSet"] = tiling_name(Tiling::web_mercator_quad);
  j["crs"] = tiling_crs(Tiling::web_mercator_quad);
  j["minzoom"] = range->min_zoom;
  j["maxzoom"] = range->max_zoom;
  j["bounds"] = {b.west, b.south, b.east, b.north};
  const auto& c = info.georeference->center;
  j["center"] = {std::clamp(c.lon, b.west, b.east), std::clamp(c.lat, b.south, b.north),
                 std::min(c.level, range->max_zoom)};
  HttpResponse r;
  r.route = Route::tilejson;
  set_owned(r, j.dump(2) + "\n", "application/json");
  add(r, "Cache-Control", cache_control(priv, 60, false));
  return r;
}

}  // namespace

HttpResponse web_tilejson_route(const std::string& name, const TilesetInfo& info,
                                const std::string& version, bool versioned, const Query& q,
                                const std::string& base, bool priv, bool can_reproject) {
  auto fail = [](std::string why) {
    HttpResponse r = error(400, std::move(why));
    r.route = Route::tilejson;
    return r;
  };
  auto format = imaging::parse_web_format(*q.format);
  if (!format) return fail("format: " + format.error().message);
  const Tiling native = info.georeference ? info.georeference->tiling : Tiling::none;
  // Web maps draw every XYZ layer as Web Mercator: a WorldCRS84Quad tileset is offered on that
  // grid unless its own grid is asked for by name (a map in EPSG:4326, a GIS).
  Tiling grid = native == Tiling::world_crs84_quad ? Tiling::web_mercator_quad : native;
  if (q.tiling) {
    auto tiling = parse_tiling(*q.tiling);
    if (!tiling || *tiling == Tiling::none) {
      return fail("tiling \"" + std::string(*q.tiling) +
                  "\": web tiles are offered in WebMercatorQuad or, for a WorldCRS84Quad "
                  "tileset, WorldCRS84Quad (its own grid)");
    }
    if (native == Tiling::none) {
      return fail("tileset \"" + name + "\" is a plain image (no georeference): it has no " +
                  std::string(tiling_name(*tiling)) + " tiles; leave tiling= out");
    }
    if (*tiling == Tiling::world_crs84_quad && native != Tiling::world_crs84_quad) {
      return fail("tileset \"" + name + "\" is " + std::string(tiling_name(native)) +
                  ": it has no WorldCRS84Quad tiles");
    }
    grid = *tiling;
  }
  if (grid != native) {
    if (!can_reproject) {
      return fail("tileset \"" + name +
                  "\" is WorldCRS84Quad and served from a cache: its WebMercatorQuad tiles are "
                  "served by vts serve only; tiling=WorldCRS84Quad gives its own grid, for a map "
                  "in EPSG:4326");
    }
    return web_mercator_tilejson(name, info, version, versioned, *format, base, priv);
  }
  const std::string ext(imaging::web_format_extension(*format));
  const std::string tiles =
      base + "/" + name + (versioned ? "@" + version : std::string()) + "/{z}/{x}/{y}." + ext;
  auto j = nlohmann::ordered_json::parse(
      write_tilejson({.tileset = name, .info = &info, .version = version, .tiles_url = tiles}));
  j.erase("vtstream");  // the tiles are images, not our codec: native clients must not read it
  const Geometry& g = info.geometry;
  j["tileSize"] = g.tile_size();
  if (native != Tiling::none) {
    // TileJSON has no word for a grid: these say which one the {z}/{x}/{y} are on.
    j["tileMatrixSet"] = tiling_name(native);
    j["crs"] = tiling_crs(native);
  }
  if (!info.georeference) {
    // Pixel space placed as if Web Mercator: level max_zoom's pixels are the world's at that
    // zoom, from the top-left (north-west) corner.
    const double world = double(g.tile_size()) * std::ldexp(1.0, g.max_zoom());
    const double fx = std::min(1.0, double(g.width()) / world);
    const double fy = std::min(1.0, double(g.height()) / world);
    const double pi = std::acos(-1.0);
    const double east = -180.0 + 360.0 * fx;
    const double south = std::atan(std::sinh(pi * (1.0 - 2.0 * fy))) * 180.0 / pi;
    const double north = 85.0511287798066;
    j["bounds"] = {-180.0, south, east, north};
    j["center"] = {(east - 180.0) / 2.0, std::atan(std::sinh(pi * (1.0 - fy))) * 180.0 / pi, 0};
  }
  HttpResponse r;
  r.route = Route::tilejson;
  set_owned(r, j.dump(2) + "\n", "application/json");
  add(r, "Cache-Control", cache_control(priv, 60, false));
  return r;
}

}  // namespace router_detail
}  // namespace server
}  // namespace vts
