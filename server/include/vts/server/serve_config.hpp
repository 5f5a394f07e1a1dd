// The `vts serve --config FILE` JSON file, applied on top of HttpServerOptions (command-line
// flags then override it). Keys (every one optional; docs/PROTOCOL.md §10 lists them):
//   listen, admin ("HOST:PORT"; admin null = no admin listener), threads, cors_origin, max_age,
//   public_url, access_log, reload_interval_ms,
//   s3_endpoint, directory_cache_mib, tile_cache_mib (0..1048576), store_timeout_ms (100..600000),
//   store_retries (0..10),
//   access: {"<tileset>": {"tokens": [...], "hmac_keys": [...]}},
//   limits: {max_header_bytes, max_target_bytes, max_connections, max_pipeline, min_send_rate,
//            idle_timeout_ms, header_timeout_ms, write_timeout_ms,
//            drain_timeout_ms},
//   web: {png_level 0..9, webp_quality 0..100, webp_lossless, webp_method 0..6,
//         jpeg_quality 1..100, cache_mib 0..1048576, max_queued_encodes 1..1048576,
//         max_queued_encodes_per_connection 1..1048576}.
// A key not in this list, at any level, is an error naming the key and the file: a misspelt
// limit must not silently leave the default in force.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <utility>

#include "vts/base/result.hpp"
#include "vts/server/http_server.hpp"
#include "vts/server/tileset_registry.hpp"

namespace vts {
inline namespace server {

// "HOST:PORT", "[v6]:PORT" or ":PORT" (host 0.0.0.0). Error invalid_argument.
Result<std::pair<std::string, std::uint16_t>> parse_endpoint(const std::string& s);

// Reads `file` and applies it to `options`. Errors: io (unreadable), invalid_argument (not a
// regular file, not JSON, a value of the wrong type, an unknown key, an empty token or HMAC key, a
// limit that is not a whole number at least its minimum, threads not a whole number 0..256, max_age
// outside a year, a reload interval not a whole number of ms up to a year), each naming the file.
// On error `options` may be partly changed.
Status apply_serve_config(const std::filesystem::path& file, HttpServerOptions& options);

// The same for config text already read; `file` only names it in errors.
Status apply_serve_config_text(std::string_view text, const std::string& file,
                               HttpServerOptions& options);

// invalid_argument when `origin` (the Access-Control-Allow-Origin value, from the config or
// --cors-origin) holds a control character: CR/LF would end the header and let the rest forge
// another.
Status check_cors_origin(std::string_view origin);

// invalid_argument when an access entry of `options` names a tileset `registry` does not serve
// (checked at start-up: a misspelt name would leave the real tileset public).
Status check_access_names(const HttpServerOptions& options, const TilesetRegistry& registry);

}  // namespace server
}  // namespace vts
