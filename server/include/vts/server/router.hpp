// The HTTP semantics of `vts serve`, as a pure function from a parsed request to a response
// description — no sockets, so every route and status is unit-testable and fuzzable. The network
// layer (http_server.hpp) parses bytes into HttpRequest, calls route(), and writes the
// HttpResponse (its body may be a view into an archive mapping, kept alive by `hold`).
// docs/PROTOCOL.md documents every route, header and status.
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

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

struct HttpResponse {
  int status = 200;
  Route route = Route::error;
  std::vector<std::pair<std::string, std::string>> headers;  // excluding Content-Length
  // The body is either `owned` or `view` (a view into an archive mapping); never both.
  std::string owned;
  std::span<const std::uint8_t> view;
  std::shared_ptr<const Tileset> hold;  // keeps `view`'s mapping alive
  std::uint64_t content_length = 0;     // of the full body (HEAD sends headers only)
  bool head_only = false;               // HEAD: send headers, no body
};

HttpResponse route(const HttpRequest& request, const TilesetRegistry& registry,
                   const RouterConfig& config);

// Signs a URL path for an HMAC-protected tileset: returns "?expires=<t>&sig=<hex>" to append.
std::string sign_path(std::string_view path, std::int64_t expires_unix, std::string_view key);

}  // namespace vts
