// The HTTP semantics of `vts serve`, as a pure function from a parsed request to a response
// description — no sockets, so every route and status is unit-testable and fuzzable. The network
// layer (http_server.hpp) parses bytes into HttpRequest, calls route(), and writes the
// HttpResponse (its body may be a view into an archive mapping, kept alive by `hold`).
// docs/PROTOCOL.md documents every route, header and status.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "vts/protocol/geometry.hpp"
#include "vts/protocol/tileset.hpp"
#include "vts/server/tileset_registry.hpp"

namespace vts {

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
  // Clock for signed-URL expiry (seconds since the Unix epoch); tests substitute their own.
  std::int64_t (*now_unix_seconds)() = nullptr;
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
};

// Which route answered, for metrics labels (stable names).
enum class Route : std::uint8_t { index, tilejson, tile, archive, preflight, error };
const char* route_name(Route r) noexcept;

// ---- Tilesets that are not archives (the cache daemon, `vts cache serve`) -------------------
//
// A server may host, besides the archives of its registry, tilesets whose tiles come from
// elsewhere, asynchronously: an AsyncTileProvider. route() answers everything it can for them
// synchronously (index, TileJSON, target validation, access control, pyramid bounds) and hands
// back a *deferred* tile response; the network layer asks the provider for the tile and, when the
// provider calls back, finishes the response with complete_deferred(). So the HTTP semantics of
// a provided tile (ETag from the payload's header frame, 304, Cache-Control, 204/404 for absent
// tiles, CORS, HEAD) are the router's, exactly as for an archive tile. A registry tileset hides a
// provided one of the same name.

// What the router needs to know about a provided tileset. Immutable once handed out.
struct ProvidedTileset {
  std::string name;     // as in URLs: [A-Za-z0-9._-]+, no leading dot, at most 128 characters
  TilesetInfo info;     // geometry (bounds checks), sparse (204 vs 404), TileJSON fields
  std::string version;  // TileJSON "version" (the origin's); may be empty. Versioned tile URLs
                        // are accepted when equal, but never advertised (see PROTOCOL.md §11)
};

// The provider's answer for one tile.
struct ProvidedTile {
  enum class Kind : std::uint8_t {
    ok,           // payload: the stored tile bytes, exactly as in an archive      -> 200 / 304
    absent,       // the origin has no such tile                                   -> 204 / 404
    unavailable,  // not held, and the origin cannot be reached (or is shutting down) -> 503
    bad_origin,   // the origin answered with something unusable (damaged tile)    -> 502
  };
  Kind kind = Kind::unavailable;
  // Kind::ok: the payload, sent without a copy; `keep` owns the bytes it views and is held until
  // the response has been written (e.g. an aliasing shared_ptr to the cache's CachedTile).
  std::span<const std::uint8_t> payload;
  std::shared_ptr<const void> keep;
  std::string message;  // unavailable / bad_origin: one line for the error body (no newline)
};

// Thread-safety: find() and all() are called from every I/O thread at once; tile() too.
class AsyncTileProvider {
 public:
  virtual ~AsyncTileProvider() = default;
  // The tileset named `name`, or null. Must not block.
  virtual std::shared_ptr<const ProvidedTileset> find(std::string_view name) const = 0;
  // Every tileset, for the index (any order).
  virtual std::vector<std::shared_ptr<const ProvidedTileset>> all() const = 0;
  // Starts fetching tile `id` (inside the pyramid) of `tileset` (one that find() returned) and
  // calls `done` exactly once, from any thread — possibly before tile() returns. Must not block;
  // `done` does not block either (it posts to the connection's thread). Every `done` must have
  // been called or destroyed before the HttpServer using this provider is destroyed.
  virtual void tile(const std::shared_ptr<const ProvidedTileset>& tileset, TileId id,
                    std::function<void(ProvidedTile)> done) = 0;
  // Extra Prometheus text appended to the server's /metrics (e.g. cache counters); may be empty.
  virtual std::string metrics_text() const { return {}; }
};

// route()'s marker for a tile that must come from the provider: what complete_deferred() needs
// once it arrives (copies, since the request's bytes are gone by then).
struct DeferredTile {
  std::shared_ptr<const ProvidedTileset> tileset;
  TileId id;
  std::string if_none_match;
  std::string cache_control;
};

struct HttpResponse {
  int status = 200;
  Route route = Route::error;
  // Excluding Content-Length. Names are string literals (static storage): a response is built
  // for every request, and a name never needs a copy.
  std::vector<std::pair<std::string_view, std::string>> headers;
  // The body is either `owned` or `view` (a view into an archive mapping, or into bytes owned by
  // `keep`); never both.
  std::string owned;
  std::span<const std::uint8_t> view;
  std::shared_ptr<const Tileset> hold;  // keeps `view`'s mapping alive
  std::shared_ptr<const void> keep;     // keeps a provided tile's `view` alive
  std::uint64_t content_length = 0;     // of the full body (HEAD sends headers only)
  bool head_only = false;               // HEAD: send headers, no body
  // Set (and nothing else but `route`, CORS headers and head_only) when the answer depends on
  // a provided tile: call provider->tile(), then complete_deferred() with its answer.
  std::shared_ptr<const DeferredTile> deferred;
};

// `provider` may be null (archives only, as `vts serve`).
HttpResponse route(const HttpRequest& request, const TilesetRegistry& registry,
                   const RouterConfig& config, const AsyncTileProvider* provider = nullptr);

// Finishes a deferred response (`marker`, as route() returned it) with the provider's answer:
// 200 / 304 / 204 / 404 / 502 / 503 (docs/PROTOCOL.md §11), keeping the marker's CORS headers
// and HEAD flag. A payload whose tile header frame is damaged is a 502.
HttpResponse complete_deferred(HttpResponse marker, ProvidedTile tile);

// Signs a URL path for an HMAC-protected tileset: returns "?expires=<t>&sig=<hex>" to append.
std::string sign_path(std::string_view path, std::int64_t expires_unix, std::string_view key);

}  // namespace vts
