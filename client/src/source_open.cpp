// open_source(): which kind of source a location names, and the pieces every source shares (the
// tile ETag, If-None-Match matching) plus the offline source.
#include <algorithm>
#include <atomic>
#include <cstdio>
#include <utility>

#include <nlohmann/json.hpp>

#include "image_layout.hpp"
#include "vts/base/file_io.hpp"
#include "vts/client/source.hpp"
#include "vts/protocol/codec.hpp"

namespace vts::client {
namespace {

int hex_value(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

// file:///path, file://localhost/path or file:/path → "/path", percent-escapes decoded
// (RFC 8089). nullopt for another host, a relative path or a malformed escape.
std::optional<std::string> file_url_path(std::string_view url) {
  std::string_view rest = url.substr(5);  // after "file:"
  if (rest.substr(0, 2) == "//") {
    rest.remove_prefix(2);
    const std::size_t slash = rest.find('/');
    if (slash == std::string_view::npos) return std::nullopt;
    const std::string_view host = rest.substr(0, slash);
    if (!host.empty() && host != "localhost") return std::nullopt;
    rest.remove_prefix(slash);
  }
  if (rest.empty() || rest.front() != '/') return std::nullopt;
  std::string out;
  for (std::size_t i = 0; i < rest.size(); ++i) {
    if (rest[i] != '%') {
      out.push_back(rest[i]);
      continue;
    }
    const int hi = i + 2 < rest.size() ? hex_value(rest[i + 1]) : -1;
    const int lo = i + 2 < rest.size() ? hex_value(rest[i + 2]) : -1;
    if (hi < 0 || lo < 0 || (hi == 0 && lo == 0)) return std::nullopt;
    out.push_back(static_cast<char>(hi * 16 + lo));
    i += 2;
  }
  return out;
}

// Answers every fetch with an offline error, at once (before fetch() returns).
class OfflineSource final : public TileSource {
 public:
  explicit OfflineSource(SourceInfo info) : info_(std::move(info)) {}
  const SourceInfo& info() const override { return info_; }
  // Nothing here costs network: the client should not spend its network budget on us.
  bool local() const override { return true; }
  Handle fetch(const SourceRequest& request, SourceCallback callback) override {
    const Handle h = next_handle_.fetch_add(1, std::memory_order_relaxed) + 1;
    SourceTile t;
    t.kind = SourceTile::Kind::error;
    t.error = make_error(ErrorCode::io, "offline: tile " + request.id.to_string() + " of " +
                                            info_.key + " is not in the cache");
    callback(std::move(t));
    return h;
  }
  void cancel(Handle) override {}

 private:
  SourceInfo info_;
  std::atomic<Handle> next_handle_{0};
};

// An XYZ/TMS template says nothing of itself: its layout comes from the options.
Result<std::unique_ptr<TileSource>> open_template(std::string_view loc, SourceOptions options) {
  ImageLayout l;
  l.tiles = std::string(loc.substr(0, loc.find('#')));
  if (l.tiles.find("{x}") == std::string::npos ||
      (l.tiles.find("{y}") == std::string::npos && l.tiles.find("{-y}") == std::string::npos)) {
    return make_error(ErrorCode::invalid_argument,
                      "tile template " + l.tiles + " lacks {x} or {y} (or {-y} for TMS rows)");
  }
  l.min_zoom = std::max(options.min_zoom, 0);
  l.max_zoom = options.max_zoom;
  if (options.bounds) l.bounds = *options.bounds;
  l.tile_size = options.tile_size;
  l.format = format_from_suffix(l.tiles);
  // The key and the description (saved in caches) drop the query: it may hold credentials.
  std::string key = l.tiles.substr(0, l.tiles.find('?'));
  nlohmann::json doc = {{"tilejson", "3.0.0"},
                        {"tiles", {key}},
                        {"minzoom", l.min_zoom},
                        {"maxzoom", l.max_zoom},
                        {"bounds", {l.bounds.west, l.bounds.south, l.bounds.east, l.bounds.north}}};
  return open_image_template(l, std::move(key), doc.dump(), std::move(options));
}

}  // namespace

Result<std::string> tile_etag(std::span<const std::uint8_t> payload) {
  Result<TileHeader> header = parse_tile_header(payload);
  if (!header) return std::move(header).error();
  char etag[24];
  std::snprintf(etag, sizeof etag, "\"%016llx\"",
                static_cast<unsigned long long>(header->checksum));
  return std::string(etag);
}

bool etag_matches(std::string_view header, std::string_view etag) {
  header = trim(header);
  if (header.empty()) return false;
  if (header == "*") return true;
  if (etag.substr(0, 2) == "W/") etag.remove_prefix(2);
  while (!header.empty()) {
    const std::size_t comma = header.find(',');
    std::string_view tag = trim(header.substr(0, comma));
    header = comma == std::string_view::npos ? std::string_view{} : header.substr(comma + 1);
    if (tag.substr(0, 2) == "W/") tag.remove_prefix(2);
    if (!tag.empty() && tag == etag) return true;
  }
  return false;
}

Result<std::unique_ptr<TileSource>> open_source(std::string_view location, SourceOptions options) {
  if (options.vtstream_only) {
    options.vtstream_only = false;
    auto opened = open_source(location, std::move(options));
    if (opened && !(*opened)->info().image_format.empty()) {
      return make_error(ErrorCode::unsupported,
                        std::string(trim(location)) + " is a tileset of standard image tiles (" +
                            (*opened)->info().image_format + "), not a vtstream tileset");
    }
    return opened;
  }
  const std::string_view loc = trim(location);
  if (loc.empty()) return make_error(ErrorCode::invalid_argument, "empty tileset location");

  if (istarts_with(loc, "http://") || istarts_with(loc, "https://")) {
    // The suffix is judged on the path alone: a query (a signed object-store URL) or a fragment
    // does not change what the resource is.
    const std::string_view path = loc.substr(0, loc.find_first_of("?#"));
    if (path.find("{z}") != std::string_view::npos) return open_template(loc, std::move(options));
    if (path.ends_with(".pmtiles")) return open_remote_archive(loc, std::move(options));
    // A set's manifest: its archives under the same prefix, by ranged GETs.
    if (path.ends_with("/tileset.json")) return open_store_archive(std::string(loc));
    return open_tilejson(loc, std::move(options));
  }
  if (istarts_with(loc, "s3://")) return open_store_archive(std::string(loc));
  if (istarts_with(loc, "file:")) {
    const std::optional<std::string> path = file_url_path(loc);
    if (!path) {
      return make_error(ErrorCode::invalid_argument,
                        "malformed file URL " + std::string(loc) +
                            " (expected file:///absolute/path, percent-encoded)");
    }
    return open_local_archive(*path, options);
  }
  // A scheme we do not speak ("s3://", "ftp://") is more likely a mistake than a local file of
  // that name.
  if (const std::size_t colon = loc.find("://"); colon != std::string_view::npos) {
    bool scheme = colon > 0;
    for (std::size_t i = 0; i < colon; ++i) {
      const char c = loc[i];
      scheme &= (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') ||
                (i > 0 && ((c >= '0' && c <= '9') || c == '+' || c == '-' || c == '.'));
    }
    if (scheme) {
      return make_error(ErrorCode::invalid_argument,
                        "unsupported URL scheme in " + std::string(loc) +
                            " (use http://, https://, s3://, file:// or a path to a .pmtiles "
                            "file or a set)");
    }
  }
  return open_local_archive(std::filesystem::path(std::string(loc)), options);
}

std::unique_ptr<TileSource> offline_source(SourceInfo info) {
  return std::make_unique<OfflineSource>(std::move(info));
}

}  // namespace vts::client
