// The HTTP semantics of `vts serve` (docs/PROTOCOL.md): routing, tile and archive answers,
// TileJSON and the index. Not pure: it reads tiles from their archive (archive::Reader: a copy
// per tile, kept by the response) and queues web-image encodes; archive bodies are a file region
// the network layer reads. The target is checked in router_target.cpp, ranges in
// router_conditional.cpp, credentials in router_access.cpp, the admin listener in router_admin.cpp.
#include "vts/server/router.hpp"

#include <algorithm>
#include <array>
#include <cassert>
#include <charconv>
#include <map>
#include <nlohmann/json.hpp>

#include "deadline_sweeper.hpp"
#include "native_tile_cache.hpp"
#include "router_internal.hpp"
#include "tile_tag_memo.hpp"
#include "vts/base/file_io.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/protocol/tilejson.hpp"
#include "vts/protocol/tiling.hpp"
#include "web_tile_cache.hpp"

namespace vts {
inline namespace server {

namespace router_detail {

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

HttpResponse tile_error(int status, std::string message) {
  HttpResponse r = error(status, std::move(message));
  r.route = Route::tile;
  return r;
}

// A versioned tile URL whose version is not the tileset's current one: 404 with the
// Vts-Error signal, so a client refetches the TileJSON.
HttpResponse not_current(std::string_view version, const std::string& name,
                         const std::string& current) {
  HttpResponse r = tile_error(404, "version " + std::string(version) + " of tileset " + name +
                                       " is not current (current: " + current + "); fetch /" +
                                       name + ".json again");
  add(r, kVtsErrorHeader, std::string(kVersionNotCurrent));
  return r;
}

HttpResponse outside_pyramid(std::uint32_t z, std::uint32_t x, std::uint32_t y,
                             const std::string& name) {
  return tile_error(404, "tile " + std::to_string(z) + "/" + std::to_string(x) + "/" +
                             std::to_string(y) + " is outside the pyramid of " + name);
}

// A tile the archive could not give: 204 (known-empty) for a missing tile of a sparse tileset,
// else the status http_status() gives the error.
// 503 for a tileset whose archive was modified in place since it was opened: the server reloads
// its tilesets, and the client tries again shortly (by then against the archive that replaced
// it, once that one is complete and valid).
HttpResponse archive_changed(std::shared_ptr<const Tileset> t, const Error& e) {
  // Nothing kept from this archive answers any more (its tags, its cached tiles).
  t->modified.store(true, std::memory_order_relaxed);
  HttpResponse r = error(503, "the archive of tileset " + t->name +
                                  " is being replaced; try again shortly (" + e.message + ")");
  add(r, "Retry-After", "1");
  r.archive_changed = true;
  r.hold = std::move(t);  // names the tileset in access logs
  return r;
}

}  // namespace router_detail

namespace {

using namespace router_detail;
using nlohmann::ordered_json;

constexpr const char* kTileType = "application/vnd.vtstream.tile";
constexpr const char* kArchiveType = "application/vnd.pmtiles";
constexpr const char* kJsonType = "application/json";
constexpr std::uint32_t kMetadataMaxAge = 60;  // TileJSON and the index carry the version

HttpResponse unreadable_tile(std::shared_ptr<const Tileset> t, TileId id, const Error& e,
                             const std::string& cc) {
  if (e.code == ErrorCode::changed) {
    HttpResponse r = archive_changed(std::move(t), e);
    r.route = Route::tile;
    return r;
  }
  if (e.code == ErrorCode::unavailable) {  // an object store that did not answer: retry
    HttpResponse r = tile_error(503, "the store holding tileset " + t->name +
                                         " did not answer; try again shortly (" + e.message + ")");
    add(r, "Retry-After", "1");
    return r;
  }
  const int status = http_status(e.code);
  if (status == 404 && t->info.sparse) {
    HttpResponse r;
    r.status = 204;
    r.route = Route::tile;
    r.hold = std::move(t);  // names the tileset in access logs
    add(r, "Cache-Control", cc);
    return r;
  }
  if (status == 404) {
    return tile_error(404, "tile " + id.to_string() + " is missing from the archive of " + t->name +
                               " (archive incomplete)");
  }
  return tile_error(status, "archive of " + t->name + " is damaged: " + e.to_string());
}

std::string base_url(const HttpRequest& request, const RouterConfig& config) {
  if (!config.public_base_url.empty()) {
    std::string b = config.public_base_url;
    while (!b.empty() && b.back() == '/') b.pop_back();
    return b;
  }
  if (request.host.empty()) return "";
  return "http://" + std::string(request.host);
}

// The URLs each kind of client takes, for one index entry: our clients the native TileJSON (and
// the archive), web maps the web TileJSON (always on a grid they draw right), GIS tools the WMTS
// capabilities, the OGC API collection and an XYZ template in Web Mercator. `can_reproject`:
// an archive tileset (vts serve); a cache daemon's provided tilesets have no Web Mercator route
// for a WorldCRS84Quad grid and no OGC routes.
ordered_json index_entry(const std::string& name, const std::string& version,
                         const TilesetInfo& info, bool can_reproject, const RouterConfig& config,
                         const std::string& base) {
  const Geometry& g = info.geometry;
  const Tiling native = info.georeference ? info.georeference->tiling : Tiling::none;
  ordered_json e = {{"name", name},
                    {"version", version},
                    {"tilejson", base + "/" + name + ".json"},
                    {"width", g.width()},
                    {"height", g.height()},
                    {"max_zoom", g.max_zoom()},
                    {"codec", codec_name(info.codec)},
                    {"protected", is_protected(config, name)},
                    {"tiling", tiling_name(native)}};
  const bool web_mercator = native != Tiling::world_crs84_quad || can_reproject;
  if (web_mercator) {
    e["web_map"] = {{"tilejson", base + "/" + name + ".json?format=webp"},
                    {"tiling", native == Tiling::none ? "none" : "WebMercatorQuad"}};
  }
  if (native != Tiling::none && can_reproject) {
    const std::string xyz = native == Tiling::world_crs84_quad ? "/WebMercatorQuad" : "";
    ordered_json gis = ordered_json::object();
    if (!is_protected(config, name)) {  // the OGC routes offer no protected tileset (§15)
      gis["wmts"] = base + "/wmts/1.0.0/WMTSCapabilities.xml";
      gis["ogcapi"] = base + "/ogcapi/collections/" + name;
    }
    gis["xyz"] = base + "/" + name + xyz + "/{z}/{x}/{y}.png";
    gis["tilematrixset"] = base + "/" + name + "/tilematrixset.json";
    e["gis"] = std::move(gis);
  }
  return e;
}

HttpResponse index_route(const TilesetRegistry& registry, const AsyncTileProvider* provider,
                         const RouterConfig& config, const std::string& base) {
  std::map<std::string, ordered_json, std::less<>> entries;  // sorted by name
  if (provider != nullptr) {
    // Inserted first so that a registry tileset of the same name replaces it, as in lookups.
    for (const auto& t : provider->all()) {
      if (t) entries[t->name] = index_entry(t->name, t->version, t->info, false, config, base);
    }
  }
  for (const auto& t : registry.all()) {
    ordered_json e = index_entry(t->name, t->version, t->info, true, config, base);
    // A set has no one archive to download (its archives stay where they are stored).
    if (!t->is_set) e["archive"] = base + "/" + t->name + ".pmtiles";
    entries[t->name] = std::move(e);
  }
  ordered_json list = ordered_json::array();
  for (auto& [name, entry] : entries) list.push_back(std::move(entry));
  HttpResponse r;
  r.route = Route::index;
  set_owned(r, list.dump(2) + "\n", kJsonType);
  add(r, "Cache-Control", cache_control(false, kMetadataMaxAge, false));
  return r;
}

// TileJSON 3.0 for a tileset, archive or provided.
HttpResponse tilejson_response(const TileJsonFields& fields, bool priv) {
  HttpResponse r;
  r.route = Route::tilejson;
  set_owned(r, write_tilejson(fields), kJsonType);
  add(r, "Cache-Control", cache_control(priv, kMetadataMaxAge, false));
  return r;
}

HttpResponse tilejson_route(const Tileset& t, const std::string& base, bool priv) {
  const std::string tiles = base + "/" + t.name + "@" + t.version + "/{z}/{x}/{y}";
  const std::string archive = t.is_set ? std::string() : base + "/" + t.name + ".pmtiles";
  return tilejson_response({.tileset = t.name,
                            .info = &t.info,
                            .version = t.version,
                            .tiles_url = tiles,
                            .archive_url = archive},
                           priv);
}

// The OGC 2D Tile Matrix Set of a georeferenced tileset (tiling.hpp), with the caching of
// TileJSON; 404 for a plain image. Counted as route "tilejson" (a metadata document).
HttpResponse tile_matrix_set_route(const std::string& name, const TilesetInfo& info, bool priv) {
  if (!info.georeference) {
    HttpResponse r =
        error(404, "tileset \"" + name + "\" is not georeferenced: it has no tile matrix set");
    r.route = Route::tilejson;
    return r;
  }
  HttpResponse r;
  r.route = Route::tilejson;
  set_owned(
      r, tile_matrix_set_json(info.georeference->tiling, info.geometry, info.georeference->bounds),
      kJsonType);
  add(r, "Cache-Control", cache_control(priv, kMetadataMaxAge, false));
  return r;
}

HttpResponse archive_route(const HttpRequest& request, std::shared_ptr<const Tileset> t,
                           const RouterConfig& config, bool priv) {
  if (t->is_set) {
    HttpResponse e = error(404, "tileset \"" + t->name +
                                    "\" is a set of archives, not one: read its tiles, or its "
                                    "archives and tileset.json where they are stored");
    e.route = Route::archive;
    return e;
  }
  if (Status s = t->reader->check_unchanged(); !s) {
    HttpResponse e = archive_changed(std::move(t), s.error());
    e.route = Route::archive;
    return e;
  }
  const std::uint64_t size = t->reader->size();
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
    r.file_offset = range.first;
    r.content_length = range.last - range.first + 1;
  } else {
    r.content_length = size;
  }
  r.file_body = true;
  r.hold = std::move(t);
  return r;
}

// The tile's ETag and Cache-Control; 304 when `if_none_match` names the tag, else a 200 whose
// body the caller sets.
HttpResponse tag_response(std::uint64_t checksum, std::string_view if_none_match,
                          const std::string& cc) {
  // "<16 lowercase hex>" without printf: this runs for every tile and every 304.
  char etag[19];
  etag[0] = '"';
  for (int i = 0; i < 16; ++i) etag[1 + i] = "0123456789abcdef"[(checksum >> (60 - 4 * i)) & 0xf];
  etag[17] = '"';
  etag[18] = '\0';
  HttpResponse r;
  r.route = Route::tile;
  add(r, "ETag", etag);
  add(r, "Cache-Control", cc);
  if (none_match(if_none_match, etag)) r.status = 304;
  return r;
}

HttpResponse damaged_tile(int status, TileId id, std::string_view tileset, const Error& e) {
  return tile_error(status, "tile " + id.to_string() + " of " + std::string(tileset) +
                                " is damaged: " + e.to_string());
}

// 200 with a tile kept in memory (its bytes sent from `tile`'s buffer, which the response keeps)
// or 304 when `if_none_match` names its tag.
HttpResponse kept_tile_response(http_detail::CachedTilePtr tile, std::string_view if_none_match,
                                const std::string& cc) {
  HttpResponse r = tag_response(tile->checksum, if_none_match, cc);
  if (r.status == 304) return r;
  add(r, "Content-Type", kTileType);
  r.view = tile->bytes;
  r.content_length = r.view.size();
  r.keep = std::move(tile);
  return r;
}

std::int64_t coarse_now_ns() {
  return http_detail::DeadlineClock::now().time_since_epoch().count();
}

// The tile of `t` the cache keeps for `tile_id`, when it may answer: `t` is not known to be
// modified, and was verified unchanged less than `recheck` ago — or is now, by this call (one
// fstat, made by one request per interval; a change found marks `t` modified). Null otherwise
// (the lookup of an archive known to be modified is counted neither as a hit nor as a miss).
http_detail::CachedTilePtr fresh_cached_tile(http_detail::NativeTileCache& cache, const Tileset& t,
                                             std::uint64_t tile_id,
                                             std::chrono::milliseconds recheck) {
  if (t.modified.load(std::memory_order_relaxed)) return nullptr;
  const std::int64_t now = coarse_now_ns();
  std::int64_t seen = t.verified_ns.load(std::memory_order_relaxed);
  if (now - seen >= std::chrono::nanoseconds(recheck).count() &&
      t.verified_ns.compare_exchange_strong(seen, now, std::memory_order_relaxed)) {
    if (!t.reader->check_unchanged().ok()) {
      t.modified.store(true, std::memory_order_relaxed);
      return nullptr;
    }
  }
  return cache.find(t.generation, tile_id);
}

// 200 with the stored payload (a view: the caller keeps its bytes alive) or 304, with the ETag
// read from the payload's tile header frame; `damaged_status` when that frame does not parse
// (500 for our own archive, 502 for a provider's origin). The frame's checksum goes to `memo`.
HttpResponse payload_response(std::span<const std::uint8_t> payload, std::string_view if_none_match,
                              const std::string& cc, int damaged_status, TileId id,
                              std::string_view tileset, http_detail::TileTagMemo* memo = nullptr,
                              std::uint64_t tile_id = 0) {
  auto header = parse_tile_header(payload);
  if (!header) return damaged_tile(damaged_status, id, tileset, header.error());
  if (memo) memo->remember(tile_id, header->checksum);
  HttpResponse r = tag_response(header->checksum, if_none_match, cc);
  if (r.status == 304) return r;
  add(r, "Content-Type", kTileType);
  r.view = payload;
  r.content_length = r.view.size();
  return r;
}

}  // namespace

namespace router_detail {

HttpResponse stored_tile_answer(std::shared_ptr<const Tileset> t, TileId id,
                                Result<std::vector<std::uint8_t>> payload,
                                std::string_view if_none_match, const std::string& cc,
                                http_detail::NativeTileCache* cache) {
  if (!payload) return unreadable_tile(std::move(t), id, payload.error(), cc);
  auto header = parse_tile_header(*payload);
  if (!header) return damaged_tile(500, id, t->name, header.error());
  const std::uint64_t tile_id = archive::zxy_to_tile_id(id.z, id.x, id.y);
  if (t->tags) t->tags->remember(tile_id, header->checksum);
  auto tile = std::make_shared<http_detail::CachedTile>(
      http_detail::CachedTile{std::move(*payload), header->checksum});
  if (cache != nullptr && !t->remote) {
    // Read whole and verified unchanged after the read (archive::Reader::get): it may be kept,
    // unless the archive is already known to have changed.
    t->verified_ns.store(coarse_now_ns(), std::memory_order_relaxed);
    if (!t->modified.load(std::memory_order_relaxed)) cache->insert(t->generation, tile_id, tile);
  }
  HttpResponse r = kept_tile_response(std::move(tile), if_none_match, cc);
  r.hold = std::move(t);  // names the tileset in access logs
  return r;
}

HttpResponse stored_read_plan(
    std::shared_ptr<const Tileset> t, TileId id, const HttpRequest& request, const std::string& cc,
    std::function<HttpResponse(Result<std::vector<std::uint8_t>>)> answer) {
  auto plan = std::make_shared<PendingAnswer>();
  plan->stored = t;
  plan->answer_stored = std::move(answer);
  plan->id = id;
  plan->if_none_match = std::string(request.if_none_match);
  plan->cache_control = cc;
  plan->connection = request.connection;
  HttpResponse r;
  r.route = Route::tile;
  r.hold = std::move(t);
  r.pending = std::move(plan);
  return r;
}

}  // namespace router_detail

namespace {

HttpResponse tile_route(const HttpRequest& request, std::shared_ptr<const Tileset> t,
                        std::string_view version, std::span<const std::string_view> zxy,
                        const RouterConfig& config, bool priv) {
  if (!version.empty() && version != t->version) {
    return not_current(version, t->name, t->version);
  }
  const auto z = parse_u32(zxy[0]), x = parse_u32(zxy[1]), y = parse_u32(zxy[2]);
  if (!z || !x || !y) return error(400, "tile address must be /{tileset}/{z}/{x}/{y} in decimal");
  const Geometry& g = t->info.geometry;
  if (*z > static_cast<std::uint32_t>(g.max_zoom())) return outside_pyramid(*z, *x, *y, t->name);
  const TileId id{static_cast<std::uint8_t>(*z), *x, *y};
  if (*x >= g.tiles_x(id.z) || *y >= g.tiles_y(id.z)) return outside_pyramid(*z, *x, *y, t->name);

  const std::string cc = version.empty() ? cache_control(priv, config.max_age_seconds, false)
                                         : cache_control(priv, kImmutableMaxAge, true);
  const std::uint64_t tile_id = archive::zxy_to_tile_id(id.z, id.x, id.y);
  http_detail::NativeTileCache* cache = t->remote ? nullptr : config.tile_cache.get();
  if (cache != nullptr) {
    // A hot tile: no read, no stat (the archive is re-checked once per recheck interval).
    if (auto kept = fresh_cached_tile(*cache, *t, tile_id, config.tile_cache_recheck)) {
      HttpResponse r = kept_tile_response(std::move(kept), request.if_none_match, cc);
      r.hold = std::move(t);
      return r;
    }
  }
  http_detail::TileTagMemo* memo =
      t->modified.load(std::memory_order_relaxed) ? nullptr : t->tags.get();
  if (!request.if_none_match.empty() && memo) {
    // A tag read before from this file answers without touching it.
    if (auto known = memo->find(tile_id)) {
      HttpResponse r = tag_response(*known, request.if_none_match, cc);
      if (r.status == 304) {
        r.hold = std::move(t);
        return r;
      }
    }
  }
  if (!request.if_none_match.empty() && !t->remote) {
    // The ETag is in the tile's header frame: read that first, the whole payload only when the
    // client's copy is not current. (From a store, where each read is a request, the payload is
    // read once.)
    auto entry = t->reader->find_entry(tile_id);
    if (!entry) return unreadable_tile(std::move(t), id, entry.error(), cc);
    std::array<std::uint8_t, TileHeader::kFrameBytes> frame;
    const std::span<std::uint8_t> head(frame.data(),
                                       std::min<std::size_t>(frame.size(), entry->length));
    Status read = t->reader->read(t->reader->header().tile_data_offset + entry->offset, head);
    if (!read) return unreadable_tile(std::move(t), id, read.error(), cc);
    HttpResponse r =
        payload_response(head, request.if_none_match, cc, 500, id, t->name, memo, tile_id);
    if (r.status != 200) {  // 304, or a damaged header frame
      r.hold = std::move(t);
      return r;
    }
  }
  // A request to a store: the answer pipeline reads it off the I/O thread.
  if (t->remote) return stored_read_plan(std::move(t), id, request, cc);
  auto payload = t->reader->get(id);
  return stored_tile_answer(std::move(t), id, std::move(payload), request.if_none_match, cc, cache);
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
    return not_current(version, t->name, t->version.empty() ? "unknown" : t->version);
  }
  const auto z = parse_u32(zxy[0]), x = parse_u32(zxy[1]), y = parse_u32(zxy[2]);
  if (!z || !x || !y) return error(400, "tile address must be /{tileset}/{z}/{x}/{y} in decimal");
  const Geometry& g = t->info.geometry;
  if (*z > static_cast<std::uint32_t>(g.max_zoom()) ||
      *x >= g.tiles_x(static_cast<std::uint8_t>(*z)) ||
      *y >= g.tiles_y(static_cast<std::uint8_t>(*z))) {
    return outside_pyramid(*z, *x, *y, t->name);
  }
  auto p = std::make_shared<PendingAnswer>();
  p->id = TileId{static_cast<std::uint8_t>(*z), *x, *y};
  p->if_none_match = std::string(request.if_none_match);
  p->cache_control = cache_control(priv, config.max_age_seconds, false);
  p->provided = std::move(t);
  p->connection = request.connection;
  HttpResponse r;
  r.route = Route::tile;
  r.pending = std::move(p);
  return r;
}

HttpResponse provided_tilejson_route(const ProvidedTileset& t, const std::string& base, bool priv) {
  const std::string tiles = base + "/" + t.name + "/{z}/{x}/{y}";
  return tilejson_response(
      {.tileset = t.name, .info = &t.info, .version = t.version, .tiles_url = tiles}, priv);
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

// The address a path names: /{ts}.json, /{ts}.pmtiles, /{ts}/tilematrixset.json or
// /{ts}[@{version}]/{z}/{x}/{y}.
struct Address {
  enum class Kind { tile, tilejson, archive, tile_matrix_set } kind = Kind::tile;
  std::string_view name;
  std::string_view version;
  std::vector<std::string_view> segments;
  std::optional<imaging::WebFormat> web;  // /{ts}/{z}/{x}/{y}.{ext}: a web image (router_web.cpp)
  bool web_mercator = false;              // /{ts}/WebMercatorQuad/{z}/{x}/{y}.{ext}
  std::span<const std::string_view> zxy() const {
    return std::span<const std::string_view>(segments).subspan(1);
  }
};

// nullopt when `path` (not "/") is an address; else the 400 or 404.
std::optional<HttpResponse> parse_address(std::string_view path, Address& a) {
  std::string why;
  if (!split_segments(path, a.segments, why)) return error(400, why);
  if (a.segments.size() == 1) {
    const std::string_view s = a.segments[0];
    if (s.ends_with(".json")) {
      a.kind = Address::Kind::tilejson;
      a.name = s.substr(0, s.size() - 5);
    } else if (s.ends_with(".pmtiles")) {
      a.kind = Address::Kind::archive;
      a.name = s.substr(0, s.size() - 8);
    } else {
      return error(404,
                   "no such resource; try /, /{tileset}.json, /{tileset}.pmtiles, "
                   "/{tileset}/tilematrixset.json, /{tileset}/{z}/{x}/{y} or "
                   "/{tileset}/{z}/{x}/{y}.png|.webp|.jpg");
    }
    return std::nullopt;
  }
  if (a.segments.size() == 2 && a.segments[1] == "tilematrixset.json") {
    a.kind = Address::Kind::tile_matrix_set;
    a.name = a.segments[0];
    return std::nullopt;
  }
  if (a.segments.size() == 5 && a.segments[1] == "WebMercatorQuad") {
    a.web_mercator = true;
    a.segments.erase(a.segments.begin() + 1);
    if (a.segments[3].find('.') == std::string_view::npos) {
      return error(400,
                   "a WebMercatorQuad tile is an image: /{tileset}/WebMercatorQuad/{z}/{x}/{y}"
                   ".png, .webp or .jpg");
    }
  }
  if (a.segments.size() != 4) return error(400, "tile address must be /{tileset}/{z}/{x}/{y}");
  a.name = a.segments[0];
  if (const std::size_t at = a.name.find('@'); at != std::string_view::npos) {
    a.version = a.name.substr(at + 1);
    a.name = a.name.substr(0, at);
    if (a.version.empty()) return error(400, "empty version after '@'");
  }
  if (const std::size_t dot = a.segments[3].find('.'); dot != std::string_view::npos) {
    const std::string_view ext = a.segments[3].substr(dot + 1);
    a.segments[3] = a.segments[3].substr(0, dot);
    if (ext == "png") a.web = imaging::WebFormat::png;
    if (ext == "webp") a.web = imaging::WebFormat::webp;
    if (ext == "jpg" || ext == "jpeg") a.web = imaging::WebFormat::jpeg;
    if (!a.web) {
      return error(400, "unknown tile image extension \"." + std::string(ext) +
                            "\"; use .png, .webp or .jpg (or no extension for the native tile)");
    }
  }
  for (std::size_t i = 1; i < 4; ++i) {
    if (!parse_u32(a.segments[i])) {
      return error(400,
                   "tile address must be /{tileset}/{z}/{x}/{y} with decimal numbers "
                   "(no signs or leading zeros)");
    }
  }
  return std::nullopt;
}

HttpResponse serve_provided(const HttpRequest& request, std::shared_ptr<const ProvidedTileset> t,
                            const Address& a, const RouterConfig& config, const std::string& base,
                            bool priv) {
  switch (a.kind) {
    case Address::Kind::tilejson:
      return provided_tilejson_route(*t, base, priv);
    case Address::Kind::tile_matrix_set:
      return tile_matrix_set_route(t->name, t->info, priv);
    case Address::Kind::archive: {
      HttpResponse r = error(404, "tileset \"" + t->name +
                                      "\" is served from a cache and has no archive here; use /" +
                                      t->name + "/{z}/{x}/{y}");
      r.route = Route::archive;
      return r;
    }
    case Address::Kind::tile:
      break;
  }
  return provided_tile_route(request, std::move(t), a.version, a.zxy(), config, priv);
}

HttpResponse serve_archive(const HttpRequest& request, std::shared_ptr<const Tileset> t,
                           const Address& a, const RouterConfig& config, const std::string& base,
                           bool priv) {
  switch (a.kind) {
    case Address::Kind::tilejson:
      return tilejson_route(*t, base, priv);
    case Address::Kind::tile_matrix_set:
      return tile_matrix_set_route(t->name, t->info, priv);
    case Address::Kind::archive:
      return archive_route(request, std::move(t), config, priv);
    case Address::Kind::tile:
      break;
  }
  return tile_route(request, std::move(t), a.version, a.zxy(), config, priv);
}

// Web images of a provided tileset (vts cache serve): the tile comes from the provider
// (a pending answer), then is encoded as for archives (provided_web_image). Not versioned as
// immutable, as its native tiles. WebMercatorQuad resampling is not served from a provider.
HttpResponse provided_web(const HttpRequest& request, std::shared_ptr<const ProvidedTileset> t,
                          const Target& target, const Address& a, const RouterConfig& config,
                          const std::string& base, bool priv) {
  if (a.kind == Address::Kind::tilejson) {
    HttpResponse r = error(400, "tiling= needs format=png, webp or jpg");
    if (!target.query.format) {
      r.route = Route::tilejson;
      return r;
    }
    return web_tilejson_route(t->name, t->info, t->version, false, target.query, base, priv, false);
  }
  if (a.web_mercator) {
    return tile_error(404, "tileset \"" + t->name +
                               "\" is served from a cache: WebMercatorQuad tiles are served by "
                               "vts serve only");
  }
  if (!a.version.empty() && (t->version.empty() || a.version != t->version)) {
    return not_current(a.version, t->name, t->version.empty() ? "unknown" : t->version);
  }
  const Geometry& g = t->info.geometry;
  std::optional<HttpResponse> rejection;
  const auto tile = web_tile_id(a.zxy(), g, t->name, rejection);
  if (!tile) return std::move(*rejection);
  const TileId id = *tile;
  if (config.web.cache) {
    config.web.cache->requests_by_format[static_cast<std::size_t>(*a.web)].fetch_add(
        1, std::memory_order_relaxed);
  }
  const std::string cc = cache_control(priv, config.max_age_seconds, false);
  if (!g.exists(id))
    return web_filler(g.tile_size(), *a.web, config, request.if_none_match, cc, request.connection);
  auto p = std::make_shared<PendingAnswer>();
  p->id = id;
  p->if_none_match = std::string(request.if_none_match);
  p->cache_control = cc;
  p->provided = std::move(t);
  p->web = *a.web;
  p->web_options = config.web.encode;
  p->cache = config.web.cache;
  p->connection = request.connection;
  HttpResponse r;
  r.route = Route::tile;
  r.pending = std::move(p);
  return r;
}

// Whether a request asks for an image and not our tile codec: a browser's <img> or a web map's
// tile fetch (Accept: image/webp,*/*, ...). Our clients send */* or name kTileType.
bool wants_image(std::string_view accept) {
  return icontains(accept, "image/") && !icontains(accept, kTileType);
}

// 406 for a native tile asked as an image, naming the routes that answer images. Not cached
// (error()'s no-store): the 200 a cache may hold for the same URL is right for every other client,
// so native tiles need no Vary: Accept.
HttpResponse image_not_acceptable(std::string_view name, std::span<const std::string_view> zxy) {
  const std::string ts(name);
  const std::string tile =
      std::string(zxy[0]) + "/" + std::string(zxy[1]) + "/" + std::string(zxy[2]);
  HttpResponse r = error(406, "/" + ts + "/" + tile + " is a vtstream tile (" + kTileType +
                                  "), not an image; web maps take /" + ts +
                                  ".json?format=webp (a TileJSON of images) or the images "
                                  "themselves, /" +
                                  ts + "/" + tile + ".png, .webp or .jpg");
  r.route = Route::tile;
  return r;
}

// Looks the address up (archives first, then the provider), checks credentials, answers.
HttpResponse serve_address(const HttpRequest& request, const Target& target, const Address& a,
                           const TilesetRegistry& registry, const RouterConfig& config,
                           const AsyncTileProvider* provider, const std::string& base) {
  auto t = registry.find(a.name);
  std::shared_ptr<const ProvidedTileset> provided;
  if (!t && provider != nullptr) provided = provider->find(a.name);
  if (!t && !provided) return error(404, "no tileset named \"" + std::string(a.name) + "\"");
  const bool priv = is_protected(config, a.name);
  if (priv) {
    const TilesetAccess& access = config.access.find(a.name)->second;
    if (auto denied = check_access(access, request, target.raw_path, target.query, config)) {
      return *denied;
    }
  }
  const bool web =
      a.web || (a.kind == Address::Kind::tilejson && (target.query.format || target.query.tiling));
  if (web && provided)
    return provided_web(request, std::move(provided), target, a, config, base, priv);
  if (web && a.kind == Address::Kind::tilejson) {
    if (!target.query.format) {
      HttpResponse r = error(400, "tiling= needs format=png, webp or jpg");
      r.route = Route::tilejson;
      return r;
    }
    return web_tilejson_route(t->name, t->info, t->version, true, target.query, base, priv, true);
  }
  if (web && a.web_mercator) {
    return web_mercator_tile_route(request, std::move(t), a.version, a.zxy(), *a.web, config, priv);
  }
  if (web) return web_tile_route(request, std::move(t), a.version, a.zxy(), *a.web, config, priv);
  if (a.kind == Address::Kind::tile && wants_image(request.accept)) {
    return image_not_acceptable(a.name, a.zxy());
  }
  if (provided) return serve_provided(request, std::move(provided), a, config, base, priv);
  return serve_archive(request, std::move(t), a, config, base, priv);
}

HttpResponse dispatch(const HttpRequest& request, const TilesetRegistry& registry,
                      const RouterConfig& config, const AsyncTileProvider* provider) {
  if (request.method == HttpMethod::other) {
    HttpResponse r = error(405, "method not allowed; use GET, HEAD or OPTIONS");
    add(r, "Allow", kAllowedMethods);
    return r;
  }
  if (request.method == HttpMethod::options && request.target == "*") return preflight(request);
  std::optional<HttpResponse> rejection;
  const auto target = parse_target(request.target, config.max_target_bytes, rejection);
  if (!target) return std::move(*rejection);
  if (request.method == HttpMethod::options) return preflight(request);

  const std::string base = base_url(request, config);
  if (config.public_base_url.empty() && !request.host.empty() && !valid_host(request.host)) {
    return error(400, "malformed Host header");
  }
  if (auto page = web_page(request, *target, registry, config, provider)) return std::move(*page);
  if (target->path == "/") {
    HttpResponse r = index_route(registry, provider, config, base);
    add(r, "Vary", "Accept");  // a browser gets the HTML index (router_web_page.cpp)
    return r;
  }
  if (auto wmts = wmts_route(request, *target, registry, config, base)) return std::move(*wmts);
  if (auto ogc = ogcapi_route(request, *target, registry, config, base)) return std::move(*ogc);
  Address a;
  if (auto bad = parse_address(target->path, a)) return std::move(*bad);
  return serve_address(request, *target, a, registry, config, provider, base);
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
    case Route::admin:
      return "admin";
    case Route::viewer:
      return "viewer";
  }
  return "error";
}

namespace {

// The CORS headers of every response of the tile listener (§8).
void add_cors(HttpResponse& r, const RouterConfig& config) {
  if (config.cors_origin.empty()) return;
  add(r, "Access-Control-Allow-Origin", config.cors_origin);
  if (config.cors_origin != "*") add(r, "Vary", "Origin");
  if (r.route != Route::preflight) {
    add(r, "Access-Control-Expose-Headers", "ETag, Content-Range, Content-Length");
  }
}

}  // namespace

HttpResponse unparsed_request_error(int status, std::string message, const RouterConfig* config) {
  HttpResponse r = error(status, std::move(message));
  if (config != nullptr) add_cors(r, *config);
  return r;
}

HttpResponse route(const HttpRequest& request, const TilesetRegistry& registry,
                   const RouterConfig& config, const AsyncTileProvider* provider) {
  HttpResponse r = dispatch(request, registry, config, provider);
  add_cors(r, config);
  if (request.method == HttpMethod::head) r.head_only = true;
  // 204 and 304 carry no body by definition (RFC 9110 §15.3.5, §15.4.5).
  if (r.status == 204 || r.status == 304) {
    r.owned.clear();
    r.view = {};
    r.content_length = 0;
  }
  return r;
}

namespace router_detail {

HttpResponse answer_provided(const PendingAnswer& p, ProvidedTile tile) {
  const std::string& name = p.provided->name;
  const bool web_ok =
      p.web && (tile.kind == ProvidedTile::Kind::ok ||
                (tile.kind == ProvidedTile::Kind::absent && p.provided->info.sparse));
  if (web_ok) {
    const std::vector<std::uint8_t> bytes(tile.payload.begin(), tile.payload.end());
    return provided_web_image(p, tile.kind == ProvidedTile::Kind::ok ? &bytes : nullptr);
  }
  HttpResponse r;
  switch (tile.kind) {
    case ProvidedTile::Kind::unavailable:
      r = error(503, "tile " + p.id.to_string() + " of " + name +
                         " is not cached and its origin is unavailable" +
                         (tile.message.empty() ? std::string() : ": " + tile.message));
      break;
    case ProvidedTile::Kind::ok:
      r = payload_response(tile.payload, p.if_none_match, p.cache_control, 502, p.id, name);
      if (r.status == 200) r.keep = std::move(tile.keep);
      break;
    case ProvidedTile::Kind::absent:
      if (p.provided->info.sparse) {
        r.status = 204;  // known-empty: cacheable like a tile
        add(r, "Cache-Control", p.cache_control);
      } else {
        r = error(404, "tile " + p.id.to_string() + " is missing from the origin of " + name +
                           " (origin incomplete)");
      }
      break;
    case ProvidedTile::Kind::bad_origin:
      r = error(502, "the origin of " + name + " sent an unusable tile " + p.id.to_string() +
                         (tile.message.empty() ? std::string() : ": " + tile.message));
      break;
  }
  return r;
}

}  // namespace router_detail

}  // namespace server
}  // namespace vts
