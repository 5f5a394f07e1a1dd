// Pieces of the router shared by its source files (router*.cpp). Pure: no I/O.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "vts/server/router.hpp"

namespace vts {
inline namespace server {
namespace http_detail {
class NativeTileCache;  // native_tile_cache.hpp
}
namespace router_detail {

inline constexpr const char* kAllowedMethods = "GET, HEAD, OPTIONS";
inline constexpr const char* kTextType = "text/plain; charset=utf-8";

// Appends a header; `name` must be a string literal (HttpResponse::headers keeps a view).
void add(HttpResponse& r, std::string_view name, std::string value);
// Sets an owned body and its Content-Type.
void set_owned(HttpResponse& r, std::string body, const char* type);
// A text/plain error (message plus '\n'), Cache-Control: no-store, route `error`.
HttpResponse error(int status, std::string message);
// "public|private, max-age=N[, immutable]".
std::string cache_control(bool is_private, std::uint32_t max_age, bool immutable);
inline constexpr std::uint32_t kImmutableMaxAge = 31536000;  // of versioned tile URLs

// Tile answers shared by the native and the web tile routes (router.cpp).
HttpResponse tile_error(int status, std::string message);
// The answer to a request for tile `id` of the archive tileset `t` from its stored payload (or
// the error reading it): 200 with the payload, 304 when `if_none_match` names its tag, 204/404/
// 500/503 as the error says. What route() answers for a local archive, and the answer pipeline
// for one in an object store. With `cache` (a local archive's), the tile read is kept there under
// the tileset's generation unless the archive is known to have been modified.
HttpResponse stored_tile_answer(std::shared_ptr<const Tileset> t, TileId id,
                                Result<std::vector<std::uint8_t>> payload,
                                std::string_view if_none_match, const std::string& cc,
                                http_detail::NativeTileCache* cache = nullptr);
// The plan for a tile of a remote tileset (Tileset::remote): read on the answer pipeline's
// store-read pool, then answered by `answer` (unset: stored_tile_answer()).
HttpResponse stored_read_plan(
    std::shared_ptr<const Tileset> t, TileId id, const HttpRequest& request, const std::string& cc,
    std::function<HttpResponse(Result<std::vector<std::uint8_t>>)> answer = {});
// 404 with Vts-Error: version-not-current.
HttpResponse not_current(std::string_view version, const std::string& name,
                         const std::string& current);
HttpResponse outside_pyramid(std::uint32_t z, std::uint32_t x, std::uint32_t y,
                             const std::string& name);
// 503 with Retry-After for an archive modified in place (and archive_changed set).
HttpResponse archive_changed(std::shared_ptr<const Tileset> t, const Error& e);

// ---- request target (router_target.cpp)

int hex_value(char c);
// Strict decimal: "0" or [1-9][0-9]*, fitting in uint32.
std::optional<std::uint32_t> parse_u32(std::string_view s);

struct Query {
  std::optional<std::string_view> expires;
  std::optional<std::string_view> sig;
  std::optional<std::string_view> format;  // /{ts}.json?format=png|webp|jpg
  std::optional<std::string_view> tiling;  // /{ts}.json?format=...&tiling=WebMercatorQuad
  // WMTS KVP (router_wmts.cpp), matched case-insensitively, as sent (decode_query_value()).
  // `format` above is WMTS's FORMAT too.
  std::optional<std::string_view> service, request, version, layer, style, tile_matrix_set,
      tile_matrix, tile_row, tile_col;
};
// A query value as sent, percent-decoded ('+' is a space); nullopt for a malformed escape or an
// escaped control character.
std::optional<std::string> decode_query_value(std::string_view v);

// The request target, checked once for both listeners: origin-form, at most max_target_bytes
// (else 414), a path whose escapes and characters are allowed and a query without controls (else
// 400). `path` is the decoded path, `raw_path` the path as sent (signed URLs sign it).
struct Target {
  std::string path;
  std::string_view raw_path;
  Query query;
};
// nullopt with `rejection` set when the target is refused.
std::optional<Target> parse_target(std::string_view target, std::size_t max_target_bytes,
                                   std::optional<HttpResponse>& rejection);

// Splits "/a/b/c" (not "/") into segments; rejects empty segments and "." / "..".
bool split_segments(std::string_view path, std::vector<std::string_view>& out, std::string& why);
// Host: a reg-name / IPv4 / [IPv6] with an optional port; nothing that could alter a URL.
bool valid_host(std::string_view h);

// ---- conditional requests and ranges (router_conditional.cpp)

// If-None-Match with the weak comparison (RFC 9110 §13.1.2).
bool none_match(std::string_view header, std::string_view etag);
// Saturating decimal parse (a huge position is valid syntax, just unsatisfiable).
bool parse_pos(std::string_view s, std::uint64_t& v);

struct RangeDecision {
  enum Kind { full, partial, unsatisfiable } kind = full;
  std::uint64_t first = 0, last = 0;  // inclusive, for partial
};
// RFC 9110 §14: one satisfiable range → partial; none satisfiable → unsatisfiable; several
// ranges or an invalid header → full.
RangeDecision decide_range(std::string_view header, std::uint64_t size);

// ---- access control (router_access.cpp)

// Whether tileset `name` has bearer tokens or signing keys (docs/PROTOCOL.md §7).
bool is_protected(const RouterConfig& config, std::string_view name);

// nullopt = allowed; otherwise the error response (401 or 403).
std::optional<HttpResponse> check_access(const TilesetAccess& access, const HttpRequest& request,
                                         std::string_view raw_path, const Query& query,
                                         const RouterConfig& config);

// ---- web images of tiles (router_web.cpp)

// The tile a web tile route addresses, from `zxy` (validated decimals): z at most the pyramid's
// max zoom, x and y within level z's XYZ grid (at least 2^z x 2^z, as web maps address it; the
// pyramid's own grid where that is wider). Otherwise nullopt, with `rejection` set to the 404 of
// outside_pyramid naming tileset `name`. Shared by archives' and provided tilesets' web tiles.
std::optional<TileId> web_tile_id(std::span<const std::string_view> zxy, const Geometry& g,
                                  const std::string& name, std::optional<HttpResponse>& rejection);

// GET /{ts}[@{version}]/{z}/{x}/{y}.{ext}: the tile's content as a PNG / WebP / JPEG image, from
// the web tile cache (single flight) or encoded now. `zxy` are validated decimals.
HttpResponse web_tile_route(const HttpRequest& request, std::shared_ptr<const Tileset> t,
                            std::string_view version, std::span<const std::string_view> zxy,
                            imaging::WebFormat format, const RouterConfig& config, bool priv);
// GET /{ts}[@{version}]/WebMercatorQuad/{z}/{x}/{y}.{ext} of a WorldCRS84Quad tileset: the tile
// resampled to Web Mercator (render_web_mercator_tile), as an image.
HttpResponse web_mercator_tile_route(const HttpRequest& request, std::shared_ptr<const Tileset> t,
                                     std::string_view version,
                                     std::span<const std::string_view> zxy,
                                     imaging::WebFormat format, const RouterConfig& config,
                                     bool priv);
// The answer to a provided tile (vts cache serve) wanted as a web image, once it has arrived:
// `payload` (null: absent from a sparse origin, the transparent filler). A 304 or 502 at once, a
// cached image, or the plan to encode it (a pending answer with `image`).
HttpResponse provided_web_image(const PendingAnswer& d, const std::vector<std::uint8_t>* payload);
// The answer a provided tile (the pending answer `p`'s step 1) leads to: the tile (a view of its
// payload, kept by `keep`), 304, 204 (absent from a sparse origin), 404, 502, 503; or for a web
// image what provided_web_image() answers. Without the finishing touches (finish_pending's).
HttpResponse answer_provided(const PendingAnswer& p, ProvidedTile tile);
// The transparent filler of a tile with nothing to show (T x T texels), asked for on connection
// `owner` (HttpRequest::connection).
HttpResponse web_filler(std::uint32_t tile_size, imaging::WebFormat f, const RouterConfig& config,
                        std::string_view if_none_match, const std::string& cc, std::uint64_t owner);
// 200 with an encoded image, or 304 when `if_none_match` names its ETag.
HttpResponse web_image_response(const std::shared_ptr<const http_detail::WebTile>& tile,
                                std::string_view if_none_match, const std::string& cc);
// GET /{ts}.json?format=...[&tiling=...]: the TileJSON stock web maps read; 400 for an unknown
// format or a tiling this tileset cannot be served in. Web Mercator unless tiling= names the
// tileset's own grid: a WorldCRS84Quad tileset's template is then its WebMercatorQuad route, which
// needs `can_reproject` (archives; a cache daemon's provided tilesets cannot). `versioned`: the
// template names the version (archives); provided tilesets' tiles are not.
HttpResponse web_tilejson_route(const std::string& name, const TilesetInfo& info,
                                const std::string& version, bool versioned, const Query& q,
                                const std::string& base, bool priv, bool can_reproject);

// ---- the browser viewer (router_web_page.cpp, web_assets.cpp)

// A file embedded in the binary at build time (server/CMakeLists.txt generates web_assets.cpp).
struct WebAsset {
  std::string_view name;          // "ol.js"
  std::string_view url_name;      // "ol.<first 16 hex digits of its SHA-256>.js"
  std::string_view hash;          // those 16 hex digits (the ETag)
  std::string_view content_type;  // "text/javascript; charset=utf-8"
  std::span<const std::uint8_t> bytes;
};
std::span<const WebAsset> web_assets();

// A URL path segment: every byte but RFC 3986's unreserved ones percent-encoded.
std::string url_segment(std::string_view s);

// GET / from a browser (Accept: text/html), /{ts}/ and /_viewer/<asset>; nullopt for any other
// path (and for / without text/html, which stays the JSON index).
std::optional<HttpResponse> web_page(const HttpRequest& request, const Target& target,
                                     const TilesetRegistry& registry, const RouterConfig& config,
                                     const AsyncTileProvider* provider);

// ---- OGC entry points (router_wmts.cpp, router_ogcapi.cpp; docs/PROTOCOL.md §15)

// /wmts (KVP) and /wmts/...: WMTS 1.0.0 over the georeferenced, unprotected archive tilesets;
// nullopt for any other path. `base` is the URL prefix of absolute links (base_url()).
std::optional<HttpResponse> wmts_route(const HttpRequest& request, const Target& target,
                                       const TilesetRegistry& registry, const RouterConfig& config,
                                       const std::string& base);
// /ogcapi and /ogcapi/...: OGC API - Tiles over the same tilesets; nullopt for any other path.
std::optional<HttpResponse> ogcapi_route(const HttpRequest& request, const Target& target,
                                         const TilesetRegistry& registry,
                                         const RouterConfig& config, const std::string& base);

}  // namespace router_detail
}  // namespace server
}  // namespace vts
