#include "vts/server/serve_config.hpp"

#include <array>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <type_traits>

#include "vts/base/file_io.hpp"
#include "vts/protocol/json_input.hpp"

namespace vts {
inline namespace server {
namespace {

using nlohmann::json;

constexpr std::array<std::string_view, 16> kTopKeys = {"listen",
                                                       "admin",
                                                       "threads",
                                                       "cors_origin",
                                                       "max_age",
                                                       "public_url",
                                                       "access_log",
                                                       "access",
                                                       "reload_interval_ms",
                                                       "limits",
                                                       "web",
                                                       "s3_endpoint",
                                                       "directory_cache_mib",
                                                       "tile_cache_mib",
                                                       "store_timeout_ms",
                                                       "store_retries"};
constexpr std::array<std::string_view, 8> kWebKeys = {
    "png_level",    "webp_quality", "webp_lossless",      "webp_method",
    "jpeg_quality", "cache_mib",    "max_queued_encodes", "max_queued_encodes_per_connection"};
constexpr std::array<std::string_view, 9> kLimitKeys = {
    "max_header_bytes", "max_target_bytes",  "max_connections",  "max_pipeline",    "min_send_rate",
    "idle_timeout_ms",  "header_timeout_ms", "write_timeout_ms", "drain_timeout_ms"};
constexpr std::array<std::string_view, 2> kAccessKeys = {"tokens", "hmac_keys"};

Error config_error(const std::string& file, const std::string& why) {
  return make_error(ErrorCode::invalid_argument, "config '" + file + "': " + why);
}

// Refuses a key of `object` (at `where`, e.g. "limits.") that is not in `known`.
template <std::size_t N>
Status check_keys(const json& object, const std::array<std::string_view, N>& known,
                  const std::string& where, const std::string& file) {
  if (!object.is_object()) return config_error(file, "\"" + where + "\" must be an object");
  for (const auto& [key, value] : object.items()) {
    bool ok = false;
    for (std::string_view k : known) ok |= key == k;
    if (!ok) {
      std::string list;
      for (std::string_view k : known) list += (list.empty() ? "" : ", ") + std::string(k);
      return config_error(file, "unknown key \"" + where + key + "\" (known: " + list + ")");
    }
  }
  return {};
}

Status apply_endpoint(const json& j, const char* key, std::string& host, std::uint16_t& port) {
  if (!j.contains(key)) return {};
  auto ep = parse_endpoint(j.at(key).get<std::string>());
  if (!ep) return ep.error();
  host = ep->first;
  port = ep->second;
  return {};
}

Status apply_access(const json& access, const std::string& file, RouterConfig& router) {
  if (!access.is_object()) return config_error(file, "\"access\" must be an object");
  for (const auto& [name, a] : access.items()) {
    if (auto st = check_keys(a, kAccessKeys, "access." + name + ".", file); !st.ok()) return st;
    TilesetAccess acc;
    if (a.contains("tokens")) acc.bearer_tokens = a.at("tokens").get<std::vector<std::string>>();
    if (a.contains("hmac_keys")) acc.hmac_keys = a.at("hmac_keys").get<std::vector<std::string>>();
    // An empty token or key would let anyone in (an empty bearer, a signature anyone can make).
    for (const auto& t : acc.bearer_tokens)
      if (t.empty()) return config_error(file, "access." + name + ".tokens holds an empty token");
    for (const auto& k : acc.hmac_keys)
      if (k.empty()) return config_error(file, "access." + name + ".hmac_keys holds an empty key");
    if (acc.bearer_tokens.empty() && acc.hmac_keys.empty())
      return config_error(file, "access." + name + " has no tokens and no hmac_keys");
    router.access[name] = std::move(acc);
  }
  return {};
}

Status apply_limits(const json& l, const std::string& file, HttpServerLimits& L) {
  if (auto st = check_keys(l, kLimitKeys, "limits.", file); !st.ok()) return st;
  // Every limit is a whole number, at least `min` (min_send_rate may be 0: no rate bound).
  Status bad;
  auto number = [&](const char* key, std::uint64_t min) -> std::optional<std::uint64_t> {
    if (!l.contains(key) || !bad.ok()) return std::nullopt;
    const json& v = l.at(key);
    if (!v.is_number_integer() || (v.is_number_integer() && !v.is_number_unsigned()) ||
        v.get<std::uint64_t>() < min) {
      bad =
          config_error(file, "limits." + std::string(key) + " is " + v.dump() +
                                 ": it must be a whole number of at least " + std::to_string(min));
      return std::nullopt;
    }
    return v.get<std::uint64_t>();
  };
  auto size = [&](const char* key, std::size_t& out, std::uint64_t min = 1) {
    if (auto v = number(key, min)) out = std::size_t(*v);
  };
  auto ms = [&](const char* key, std::chrono::milliseconds& out) {
    if (auto v = number(key, 1)) out = std::chrono::milliseconds(*v);
  };
  size("max_header_bytes", L.max_header_bytes, 256);
  size("max_target_bytes", L.max_target_bytes);
  size("max_connections", L.max_connections);
  size("max_pipeline", L.max_pipeline);
  size("min_send_rate", L.min_send_rate, 0);
  ms("idle_timeout_ms", L.idle_timeout);
  ms("header_timeout_ms", L.header_timeout);
  ms("write_timeout_ms", L.write_timeout);
  ms("drain_timeout_ms", L.drain_timeout);
  return bad;
}

// The "web" object: encoder settings and the RAM cache's cap of web images (docs/PROTOCOL.md §12).
Status apply_web(const json& w, const std::string& file, WebTileConfig& web) {
  if (auto st = check_keys(w, kWebKeys, "web.", file); !st.ok()) return st;
  Status bad;
  auto whole = [&](const char* key, std::int64_t lo, std::int64_t hi, auto& out) {
    if (!w.contains(key) || !bad.ok()) return;
    const json& v = w.at(key);
    if (!v.is_number_integer() || v.get<std::int64_t>() < lo || v.get<std::int64_t>() > hi) {
      bad = config_error(file, "web." + std::string(key) + " is " + v.dump() + ": a whole number " +
                                   std::to_string(lo) + " to " + std::to_string(hi));
      return;
    }
    out = static_cast<std::remove_reference_t<decltype(out)>>(v.get<std::int64_t>());
  };
  whole("png_level", 0, 9, web.encode.png_level);
  whole("webp_quality", 0, 100, web.encode.webp_quality);
  whole("webp_method", 0, 6, web.encode.webp_method);
  whole("jpeg_quality", 1, 100, web.encode.jpeg_quality);
  std::int64_t mib = -1;
  whole("cache_mib", 0, 1 << 20, mib);
  if (mib >= 0) web.cache_bytes = std::size_t(mib) << 20;
  whole("max_queued_encodes", 1, 1 << 20, web.max_queued_encodes);
  whole("max_queued_encodes_per_connection", 1, 1 << 20, web.max_queued_encodes_per_connection);
  if (bad.ok() && w.contains("webp_lossless")) {
    if (!w.at("webp_lossless").is_boolean())
      return config_error(
          file, "web.webp_lossless is " + w.at("webp_lossless").dump() + ": true or false");
    web.encode.webp_lossless = w.at("webp_lossless").get<bool>();
  }
  if (bad.ok()) {
    if (Status st = validate(web.encode); !st.ok())
      return config_error(file, "web: " + st.error().message);
  }
  return bad;
}

// Throws nlohmann::json::exception on a value of the wrong type.
Status apply(const json& j, const std::string& file, HttpServerOptions& o) {
  if (auto st = check_keys(j, kTopKeys, "", file); !st.ok()) return st;
  if (auto st = apply_endpoint(j, "listen", o.listen_host, o.listen_port); !st.ok()) return st;
  if (j.contains("admin") && j.at("admin").is_null()) {
    o.admin_enabled = false;
  } else if (auto st = apply_endpoint(j, "admin", o.admin_host, o.admin_port); !st.ok()) {
    return st;
  }
  if (j.contains("threads")) {
    // Checked as JSON before any conversion (get<int> wraps 4294967297 to 1 and truncates 2.5);
    // a string or an object is refused by get<> as a type error.
    const json& v = j.at("threads");
    if (v.is_number() && (!v.is_number_unsigned() || v.get<std::uint64_t>() > 256))
      return config_error(file, "threads is " + v.dump() + ": a whole number 0 to 256");
    o.threads = v.get<int>();
  }
  if (j.contains("cors_origin")) {
    o.router.cors_origin = j.at("cors_origin").get<std::string>();
    if (Status st = check_cors_origin(o.router.cors_origin); !st.ok())
      return config_error(file, st.error().message);
  }
  if (j.contains("max_age")) {
    const json& v = j.at("max_age");
    if (!v.is_number_unsigned() || v.get<std::uint64_t>() > 31536000)
      return config_error(file, "max_age is " + v.dump() + ": 0 to 31536000 seconds");
    o.router.max_age_seconds = v.get<std::uint32_t>();
  }
  if (j.contains("public_url")) o.router.public_base_url = j.at("public_url").get<std::string>();
  if (j.contains("access_log")) o.access_log = j.at("access_log").get<std::string>();
  if (j.contains("reload_interval_ms")) {
    const json& v = j.at("reload_interval_ms");
    // At most a year, a whole number: a float is never converted (1e300 would be undefined).
    if (v.is_number() && (!v.is_number_unsigned() || v.get<std::uint64_t>() > 31536000000ull))
      return config_error(file, "reload_interval_ms is " + v.dump() +
                                    ": a whole number 0 to 31536000000 (0: no periodic check)");
    o.reload_interval = std::chrono::milliseconds(v.get<std::int64_t>());
  }
  if (j.contains("s3_endpoint"))
    o.registry.store.s3_endpoint = j.at("s3_endpoint").get<std::string>();
  if (j.contains("store_timeout_ms")) {
    const json& v = j.at("store_timeout_ms");
    if (!v.is_number_unsigned() || v.get<std::uint64_t>() < 100 || v.get<std::uint64_t>() > 600000)
      return config_error(file,
                          "store_timeout_ms is " + v.dump() + ": a whole number 100 to 600000");
    o.registry.store.timeout = std::chrono::milliseconds(v.get<std::int64_t>());
  }
  if (j.contains("store_retries")) {
    const json& v = j.at("store_retries");
    if (!v.is_number_unsigned() || v.get<std::uint64_t>() > 10)
      return config_error(file, "store_retries is " + v.dump() + ": a whole number 0 to 10");
    o.registry.store.retries = v.get<int>();
  }
  if (j.contains("directory_cache_mib")) {
    const json& v = j.at("directory_cache_mib");
    if (!v.is_number_unsigned() || v.get<std::uint64_t>() > (1u << 20))
      return config_error(file,
                          "directory_cache_mib is " + v.dump() + ": a whole number 0 to 1048576");
    o.registry.directory_cache_bytes = std::size_t(v.get<std::uint64_t>()) << 20;
  }
  if (j.contains("tile_cache_mib")) {
    const json& v = j.at("tile_cache_mib");
    if (!v.is_number_unsigned() || v.get<std::uint64_t>() > (1u << 20))
      return config_error(file, "tile_cache_mib is " + v.dump() + ": a whole number 0 to 1048576");
    o.router.tile_cache_bytes = std::size_t(v.get<std::uint64_t>()) << 20;
  }
  if (j.contains("access"))
    if (auto st = apply_access(j.at("access"), file, o.router); !st.ok()) return st;
  if (j.contains("limits"))
    if (auto st = apply_limits(j.at("limits"), file, o.limits); !st.ok()) return st;
  if (j.contains("web"))
    if (auto st = apply_web(j.at("web"), file, o.router.web); !st.ok()) return st;
  return {};
}

}  // namespace

Result<std::pair<std::string, std::uint16_t>> parse_endpoint(const std::string& s) {
  const auto colon = s.rfind(':');
  if (colon == std::string::npos || colon + 1 == s.size())
    return make_error(ErrorCode::invalid_argument, "'" + s + "' is not HOST:PORT");
  std::string host = s.substr(0, colon);
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']')
    host = host.substr(1, host.size() - 2);
  unsigned long port = 0;
  try {
    std::size_t used = 0;
    port = std::stoul(s.substr(colon + 1), &used);
    if (used != s.size() - colon - 1 || port > 65535) throw std::out_of_range("port");
  } catch (const std::exception&) {  // std::stoul's: the CLI's parsing, kept exactly
    return make_error(ErrorCode::invalid_argument, "'" + s + "': bad port");
  }
  return std::pair{host.empty() ? std::string("0.0.0.0") : host, std::uint16_t(port)};
}

Status apply_serve_config_text(std::string_view text, const std::string& file,
                               HttpServerOptions& options) {
  auto j = parse_json(text, "config '" + file + "'");
  if (!j) return make_error(ErrorCode::invalid_argument, j.error().message);
  try {
    return apply(*j, file, options);
  } catch (const json::exception& e) {
    return config_error(file, e.what());
  }
}

Status apply_serve_config(const std::filesystem::path& file, HttpServerOptions& options) {
  std::error_code ec;
  if (std::filesystem::exists(file, ec) && !std::filesystem::is_regular_file(file, ec))
    return make_error(ErrorCode::invalid_argument,
                      "config '" + file.string() + "' is not a regular file");
  auto text = read_file(file);
  if (!text) return make_error(ErrorCode::io, "cannot read config '" + file.string() + "'");
  return apply_serve_config_text(*text, file.string(), options);
}

Status check_cors_origin(std::string_view origin) {
  for (unsigned char c : origin) {
    if (c < 0x20 || c == 0x7f)
      return make_error(ErrorCode::invalid_argument,
                        "cors_origin holds a control character (CR, LF, ...): it is sent as the "
                        "Access-Control-Allow-Origin header's value");
  }
  return {};
}

Status check_access_names(const HttpServerOptions& options, const TilesetRegistry& registry) {
  for (const auto& [name, access] : options.router.access) {
    if (!registry.find(name)) {
      std::string served;
      for (const auto& t : registry.all()) served += (served.empty() ? "" : ", ") + t->name;
      return make_error(ErrorCode::invalid_argument,
                        "the config protects tileset \"" + name +
                            "\", which is not served (served: " + served +
                            "): a misspelt name would leave the real tileset public");
    }
  }
  return {};
}

}  // namespace server
}  // namespace vts
