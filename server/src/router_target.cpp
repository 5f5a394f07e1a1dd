// Request target parsing: the one place a target is validated (docs/PROTOCOL.md §2).
#include <limits>

#include "router_internal.hpp"
#include "vts/base/file_io.hpp"

namespace vts {
inline namespace server {
namespace router_detail {
namespace {

bool is_unreserved(unsigned char c) {
  return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-' ||
         c == '.' || c == '_' || c == '~';
}

// Decodes %XX only when XX is an unreserved character (RFC 3986 §6.2.2.2 makes those equivalent
// to the plain character); any other escape, a bare '%', a control or non-ASCII byte, a
// backslash or '#' is refused with `why` set.
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

// The WMTS KVP parameters (OGC 07-057r7 §7.2.2 and §7.3.2; their names are case-insensitive),
// with `format` shared with the web TileJSON's.
std::optional<std::string_view>* wmts_slot(std::string_view key, Query& out) {
  const std::pair<const char*, std::optional<std::string_view>*> keys[] = {
      {"service", &out.service},
      {"request", &out.request},
      {"version", &out.version},
      {"layer", &out.layer},
      {"style", &out.style},
      {"format", &out.format},
      {"tilematrixset", &out.tile_matrix_set},
      {"tilematrix", &out.tile_matrix},
      {"tilerow", &out.tile_row},
      {"tilecol", &out.tile_col}};
  for (const auto& [name, slot] : keys) {
    if (iequals(key, name)) return slot;
  }
  return nullptr;
}

// Only `expires`, `sig`, `format`, `tiling` and the WMTS parameters mean anything; every other
// parameter is ignored. A repeated one of these is ambiguous (a cache and we might disagree on
// which counts): refused.
bool parse_query(std::string_view q, Query& out, std::string& why) {
  while (!q.empty()) {
    const std::size_t amp = q.find('&');
    const std::string_view part = q.substr(0, amp);
    q = amp == std::string_view::npos ? std::string_view{} : q.substr(amp + 1);
    const std::size_t eq = part.find('=');
    const std::string_view key = part.substr(0, eq);
    const std::string_view value =
        eq == std::string_view::npos ? std::string_view{} : part.substr(eq + 1);
    std::optional<std::string_view>* slot = wmts_slot(key, out);
    if (key == "expires") slot = &out.expires;
    if (key == "sig") slot = &out.sig;
    if (key == "tiling") slot = &out.tiling;
    if (slot == nullptr) continue;
    if (slot->has_value()) {
      why = "repeated query parameter \"" + std::string(key) + "\"";
      return false;
    }
    *slot = value;
  }
  return true;
}

}  // namespace

int hex_value(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

std::optional<std::string> decode_query_value(std::string_view v) {
  std::string out;
  out.reserve(v.size());
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (v[i] == '+') {
      out.push_back(' ');
    } else if (v[i] != '%') {
      out.push_back(v[i]);
    } else {
      const int hi = i + 2 < v.size() ? hex_value(v[i + 1]) : -1;
      const int lo = i + 2 < v.size() ? hex_value(v[i + 2]) : -1;
      if (hi < 0 || lo < 0) return std::nullopt;
      const int c = hi * 16 + lo;
      if (c < 0x20 || c == 0x7f) return std::nullopt;  // a control: never in a name or a type
      out.push_back(static_cast<char>(c));
      i += 2;
    }
  }
  return out;
}

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

std::optional<Target> parse_target(std::string_view target, std::size_t max_target_bytes,
                                   std::optional<HttpResponse>& rejection) {
  if (target.size() > max_target_bytes) {
    rejection = error(414, "request target too long");
    return std::nullopt;
  }
  if (target.empty() || target.front() != '/') {
    rejection = error(400, "request target must be a path starting with '/'");
    return std::nullopt;
  }
  const std::size_t qpos = target.find('?');
  const std::string_view raw_query =
      qpos == std::string_view::npos ? std::string_view{} : target.substr(qpos + 1);
  Target t;
  t.raw_path = target.substr(0, qpos);
  std::string why;
  auto path = decode_path(t.raw_path, why);
  if (path && raw_query.find_first_of(std::string_view("\0\r\n #", 5)) != std::string_view::npos) {
    why = "query contains a control, space or '#' character";
    path.reset();
  }
  if (!path || !parse_query(raw_query, t.query, why)) {
    rejection = error(400, why);
    return std::nullopt;
  }
  t.path = std::move(*path);
  return t;
}

bool split_segments(std::string_view path, std::vector<std::string_view>& out, std::string& why) {
  std::size_t start = 1;  // path[0] == '/' and path != "/" here
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

bool valid_host(std::string_view h) {
  if (h.empty() || h.size() > 255) return false;
  for (char c : h) {
    const bool ok = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
                    c == '.' || c == '-' || c == ':' || c == '[' || c == ']' || c == '_';
    if (!ok) return false;
  }
  return true;
}

}  // namespace router_detail
}  // namespace server
}  // namespace vts
