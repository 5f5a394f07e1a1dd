// The HTTP semantics of `vts serve` (docs/PROTOCOL.md): request target validation, routing,
// conditional requests, byte ranges, CORS and access control. Pure: no I/O, no allocation of
// tile bodies (tile and archive bodies are views into the archive mapping).
#include "vts/server/router.hpp"

#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>

#include <array>
#include <cassert>
#include <charconv>
#include <cstdio>
#include <limits>
#include <nlohmann/json.hpp>

namespace vts {
namespace {

using nlohmann::ordered_json;

constexpr const char* kAllowedMethods = "GET, HEAD, OPTIONS";
constexpr const char* kTileType = "application/vnd.vtstream.tile";
constexpr const char* kArchiveType = "application/vnd.pmtiles";
constexpr const char* kJsonType = "application/json";
constexpr const char* kTextType = "text/plain; charset=utf-8";
constexpr std::uint32_t kImmutableMaxAge = 31536000;
constexpr std::uint32_t kMetadataMaxAge = 60;  // TileJSON and the index carry the version
constexpr std::size_t kMaxTargetBytes = 8192;

// ---------------------------------------------------------------------------------------------
// Response helpers

// `name` must be a string literal (HttpResponse::headers keeps a view).
void add(HttpResponse& r, std::string_view name, std::string value) {
  if (r.headers.empty()) r.headers.reserve(8);  // one allocation for a typical response
  r.headers.emplace_back(name, std::move(value));
}

void set_owned(HttpResponse& r, std::string body, const char* type) {
  r.owned = std::move(body);
  r.content_length = r.owned.size();
  add(r, "Content-Type", type);
}

HttpResponse error(int status, std::string message) {
  HttpResponse r;
  r.status = status;
  r.route = Route::error;
  message.push_back('\n');
  set_owned(r, std::move(message), kTextType);
  add(r, "Cache-Control", "no-store");
  return r;
}

std::string cache_control(bool is_private, std::uint32_t max_age, bool immutable) {
  char digits[10];
  const auto end = std::to_chars(digits, digits + sizeof digits, max_age).ptr;
  std::string s;
  s.reserve(40);  // one allocation: this runs for every tile
  s += is_private ? "private, max-age=" : "public, max-age=";
  s.append(digits, end);
  if (immutable) s += ", immutable";
  return s;
}

std::string hex(std::span<const unsigned char> bytes) {
  static constexpr char kDigits[] = "0123456789abcdef";
  std::string s;
  s.reserve(bytes.size() * 2);
  for (unsigned char b : bytes) {
    s.push_back(kDigits[b >> 4]);
    s.push_back(kDigits[b & 15]);
  }
  return s;
}

// ---------------------------------------------------------------------------------------------
// Target parsing

bool is_unreserved(unsigned char c) {
  return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-' ||
         c == '.' || c == '_' || c == '~';
}

int hex_value(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

// Decodes %XX only when XX is an unreserved character (RFC 3986 §6.2.2.2 makes those equivalent
// to the plain character); any other escape, a bare '%', a control or non-ASCII byte, a
// backslash or '#' is a 400. Returns nullopt with `why` set on rejection.
std::optional<std::string> decode_path(std::string_view raw, std::string& why) {
  std::string out;
  out.reserve(raw.size());
  for (std::size_t i = 0; i < raw.size(); ++i) {
    const auto c = static_cast<unsigned char>(raw[i]);
    if (c == '%') {
      const int hi = i + 2 < raw.size() ? hex_value(raw[i + 1]) : -1;
      const int lo = i + 2 < raw.size() ? hex_value(raw[i + 2]) : -1;
      if (hi < 0 || lo < 0) {
        why = "malformed percent-escape in path";
        return std::nullopt;
      }
      const auto d = static_cast<unsigned char>(hi * 16 + lo);
      if (!is_unreserved(d)) {
        why = "percent-escape of a reserved or non-ASCII character in path";
        return std::nullopt;
      }
      out.push_back(static_cast<char>(d));
      i += 2;
      continue;
    }
    if (c < 0x21 || c >= 0x7f || c == '\\' || c == '#') {
      why = "path contains a control, space, non-ASCII, backslash or '#' character";
      return std::nullopt;
    }
    out.push_back(static_cast<char>(c));
  }
  return out;
}

// Splits "/a/b/c" into segments; rejects empty segments ("//", trailing '/') and "." / "..".
bool split_segments(std::string_view path, std::vector<std::string_view>& out, std::string& why) {
  // path[0] == '/' and path != "/" here.
  std::size_t start = 1;
  while (true) {
    const std::size_t slash = path.find('/', start);
    const std::string_view seg = path.substr(
        start, slash == std::string_view::npos ? std::string_view::npos : slash - start);
    if (seg.empty()) {
      why = "empty path segment";
      return false;
    }
    if (seg == "." || seg == "..") {
      why = "dot segment in path";
      return false;
    }
    out.push_back(seg);
    if (slash == std::string_view::npos) return true;
    start = slash + 1;
  }
}

// Strict decimal: "0" or [1-9][0-9]*, fitting in uint32.
std::optional<std::uint32_t> parse_u32(std::string_view s) {
  if (s.empty() || s.size() > 10) return std::nullopt;
  if (s.size() > 1 && s[0] == '0') return std::nullopt;
  std::uint64_t v = 0;
  for (char c : s) {
    if (c < '0' || c > '9') return std::nullopt;
    v = v * 10 + static_cast<std::uint64_t>(c - '0');
  }
  if (v > std::numeric_limits<std::uint32_t>::max()) return std::nullopt;
  return static_cast<std::uint32_t>(v);
}

struct Query {
  std::optional<std::string_view> expires;
  std::optional<std::string_view> sig;
};

// Only `expires` and `sig` mean anything; every other parameter is ignored. A repeated
// `expires` or `sig` is ambiguous (a cache and we might disagree on which counts): 400.
bool parse_query(std::string_view q, Query& out, std::string& why) {
  while (!q.empty()) {
    const std::size_t amp = q.find('&');
    const std::string_view part = q.substr(0, amp);
    q = amp == std::string_view::npos ? std::string_view{} : q.substr(amp + 1);
    const std::size_t eq = part.find('=');
    const std::string_view key = part.substr(0, eq);
    const std::string_view value =
        eq == std::string_view::npos ? std::string_view{} : part.substr(eq + 1);
    std::optional<std::string_view>* slot = nullptr;
    if (key == "expires") slot = &out.expires;
    if (key == "sig") slot = &out.sig;
    if (slot == nullptr) continue;
    if (slot->has_value()) {
      why = "repeated query parameter \"" + std::string(key) + "\"";
      return false;
    }
    *slot = value;
  }
  return true;
}

// Host: a reg-name / IPv4 / [IPv6] with an optional port; nothing that could alter a URL.
bool valid_host(std::string_view h) {
  if (h.empty() || h.size() > 255) return false;
  for (char c : h) {
    const bool ok = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
                    c == '.' || c == '-' || c == ':' || c == '[' || c == ']' || c == '_';
    if (!ok) return false;
  }
  return true;
}

// ---------------------------------------------------------------------------------------------
// Conditional requests and ranges

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

// If-None-Match uses the weak comparison (RFC 9110 §13.1.2): "W/" prefixes are ignored.
bool none_match(std::string_view header, std::string_view etag) {
  if (header.empty()) return false;
  if (trim(header) == "*") return true;
  while (!header.empty()) {
    const std::size_t comma = header.find(',');
    std::string_view tag = trim(header.substr(0, comma));
    header = comma == std::string_view::npos ? std::string_view{} : header.substr(comma + 1);
    if (tag.size() >= 2 && tag.substr(0, 2) == "W/") tag.remove_prefix(2);
    if (tag == etag) return true;
  }
  return false;
}

// Saturating decimal parse (a huge position is valid syntax, just unsatisfiable).
bool parse_pos(std::string_view s, std::uint64_t& v) {
  if (s.empty()) return false;
  v = 0;
  for (char c : s) {
    if (c < '0' || c > '9') return false;
    const auto d = static_cast<std::uint64_t>(c - '0');
    if (v > (std::numeric_limits<std::uint64_t>::max() - d) / 10) {
      v = std::numeric_limits<std::uint64_t>::max();
    } else {
      v = v * 10 + d;
    }
  }
  return true;
}

struct RangeDecision {
  enum Kind { full, partial, unsatisfiable } kind = full;
  std::uint64_t first = 0, last = 0;  // inclusive, for partial
};

// RFC 9110 §14: one satisfiable range → 206; none satisfiable → 416; several ranges → the
// whole representation (we do not produce multipart/byteranges); an invalid header → ignored.
RangeDecision decide_range(std::string_view header, std::uint64_t size) {
  RangeDecision d;
  header = trim(header);
  if (header.size() < 6) return d;
  for (std::size_t i = 0; i < 5; ++i) {
    const char c = header[i];
    const char lower = (c >= 'A' && c <= 'Z') ? static_cast<char>(c - 'A' + 'a') : c;
    if (lower != "bytes"[i]) return d;
  }
  std::string_view set = trim(header.substr(5));
  if (set.empty() || set.front() != '=') return d;
  set = trim(set.substr(1));
  if (set.find(',') != std::string_view::npos) return d;  // multiple ranges: 200 full
  const std::size_t dash = set.find('-');
  if (dash == std::string_view::npos) return d;
  const std::string_view a = trim(set.substr(0, dash));
  const std::string_view b = trim(set.substr(dash + 1));
  std::uint64_t first = 0, last = 0;
  if (a.empty()) {  // suffix: the last n bytes
    std::uint64_t n = 0;
    if (!parse_pos(b, n)) return d;
    if (n == 0) {
      d.kind = RangeDecision::unsatisfiable;
      return d;
    }
    first = n >= size ? 0 : size - n;
    last = size - 1;
  } else {
    if (!parse_pos(a, first)) return d;
    if (b.empty()) {
      last = std::numeric_limits<std::uint64_t>::max();
    } else if (!parse_pos(b, last) || last < first) {
      return d;  // last < first is an invalid range-spec (§14.1.1): ignore the header
    }
    if (first >= size) {
      d.kind = RangeDecision::unsatisfiable;
      return d;
    }
    if (last >= size) last = size - 1;
  }
  d.kind = RangeDecision::partial;
  d.first = first;
  d.last = last;
  return d;
}

// ---------------------------------------------------------------------------------------------
// Access control

std::int64_t now_seconds(const RouterConfig& config) {
  if (config.now_unix_seconds != nullptr) return config.now_unix_seconds();
  return std::chrono::duration_cast<std::chrono::seconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

std::array<unsigned char, 32> sha256(std::string_view s) {
  std::array<unsigned char, 32> out{};
  unsigned int len = 0;
  EVP_Digest(s.data(), s.size(), out.data(), &len, EVP_sha256(), nullptr);
  return out;
}

std::array<unsigned char, 32> hmac_sha256(std::string_view key, std::string_view message) {
  std::array<unsigned char, 32> out{};
  unsigned int len = 0;
  HMAC(EVP_sha256(), key.data(), static_cast<int>(key.size()),
       reinterpret_cast<const unsigned char*>(message.data()), message.size(), out.data(), &len);
  return out;
}

bool iequals(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    auto lower = [](char c) { return (c >= 'A' && c <= 'Z') ? static_cast<char>(c + 32) : c; };
    if (lower(a[i]) != lower(b[i])) return false;
  }
  return true;
}

// nullopt = allowed; otherwise the error response (401 or 403).
std::optional<HttpResponse> check_access(const TilesetAccess& access, const HttpRequest& request,
                                         std::string_view raw_path, const Query& query,
                                         const RouterConfig& config) {
  std::string_view token;
  bool has_bearer = false;
  {
    const std::string_view auth = trim(request.authorization);
    const std::size_t sp = auth.find(' ');
    if (sp != std::string_view::npos && iequals(auth.substr(0, sp), "bearer")) {
      token = trim(auth.substr(sp + 1));
      has_bearer = !token.empty();
    }
  }
  const bool has_signature = query.expires.has_value() || query.sig.has_value();
  if (!has_bearer && !has_signature) {
    HttpResponse r = error(401, "this tileset needs credentials: a bearer token or a signed URL");
    add(r, "WWW-Authenticate", "Bearer realm=\"vtstream\"");
    return r;
  }
  if (has_bearer) {
    // Compare digests so the comparison is constant-time whatever the lengths.
    const auto given = sha256(token);
    bool ok = false;
    for (const auto& t : access.bearer_tokens) {
      const auto want = sha256(t);
      ok |= CRYPTO_memcmp(given.data(), want.data(), want.size()) == 0;
    }
    if (ok) return std::nullopt;
  }
  if (has_signature && query.expires && query.sig) {
    std::uint64_t expires = 0;
    const std::string_view sig = *query.sig;
    std::array<unsigned char, 32> given{};
    bool well_formed =
        parse_pos(*query.expires, expires) && query.expires->size() <= 18 && sig.size() == 64;
    for (std::size_t i = 0; well_formed && i < 32; ++i) {
      const int hi = hex_value(sig[2 * i]), lo = hex_value(sig[2 * i + 1]);
      if (hi < 0 || lo < 0) well_formed = false;
      given[i] = static_cast<unsigned char>(hi * 16 + lo);
    }
    if (well_formed) {
      if (static_cast<std::int64_t>(expires) < now_seconds(config)) {
        return error(403, "signed URL has expired");
      }
      const std::string message = std::string(raw_path) + "?expires=" + std::string(*query.expires);
      bool ok = false;
      for (const auto& key : access.hmac_keys) {
        const auto want = hmac_sha256(key, message);
        ok |= CRYPTO_memcmp(given.data(), want.data(), want.size()) == 0;
      }
      if (ok) return std::nullopt;
    }
  }
  return error(403, "credentials not accepted for this tileset");
}

// ---------------------------------------------------------------------------------------------
// Routes

std::string base_url(const HttpRequest& request, const RouterConfig& config) {
  if (!config.public_base_url.empty()) {
    std::string b = config.public_base_url;
    while (!b.empty() && b.back() == '/') b.pop_back();
    return b;
  }
  if (request.host.empty()) return "";
  return "http://" + std::string(request.host);
}

bool is_protected(const RouterConfig& config, std::string_view name) {
  auto it = config.access.find(name);
  return it != config.access.end() &&
         (!it->second.bearer_tokens.empty() || !it->second.hmac_keys.empty());
}

ordered_json vtstream_object(const Tileset& t) {
  ordered_json v = ordered_json::object();
  auto meta = ordered_json::parse(t.reader->metadata_json(), nullptr, false);
  if (meta.is_object()) {
    auto it = meta.find("vtstream");
    if (it != meta.end() && it->is_object()) v = *it;
  }
  return v;
}

HttpResponse index_route(const TilesetRegistry& registry, const AsyncTileProvider* provider,
                         const RouterConfig& config, const std::string& base) {
  std::map<std::string, ordered_json, std::less<>> entries;  // sorted by name
  if (provider != nullptr) {
    // Inserted first so that a registry tileset of the same name replaces it, as in lookups.
    for (const auto& t : provider->all()) {
      if (!t) continue;
      entries[t->name] = {{"name", t->name},
                          {"version", t->version},
                          {"tilejson", base + "/" + t->name + ".json"},
                          {"width", t->info.geometry.width()},
                          {"height", t->info.geometry.height()},
                          {"max_zoom", t->info.geometry.max_zoom()},
                          {"codec", codec_name(t->info.codec)},
                          {"protected", is_protected(config, t->name)}};
    }
  }
  for (const auto& t : registry.all()) {
    entries[t->name] = {{"name", t->name},
                        {"version", t->version},
                        {"tilejson", base + "/" + t->name + ".json"},
                        {"archive", base + "/" + t->name + ".pmtiles"},
                        {"width", t->info.geometry.width()},
                        {"height", t->info.geometry.height()},
                        {"max_zoom", t->info.geometry.max_zoom()},
                        {"codec", codec_name(t->info.codec)},
                        {"protected", is_protected(config, t->name)}};
  }
  ordered_json list = ordered_json::array();
  for (auto& [name, entry] : entries) list.push_back(std::move(entry));
  HttpResponse r;
  r.route = Route::index;
  set_owned(r, list.dump(2) + "\n", kJsonType);
  add(r, "Cache-Control", cache_control(false, kMetadataMaxAge, false));
  return r;
}

// TileJSON 3.0 for a tileset, archive or provided: `tiles_url` is its one URL template.
HttpResponse tilejson_response(const std::string& name, const TilesetInfo& info,
                               const std::string& version, std::string tiles_url,
                               ordered_json vtstream, bool priv) {
  ordered_json j = {
      {"tilejson", "3.0.0"},
      {"name", info.name.empty() ? name : info.name},
      {"description", info.description},
      {"version", version},
      {"scheme", "xyz"},
      {"tiles", {std::move(tiles_url)}},
      {"minzoom", 0},
      {"maxzoom", info.geometry.max_zoom()},
      {"bounds", {-180, -90, 180, 90}},
      {"vtstream", std::move(vtstream)},
  };
  HttpResponse r;
  r.route = Route::tilejson;
  set_owned(r, j.dump(2, ' ', false, ordered_json::error_handler_t::replace) + "\n", kJsonType);
  add(r, "Cache-Control", cache_control(priv, kMetadataMaxAge, false));
  return r;
}

HttpResponse tilejson_route(const Tileset& t, const std::string& base, bool priv) {
  ordered_json v = vtstream_object(t);
  v["archive"] = base + "/" + t.name + ".pmtiles";
  return tilejson_response(t.name, t.info, t.version,
                           base + "/" + t.name + "@" + t.version + "/{z}/{x}/{y}", std::move(v),
                           priv);
}

HttpResponse archive_route(const HttpRequest& request, std::shared_ptr<const Tileset> t,
                           const RouterConfig& config, bool priv) {
  const auto bytes = t->reader->bytes();
  const std::uint64_t size = bytes.size();
  const std::string etag = "\"" + t->version + "\"";
  HttpResponse r;
  r.route = Route::archive;
  add(r, "ETag", etag);
  add(r, "Cache-Control", cache_control(priv, config.max_age_seconds, false));
  add(r, "Accept-Ranges", "bytes");
  if (none_match(request.if_none_match, etag)) {
    r.status = 304;
    r.hold = std::move(t);  // names the tileset in access logs
    return r;
  }
  RangeDecision range;
  // If-Range with anything but our current strong ETag (a stale tag, or a date: we send no
  // Last-Modified) means "send the whole thing".
  if (!request.range.empty() && (request.if_range.empty() || trim(request.if_range) == etag)) {
    range = decide_range(request.range, size);
  }
  if (range.kind == RangeDecision::unsatisfiable) {
    HttpResponse e =
        error(416, "range not satisfiable: the archive has " + std::to_string(size) + " bytes");
    e.route = Route::archive;
    add(e, "Content-Range", "bytes */" + std::to_string(size));
    add(e, "Accept-Ranges", "bytes");
    return e;
  }
  add(r, "Content-Type", kArchiveType);
  if (range.kind == RangeDecision::partial) {
    r.status = 206;
    add(r, "Content-Range",
        "bytes " + std::to_string(range.first) + "-" + std::to_string(range.last) + "/" +
            std::to_string(size));
    r.view = bytes.subspan(range.first, range.last - range.first + 1);
  } else {
    r.view = bytes;
  }
  r.content_length = r.view.size();
  r.hold = std::move(t);
  return r;
}

// 200 with the stored payload (a view: the caller keeps its bytes alive) or 304, with the ETag
// read from the payload's tile header frame; `damaged_status` when that frame does not parse
// (500 for our own archive, 502 for a provider's origin).
HttpResponse payload_response(std::span<const std::uint8_t> payload, std::string_view if_none_match,
                              const std::string& cc, int damaged_status, TileId id,
                              std::string_view tileset) {
  auto header = parse_tile_header(payload);
  if (!header) {
    HttpResponse r =
        error(damaged_status, "tile " + id.to_string() + " of " + std::string(tileset) +
                                  " is damaged: " + header.error().to_string());
    r.route = Route::tile;
    return r;
  }
  // "<16 lowercase hex>" without printf: this runs for every tile and every 304.
  char etag[19];
  etag[0] = '"';
  for (int i = 0; i < 16; ++i)
    etag[1 + i] = "0123456789abcdef"[(header->checksum >> (60 - 4 * i)) & 0xf];
  etag[17] = '"';
  etag[18] = '\0';
  HttpResponse r;
  r.route = Route::tile;
  add(r, "ETag", etag);
  add(r, "Cache-Control", cc);
  if (none_match(if_none_match, etag)) {
    r.status = 304;
    return r;
  }
  add(r, "Content-Type", kTileType);
  r.view = payload;
  r.content_length = r.view.size();
  return r;
}

HttpResponse tile_route(const HttpRequest& request, std::shared_ptr<const Tileset> t,
                        std::string_view version, std::span<const std::string_view> zxy,
                        const RouterConfig& config, bool priv) {
  if (!version.empty() && version != t->version) {
    HttpResponse r = error(404, "version " + std::string(version) + " of tileset " + t->name +
                                    " is not current (current: " + t->version + "); fetch /" +
                                    t->name + ".json again");
    r.route = Route::tile;
    return r;
  }
  const auto z = parse_u32(zxy[0]), x = parse_u32(zxy[1]), y = parse_u32(zxy[2]);
  if (!z || !x || !y) return error(400, "tile address must be /{tileset}/{z}/{x}/{y} in decimal");
  const Geometry& g = t->info.geometry;
  auto outside = [&] {
    HttpResponse r = error(404, "tile " + std::to_string(*z) + "/" + std::to_string(*x) + "/" +
                                    std::to_string(*y) + " is outside the pyramid of " + t->name);
    r.route = Route::tile;
    return r;
  };
  if (*z > static_cast<std::uint32_t>(g.max_zoom())) return outside();
  const TileId id{static_cast<std::uint8_t>(*z), *x, *y};
  if (*x >= g.tiles_x(id.z) || *y >= g.tiles_y(id.z)) return outside();

  const std::string cc = version.empty() ? cache_control(priv, config.max_age_seconds, false)
                                         : cache_control(priv, kImmutableMaxAge, true);
  auto payload = t->reader->get(id);
  if (!payload) {
    if (payload.error().code == ErrorCode::not_found) {
      if (t->info.sparse) {
        HttpResponse r;
        r.status = 204;
        r.route = Route::tile;
        r.hold = std::move(t);  // names the tileset in access logs
        add(r, "Cache-Control", cc);
        return r;
      }
      HttpResponse r = error(404, "tile " + id.to_string() + " is missing from the archive of " +
                                      t->name + " (archive incomplete)");
      r.route = Route::tile;
      return r;
    }
    HttpResponse r =
        error(500, "archive of " + t->name + " is damaged: " + payload.error().to_string());
    r.route = Route::tile;
    return r;
  }
  HttpResponse r = payload_response(*payload, request.if_none_match, cc, 500, id, t->name);
  r.hold = std::move(t);  // keeps the mapping alive; names the tileset in access logs
  return r;
}

// Versioned URLs of a provided tileset: the version must be the one the provider reports (the
// origin's), else 404 "not current" as for archives, so a client refetches the TileJSON. The
// daemon cannot promise that every tile it holds belongs to that version (tiles are revalidated
// by ETag), so even a current versioned URL is not answered as immutable.
HttpResponse provided_tile_route(const HttpRequest& request,
                                 std::shared_ptr<const ProvidedTileset> t, std::string_view version,
                                 std::span<const std::string_view> zxy, const RouterConfig& config,
                                 bool priv) {
  if (!version.empty() && (t->version.empty() || version != t->version)) {
    HttpResponse r = error(404, "version " + std::string(version) + " of tileset " + t->name +
                                    " is not current (current: " +
                                    (t->version.empty() ? std::string("unknown") : t->version) +
                                    "); fetch /" + t->name + ".json again");
    r.route = Route::tile;
    return r;
  }
  const auto z = parse_u32(zxy[0]), x = parse_u32(zxy[1]), y = parse_u32(zxy[2]);
  if (!z || !x || !y) return error(400, "tile address must be /{tileset}/{z}/{x}/{y} in decimal");
  const Geometry& g = t->info.geometry;
  if (*z > static_cast<std::uint32_t>(g.max_zoom()) ||
      *x >= g.tiles_x(static_cast<std::uint8_t>(*z)) ||
      *y >= g.tiles_y(static_cast<std::uint8_t>(*z))) {
    HttpResponse r = error(404, "tile " + std::to_string(*z) + "/" + std::to_string(*x) + "/" +
                                    std::to_string(*y) + " is outside the pyramid of " + t->name);
    r.route = Route::tile;
    return r;
  }
  auto d = std::make_shared<DeferredTile>();
  d->id = TileId{static_cast<std::uint8_t>(*z), *x, *y};
  d->if_none_match = std::string(request.if_none_match);
  d->cache_control = cache_control(priv, config.max_age_seconds, false);
  d->tileset = std::move(t);
  HttpResponse r;
  r.route = Route::tile;
  r.deferred = std::move(d);
  return r;
}

HttpResponse provided_tilejson_route(const ProvidedTileset& t, const std::string& base, bool priv) {
  ordered_json v = ordered_json::object();
  auto meta = ordered_json::parse(t.info.to_json(), nullptr, false);
  if (meta.is_object()) {
    auto it = meta.find("vtstream");
    if (it != meta.end() && it->is_object()) v = *it;
  }
  return tilejson_response(t.name, t.info, t.version, base + "/" + t.name + "/{z}/{x}/{y}",
                           std::move(v), priv);
}

HttpResponse preflight(const HttpRequest& request) {
  HttpResponse r;
  r.status = 204;
  r.route = Route::preflight;
  add(r, "Allow", kAllowedMethods);
  if (!request.access_control_request_method.empty()) {
    add(r, "Access-Control-Allow-Methods", kAllowedMethods);
    add(r, "Access-Control-Allow-Headers", "Authorization, If-None-Match, Range");
    add(r, "Access-Control-Max-Age", "86400");
  }
  return r;
}

HttpResponse dispatch(const HttpRequest& request, const TilesetRegistry& registry,
                      const RouterConfig& config, const AsyncTileProvider* provider) {
  if (request.method == HttpMethod::other) {
    HttpResponse r = error(405, "method not allowed; use GET, HEAD or OPTIONS");
    add(r, "Allow", kAllowedMethods);
    return r;
  }
  if (request.method == HttpMethod::options && request.target == "*") return preflight(request);
  if (request.target.size() > kMaxTargetBytes) return error(414, "request target too long");
  if (request.target.empty() || request.target.front() != '/') {
    return error(400, "request target must be a path starting with '/'");
  }
  const std::size_t qpos = request.target.find('?');
  const std::string_view raw_path = request.target.substr(0, qpos);
  const std::string_view raw_query =
      qpos == std::string_view::npos ? std::string_view{} : request.target.substr(qpos + 1);

  std::string why;
  const auto path = decode_path(raw_path, why);
  if (!path) return error(400, why);
  Query query;
  if (raw_query.find_first_of(std::string_view("\0\r\n #", 5)) != std::string_view::npos) {
    return error(400, "query contains a control, space or '#' character");
  }
  if (!parse_query(raw_query, query, why)) return error(400, why);
  if (request.method == HttpMethod::options) return preflight(request);

  std::string base = base_url(request, config);
  if (config.public_base_url.empty() && !request.host.empty() && !valid_host(request.host)) {
    return error(400, "malformed Host header");
  }
  if (*path == "/") return index_route(registry, provider, config, base);

  std::vector<std::string_view> segments;
  if (!split_segments(*path, segments, why)) return error(400, why);

  std::string_view name;
  std::string_view version;
  enum class Kind { tile, tilejson, archive } kind = Kind::tile;
  if (segments.size() == 1) {
    const std::string_view s = segments[0];
    if (s.ends_with(".json")) {
      kind = Kind::tilejson;
      name = s.substr(0, s.size() - 5);
    } else if (s.ends_with(".pmtiles")) {
      kind = Kind::archive;
      name = s.substr(0, s.size() - 8);
    } else {
      return error(404,
                   "no such resource; try /, /{tileset}.json, /{tileset}.pmtiles or "
                   "/{tileset}/{z}/{x}/{y}");
    }
  } else if (segments.size() == 4) {
    name = segments[0];
    const std::size_t at = name.find('@');
    if (at != std::string_view::npos) {
      version = name.substr(at + 1);
      name = name.substr(0, at);
      if (version.empty()) return error(400, "empty version after '@'");
    }
    for (std::size_t i = 1; i < 4; ++i) {
      if (!parse_u32(segments[i])) {
        return error(400,
                     "tile address must be /{tileset}/{z}/{x}/{y} with decimal numbers "
                     "(no signs or leading zeros)");
      }
    }
  } else {
    return error(400, "tile address must be /{tileset}/{z}/{x}/{y}");
  }

  auto t = registry.find(name);
  std::shared_ptr<const ProvidedTileset> provided;
  if (!t && provider != nullptr) provided = provider->find(name);
  if (!t && !provided) return error(404, "no tileset named \"" + std::string(name) + "\"");

  bool priv = false;
  if (auto it = config.access.find(name);
      it != config.access.end() &&
      (!it->second.bearer_tokens.empty() || !it->second.hmac_keys.empty())) {
    priv = true;
    if (auto denied = check_access(it->second, request, raw_path, query, config)) return *denied;
  }
  if (provided) {
    switch (kind) {
      case Kind::tilejson:
        return provided_tilejson_route(*provided, base, priv);
      case Kind::archive: {
        HttpResponse r = error(404, "tileset \"" + provided->name +
                                        "\" is served from a cache and has no archive here; use "
                                        "/" +
                                        provided->name + "/{z}/{x}/{y}");
        r.route = Route::archive;
        return r;
      }
      case Kind::tile:
        break;
    }
    return provided_tile_route(request, std::move(provided), version,
                               std::span<const std::string_view>(segments).subspan(1), config,
                               priv);
  }
  switch (kind) {
    case Kind::tilejson:
      return tilejson_route(*t, base, priv);
    case Kind::archive:
      return archive_route(request, std::move(t), config, priv);
    case Kind::tile:
      break;
  }
  return tile_route(request, std::move(t), version,
                    std::span<const std::string_view>(segments).subspan(1), config, priv);
}

}  // namespace

const char* route_name(Route r) noexcept {
  switch (r) {
    case Route::index:
      return "index";
    case Route::tilejson:
      return "tilejson";
    case Route::tile:
      return "tile";
    case Route::archive:
      return "archive";
    case Route::preflight:
      return "preflight";
    case Route::error:
      return "error";
  }
  return "error";
}

HttpResponse route(const HttpRequest& request, const TilesetRegistry& registry,
                   const RouterConfig& config, const AsyncTileProvider* provider) {
  HttpResponse r = dispatch(request, registry, config, provider);
  if (!config.cors_origin.empty()) {
    add(r, "Access-Control-Allow-Origin", config.cors_origin);
    if (config.cors_origin != "*") add(r, "Vary", "Origin");
    if (r.route != Route::preflight) {
      add(r, "Access-Control-Expose-Headers", "ETag, Content-Range, Content-Length");
    }
  }
  if (request.method == HttpMethod::head) r.head_only = true;
  // 204 and 304 carry no body by definition (RFC 9110 §15.3.5, §15.4.5).
  if (r.status == 204 || r.status == 304) {
    r.owned.clear();
    r.view = {};
    r.content_length = 0;
  }
  return r;
}

HttpResponse complete_deferred(HttpResponse marker, ProvidedTile tile) {
  assert(marker.deferred);
  const DeferredTile& d = *marker.deferred;
  const std::string& name = d.tileset->name;
  HttpResponse r;
  switch (tile.kind) {
    case ProvidedTile::Kind::ok:
      r = payload_response(tile.payload, d.if_none_match, d.cache_control, 502, d.id, name);
      if (r.status == 200) r.keep = std::move(tile.keep);
      break;
    case ProvidedTile::Kind::absent:
      if (d.tileset->info.sparse) {
        r.status = 204;  // known-empty: cacheable like a tile
        add(r, "Cache-Control", d.cache_control);
      } else {
        r = error(404, "tile " + d.id.to_string() + " is missing from the origin of " + name +
                           " (origin incomplete)");
      }
      break;
    case ProvidedTile::Kind::unavailable:
      r = error(503, "tile " + d.id.to_string() + " of " + name +
                         " is not cached and its origin is unavailable" +
                         (tile.message.empty() ? std::string() : ": " + tile.message));
      break;
    case ProvidedTile::Kind::bad_origin:
      r = error(502, "the origin of " + name + " sent an unusable tile " + d.id.to_string() +
                         (tile.message.empty() ? std::string() : ": " + tile.message));
      break;
  }
  r.route = Route::tile;
  for (auto& h : marker.headers) r.headers.push_back(std::move(h));  // CORS, from route()
  r.head_only = marker.head_only;
  if (r.status == 204 || r.status == 304) {
    r.owned.clear();
    r.view = {};
    r.keep.reset();
    r.content_length = 0;
  }
  return r;
}

std::string sign_path(std::string_view path, std::int64_t expires_unix, std::string_view key) {
  const std::string expires = std::to_string(expires_unix);
  const auto mac = hmac_sha256(key, std::string(path) + "?expires=" + expires);
  return "?expires=" + expires + "&sig=" + hex(mac);
}

}  // namespace vts
