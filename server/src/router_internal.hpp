// Pieces of the router shared by its source files (router*.cpp). Pure: no I/O.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "vts/server/router.hpp"

namespace vts::router_detail {

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

// ---- request target (router_target.cpp)

int hex_value(char c);
// Strict decimal: "0" or [1-9][0-9]*, fitting in uint32.
std::optional<std::uint32_t> parse_u32(std::string_view s);

struct Query {
  std::optional<std::string_view> expires;
  std::optional<std::string_view> sig;
};

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

// nullopt = allowed; otherwise the error response (401 or 403).
std::optional<HttpResponse> check_access(const TilesetAccess& access, const HttpRequest& request,
                                         std::string_view raw_path, const Query& query,
                                         const RouterConfig& config);

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

// Text for HTML content and quoted attribute values: & < > " ' as character references.
std::string html_escape(std::string_view s);
// A URL path segment: every byte but RFC 3986's unreserved ones percent-encoded.
std::string url_segment(std::string_view s);

// GET / from a browser (Accept: text/html), /{ts}/ and /_viewer/<asset>; nullopt for any other
// path (and for / without text/html, which stays the JSON index).
std::optional<HttpResponse> web_page(const HttpRequest& request, const Target& target,
                                     const TilesetRegistry& registry, const RouterConfig& config,
                                     const AsyncTileProvider* provider);

}  // namespace vts::router_detail
