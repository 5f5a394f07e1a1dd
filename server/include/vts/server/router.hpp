// The HTTP semantics of `vts serve`: functions from a parsed request to a response description,
// with no sockets, so every route and status is unit-testable and fuzzable. route() answers at
// once what its archive, memo and caches hold (it reads a tile's bytes or takes them from the
// native tile cache, remembers tile tags in the tileset's memo, looks web images up in the web
// tile cache) and starts no work: an answer that
// needs a provided tile or a web image encode is a plan (PendingAnswer) that finish_pending()
// carries out (docs/ARCHITECTURE.md "One answer pipeline"). The network layer (http_server.hpp)
// parses bytes into HttpRequest, calls route() (tile listener) or route_admin() (admin listener),
// and writes the HttpResponse (its body: bytes in memory, or a region of the archive `hold`
// names). docs/PROTOCOL.md documents every route, header and status. All functions are
// thread-safe for concurrent calls.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <stop_token>
#include <string>
#include <string_view>
#include <vector>

#include "vts/imaging/web_image.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/protocol/tile_provider.hpp"
#include "vts/protocol/tileset.hpp"
#include "vts/server/tileset_registry.hpp"

namespace vts {
inline namespace server {

namespace http_detail {
class WebTileCache;  // web_tile_cache.hpp
struct WebTile;
class NativeTileCache;  // native_tile_cache.hpp
}  // namespace http_detail

// Web images of tiles (/{ts}/{z}/{x}/{y}.png|.webp|.jpg; docs/PROTOCOL.md §12).
struct WebTileConfig {
  imaging::WebEncodeOptions encode;
  std::size_t cache_bytes = std::size_t(64) << 20;  // "cache_mib" (default 64 MiB; 0 = no cache)
  // Admission to the encode workers (docs/PROTOCOL.md §12): at most this many encodes wait, in
  // all ("max_queued_encodes") and from one connection ("max_queued_encodes_per_connection");
  // a miss beyond either is answered 503 with Retry-After.
  std::size_t max_queued_encodes = 1024;
  std::size_t max_queued_encodes_per_connection = 8;
  // Made by HttpServer from cache_bytes when null; route() without one encodes every request.
  std::shared_ptr<http_detail::WebTileCache> cache;
};

// Per-tileset access control (from the config file). A tileset with neither tokens nor keys is
// public.
struct TilesetAccess {
  std::vector<std::string> bearer_tokens;  // "Authorization: Bearer <token>"
  std::vector<std::string> hmac_keys;      // signed URLs: ?expires=<unix s>&sig=<hex HMAC-SHA256>
};

struct RouterConfig {
  std::string cors_origin = "*";         // Access-Control-Allow-Origin; empty = no CORS headers
  std::uint32_t max_age_seconds = 3600;  // Cache-Control max-age of unversioned tile URLs
  std::string public_base_url;           // for TileJSON tile URLs; empty = from the Host header
  std::map<std::string, TilesetAccess, std::less<>> access;  // by tileset name
  std::size_t max_target_bytes = 8192;                       // longer request targets are 414
  // Clock for signed-URL expiry (seconds since the Unix epoch); tests substitute their own.
  std::int64_t (*now_unix_seconds)() = nullptr;
  WebTileConfig web;
  // Native tiles of local archives kept in RAM (docs/PROTOCOL.md §6): at most tile_cache_bytes
  // ("tile_cache_mib", default 256 MiB; 0 = none). A kept tile answers while its archive is not
  // known to be modified in place and was verified unchanged within tile_cache_recheck (else
  // one request re-checks it: one fstat). Made by HttpServer when null; route() without one
  // reads every tile.
  std::size_t tile_cache_bytes = std::size_t(256) << 20;
  std::chrono::milliseconds tile_cache_recheck{50};
  std::shared_ptr<http_detail::NativeTileCache> tile_cache;
};

enum class HttpMethod : std::uint8_t { get, head, options, other };

struct HttpRequest {
  HttpMethod method = HttpMethod::get;
  std::string_view method_text;  // as received, for logs
  std::string_view target;       // origin-form: path and optional query
  // Only the headers the router reads (absent = empty).
  std::string_view host;
  std::string_view if_none_match;
  std::string_view range;
  std::string_view if_range;  // Range applies only if this equals the archive's ETag (RFC 9110)
  std::string_view origin;
  std::string_view authorization;
  std::string_view access_control_request_method;
  std::string_view accept;  // "text/html" in it: GET / answers the HTML index (a browser)
  // Which connection asked (the session's id; 0 = unknown): web-image encodes are queued fairly
  // between connections and capped per connection (WebTileConfig::limits).
  std::uint64_t connection = 0;
};

// Which route answered, for metrics labels (stable names). `admin` is every answer of the admin
// listener.
// `viewer` is the browser viewer's pages and assets.
enum class Route : std::uint8_t { index, tilejson, tile, archive, preflight, error, admin, viewer };
inline constexpr int kRouteCount = 8;
const char* route_name(Route r) noexcept;

// A web image route() decided on: `encode` makes it from the tileset's bytes (owning what it
// reads), and it is kept under `key` in the web tile cache with its strong ETag.
struct WebImageJob {
  std::string key;
  std::string etag;
  const char* content_type = "";  // a string literal
  std::function<Result<std::vector<std::uint8_t>>()> encode;
};

struct HttpResponse;

// route()'s plan for an answer it cannot give at once: the answer pipeline (finish_pending())
// carries it out, in order (docs/ARCHITECTURE.md "One answer pipeline"):
//   0. with `stored`: tile `id` read from that tileset's archive in an object store (one ranged
//      GET) on the store-read pool, never on an I/O thread, then answered as route() answers a
//      local archive's tile;
//   1. with `provided`: the provider's tile `id` (vts cache serve), from which the answer
//      follows: the tile itself, a status, or (with `web`) a web image job;
//   2. with `image`: the web image from the cache, or encoded on the cache's shared encode pool
//      (single flight, fair between connections, shed over its caps);
//   3. one finish: the final response with the marker's CORS headers, HEAD flag and tileset.
// A plain value: route() starts nothing.
struct PendingAnswer {
  std::shared_ptr<const Tileset> stored;
  // Step 0's answer from the stored payload (or the error reading it): the tile itself, a status,
  // or a web image job for step 2. Unset: the tile as route() answers a local archive's.
  std::function<HttpResponse(Result<std::vector<std::uint8_t>>)> answer_stored;
  std::shared_ptr<const ProvidedTileset> provided;
  TileId id;
  std::optional<imaging::WebFormat> web;  // step 1's tile wanted as this web image
  imaging::WebEncodeOptions web_options;
  std::optional<WebImageJob> image;
  // The web tile cache (RouterConfig::web::cache); null: the image is encoded on the thread
  // that carries the plan out, and kept nowhere.
  std::shared_ptr<http_detail::WebTileCache> cache;
  std::string if_none_match;
  std::string cache_control;
  std::uint64_t connection = 0;  // HttpRequest::connection
};

struct HttpResponse {
  int status = 200;
  Route route = Route::error;
  // Excluding Content-Length. Names are string literals (static storage): a response is built
  // for every request, and a name never needs a copy.
  std::vector<std::pair<std::string_view, std::string>> headers;
  // The body is one of: `owned`; `view` (into bytes owned by `keep`: a tile read from an
  // archive, a provided tile; or, with no `keep`, a viewer asset embedded in the binary); or, with
  // `file_body`, bytes [file_offset, file_offset + content_length) of `hold`'s archive, read as
  // they are sent.
  std::string owned;
  std::span<const std::uint8_t> view;
  std::shared_ptr<const Tileset> hold;  // the tileset answered from (access logs, file bodies)
  std::shared_ptr<const void> keep;     // keeps `view`'s bytes alive
  bool file_body = false;
  std::uint64_t file_offset = 0;
  std::uint64_t content_length = 0;  // of the full body (HEAD sends headers only)
  // The tileset's archive was modified in place since it was opened: the answer is a 503, and
  // the server should reload its tilesets now rather than at its next periodic check.
  bool archive_changed = false;
  bool head_only = false;  // HEAD: send headers, no body
  // Set (with `route`, `hold`, CORS headers and head_only, nothing else) when the answer needs
  // work first: hand the response to finish_pending().
  std::shared_ptr<const PendingAnswer> pending;
};

// The answer to a request refused before it could be routed (the network layer: a request that
// does not parse, is too large, or is framed or addressed wrongly — 400 / 413 / 414 / 431): an
// error exactly as route() gives one — a text/plain `message` + "\n", Cache-Control: no-store,
// route `error` — with the CORS headers route() adds under `config` (null: none, as on the admin
// listener).
HttpResponse unparsed_request_error(int status, std::string message, const RouterConfig* config);

// `provider` may be null (archives only, as `vts serve`).
HttpResponse route(const HttpRequest& request, const TilesetRegistry& registry,
                   const RouterConfig& config, const AsyncTileProvider* provider = nullptr);

// What the admin listener reports.
struct AdminState {
  bool ready = false;    // /health: 200 "ok" when set, else 503 "loading"
  std::string degraded;  // when ready and non-empty, /health is 503 "degraded: <this>"
  std::function<std::string()> metrics_text;  // /metrics body; called for /metrics only
  // The archive files not served as they are (TilesetRegistry::skipped()); /health lists them
  // after its first line. Called for /health only; may be empty (none).
  std::function<std::vector<SkippedArchive>()> skipped;
  std::size_t max_target_bytes = 8192;  // longer request targets are 414
};

// The admin listener: GET/HEAD /metrics and /health (no-store), 404 for any other path, 405 for
// other methods; every answer has route `admin`. The target is checked as route() checks it.
// /health is text/plain: "ok", "loading" or "degraded: <why>" on the first line, then one line
// per skipped archive, "skipped <file>: <reason>" (control characters in either written as \xHH, so
// a line is a line).
HttpResponse route_admin(const HttpRequest& request, const AdminState& state);

// Carries out `marker.pending` (route()'s plan; `provider` is the one given to route()) and calls
// `done` exactly once with the final response: 200 / 304 / 204 / 404 / 500 / 502 / 503
// (docs/PROTOCOL.md §11, §12). `done` runs on this thread when nothing had to wait (a cache hit,
// an encode without a pool), else on the thread that ended the work (the provider's, an
// encoder's). `interest` stopped means the client has gone: an encode nobody else waits for is
// dropped before it runs, and the provider may abandon the fetch.
void finish_pending(HttpResponse marker, AsyncTileProvider* provider, std::stop_token interest,
                    std::function<void(HttpResponse)> done);
// finish_pending(), waited for on this thread (tests and tools: a server never blocks a thread).
HttpResponse finish_pending_now(HttpResponse marker, AsyncTileProvider* provider = nullptr);

// Signs a URL path for an HMAC-protected tileset: returns "?expires=<t>&sig=<hex>" to append.
std::string sign_path(std::string_view path, std::int64_t expires_unix, std::string_view key);

}  // namespace server
}  // namespace vts
