// Where tiles come from, behind one asynchronous interface: a local archive (pread), a tile server
// described by TileJSON (`vts serve` or any server with our tiles), or a remote PMTiles archive
// read with HTTP range requests (from `vts serve`'s .pmtiles route, nginx or an object store —
// no tile server needed). The client stack (TileClient) decorates a source with caches,
// prefetching and decoding; sources themselves keep no tile cache.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/client/fetcher.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/protocol/tileset.hpp"
#include "vts/protocol/tiling.hpp"

namespace vts::client {

struct SourceInfo {
  TilesetInfo info;
  // Stable identity of the tileset for cache keys: the same for every run and every version of
  // the tileset (e.g. "http://host:8080/earth" for TileJSON at http://host:8080/earth.json, the
  // URL of a remote archive, or "file:" + the absolute path of a local one).
  std::string key;
  // The tileset's current version as the source knows it (archive version / content hash);
  // empty when unknown. Informational: tiles are revalidated by ETag.
  std::string version;
  // The source's own description, JSON (TileJSON for HTTP sources, the archive's metadata for
  // archives): what a cache stores so the tileset can be opened offline.
  std::string description_json;
  // Standard image tiles of a third-party server or archive (an XYZ/TMS template, a TileJSON
  // without our "vtstream" object, a stock PMTiles archive): "png", "jpeg", "webp", or "image"
  // when the source does not say. Their payloads are the server's bytes as they came: no tile
  // header, no checksum. Empty for our tiles. Such a tileset's `info` is a WebMercatorQuad
  // pyramid of `image_tile_size` px tiles without border, georeferenced to the source's bounds.
  std::string image_format;
  std::uint32_t image_tile_size = 0;
  int min_zoom = 0;  // coarser levels have no tiles (image tilesets; 0 for ours)
};

struct SourceRequest {
  TileId id;
  std::string if_none_match;  // the cached tile's ETag, for revalidation
  int level = 0;              // fetch order: lower level first ...
  double urgency = 0;         // ... then higher urgency
};

// What the HTTP exchange behind a tile cost, for sources that fetch one URL per tile (TileJSON
// sources: `vts serve`, a cache daemon, a CDN); the load test reports it per request.
struct SourceTransfer {
  int status = 0;           // the final HTTP status (0: no response)
  std::uint64_t bytes = 0;  // response body bytes
  int attempts = 0;         // attempts the fetcher started (retries included)
  // From the fetch's submission: until it went on the wire, until its first response byte (0:
  // none), until it ended (FetchResult::Timing).
  std::chrono::nanoseconds queued{0}, first_byte{0}, total{0};
};

struct SourceTile {
  enum class Kind {
    ok,            // payload + etag
    not_modified,  // the ETag sent is still current
    absent,        // no such tile (404 / 204 / not in the archive)
    error,         // error is set
    cancelled,
  };
  Kind kind = Kind::error;
  std::vector<std::uint8_t> payload;  // the stored tile bytes, exactly as in the archive
  // The validator to revalidate with, quoted as HTTP sends it: the archive sources' tile_etag();
  // the TileJSON source's server's ETag header, empty when it sent none.
  std::string etag;
  std::optional<Error> error;
  std::optional<SourceTransfer> transfer;  // set by sources that made one HTTP request for it
  // Seconds the tile stays fresh, from the response's Cache-Control (cache_control_lifetime());
  // -1 when the source does not know (no header, a local archive).
  std::int64_t fresh_for = -1;
};

// "Fresh for ever": what `immutable` means to a cache (cache_control_lifetime()).
inline constexpr std::int64_t kFreshForever = std::int64_t{1} << 40;

// The freshness lifetime a Cache-Control header value gives a cached response, in seconds:
// no-store / no-cache / must-revalidate with max-age=0 → 0 (revalidate at every use); immutable
// → kFreshForever; max-age=N → N; none of these (or an empty value) → -1, "not said".
// Directives are case-insensitive and comma-separated; s-maxage and unknown ones are ignored.
std::int64_t cache_control_lifetime(std::string_view value);

using SourceCallback = std::function<void(SourceTile&&)>;

class TileSource {
 public:
  virtual ~TileSource() = default;
  virtual const SourceInfo& info() const = 0;
  // True when reading a tile costs no network (a local archive): the client then reads it on its
  // disk budget instead of its network budget.
  virtual bool local() const = 0;
  // Asynchronous: the callback runs exactly once, on a thread of the source (the fetcher's for
  // remote sources, or a remote source's own delivery thread for answers it knows without the
  // network; a local source runs it before fetch() returns). It must not block. A remote source
  // never runs it inside fetch() or cancel(). Payloads are not verified here (the client
  // verifies checksums when decoding). The archive sources (local and remote) read the ETag from
  // the payload's tile header, as `vts serve` does, so for them a payload without a valid header
  // frame is an error (corrupt) where the server answers 500; the TileJSON source reports the
  // server's ETag. A remote archive judges If-None-Match itself after reading the tile's bytes:
  // not_modified there saves the copy and the decode, not the range read.
  using Handle = std::uint64_t;
  virtual Handle fetch(const SourceRequest& request, SourceCallback callback) = 0;
  // The callback then runs with Kind::cancelled unless it has already run. Thread-safe.
  virtual void cancel(Handle h) = 0;
};

// The default of SourceOptions::max_download (and of `--max-download`): 256 MiB.
inline constexpr std::uint64_t kDefaultMaxDownload = std::uint64_t{256} << 20;

struct SourceOptions {
  FetcherOptions fetcher;  // for HTTP sources
  // A remote archive whose host ignores Range (answers 200 with the whole file, e.g.
  // `python3 -m http.server`) is downloaded once, by the opening read, and held in memory when it
  // is at most this many bytes; every tile is then read from that copy. A bigger one fails to
  // open (unsupported, naming the host's behaviour) as soon as its size is known. 0: never.
  std::uint64_t max_download = kDefaultMaxDownload;
  // Extra headers (e.g. "Authorization: Bearer ...") go in fetcher.headers.

  // For image tilesets (an XYZ/TMS template says nothing of itself): the area with tiles
  // (default: the whole Web Mercator square) and the zoom range (a template needs max_zoom; a
  // TileJSON or archive says its own, which these override when set). Tiles outside them are
  // absent without a request.
  std::optional<LonLatBounds> bounds;
  int min_zoom = -1, max_zoom = -1;
  std::uint32_t tile_size = 256;  // a template's tile size in pixels
  // open_source() refuses image tilesets (unsupported), for users that serve our tiles only
  // (the cache daemon).
  bool vtstream_only = false;
};

// Where an image tileset's tiles are and what they are: a template's or TileJSON's layout.
struct ImageLayout {
  std::string tiles;  // URL template with {z}, {x} and {y} or {-y}
  // More templates of the same tiles (a TileJSON's further "tiles"). Requests are spread over all
  // of them, each with {s} taken as the hosts a, b, c and a range {a-c} or {1-4} as its hosts, a
  // tile always to the same one: (x + y) modulo their number, as web maps pick.
  std::vector<std::string> mirrors;
  bool tms = false;  // {y} counts rows from the south (TileJSON "scheme": "tms")
  int min_zoom = 0, max_zoom = -1;
  LonLatBounds bounds = {-180, -kWebMercatorMaxLat, 180, kWebMercatorMaxLat};
  std::uint32_t tile_size = 256;
  std::string format;  // "png", "jpeg", "webp", or "image"
};
// The SourceInfo of an image tileset (see SourceInfo::image_format): invalid_argument naming the
// field for a zoom range outside 0..24 or upside down, bounds that are not a box, a tile size that
// is not a power of two in 64..1024.
Result<SourceInfo> image_source_info(const ImageLayout& layout, std::string key,
                                     std::string description_json);
// Whether an image tileset has tile `id`: inside its zoom range and its bounds.
bool image_tile_exists(const SourceInfo& info, TileId id);

// Opens `location`:
//   - a path to a *.pmtiles file (or file:///path)                → local archive;
//   - an http(s) URL ending in .pmtiles                           → remote archive, range reads;
//   - an http(s) URL with {z} in it (https://host/{z}/{x}/{y}.png; {-y}: TMS rows; {s} or
//     {a-c}: hosts, see ImageLayout::mirrors) → an XYZ template of image tiles, laid out by
//     options' bounds and zoom range (max_zoom required);
//   - an http(s) URL ending in .json                              → TileJSON;
//   - any other http(s) URL (e.g. http://host:8080/earth)         → TileJSON at URL + ".json".
// The suffix is judged on the URL's path (a query such as an object store's signature is kept and
// sent). file: URLs are file:///path or file://localhost/path, percent-encoded; another scheme
// ("s3://") is invalid_argument. Blocks while it fetches the TileJSON or the archive header and
// root directory. Errors name the location and what was wrong (unreachable, not an archive, not
// our tileset, bad TileJSON...): not_found for a missing file, tileset or archive (HTTP 404), io
// for an unreachable server or another HTTP status, corrupt for bytes that are not TileJSON or
// PMTiles. A TileJSON without our "vtstream" object (TileJSON 2.x/3.0: "tiles", "minzoom",
// "maxzoom", "bounds", "scheme") and a PMTiles archive (local or remote) without it whose tile type
// is png, jpeg or webp (image_tiles.hpp) open as image tilesets; other archives and TileJSON
// without it are unsupported.
//
// A TileJSON source follows a rebuilt tileset: when a versioned tile URL answers 404 "not
// current", it refetches the TileJSON, moves to its new tile URLs and retries the tile. info()
// keeps describing the tileset as opened; a rebuild that changed the geometry or codec makes
// tiles fail (unsupported) until the tileset is opened again.
Result<std::unique_ptr<TileSource>> open_source(std::string_view location,
                                                SourceOptions options = {});

// An image tileset fetched one URL per tile (an XYZ/TMS template or a third-party TileJSON):
// 200 is the tile, 204 absent, another status (404 included: the layout says the tile exists)
// an error naming it. Tiles outside the layout's zoom range and bounds are absent at once.
Result<std::unique_ptr<TileSource>> open_image_template(const ImageLayout& layout, std::string key,
                                                        std::string description_json,
                                                        SourceOptions options = {});

// The three kinds of source, for callers that know which one they want (open_source picks one
// from the location's form). Same blocking and error behaviour as open_source().
// A local stock raster archive opens as an image tileset, as a remote one does; options' bounds
// and zoom range apply to it alone.
Result<std::unique_ptr<TileSource>> open_local_archive(const std::filesystem::path& path,
                                                       const SourceOptions& options = {});
// An archive or a set in an object store or on a web server read by ranged GETs (store/open.hpp):
// s3://bucket/key.pmtiles, s3://bucket/set/tileset.json, https://host/set/tileset.json. Reads
// are synchronous, as for a local archive; credentials and endpoint from the AWS environment.
Result<std::unique_ptr<TileSource>> open_store_archive(const std::string& location);
Result<std::unique_ptr<TileSource>> open_tilejson(std::string_view url, SourceOptions options = {});
Result<std::unique_ptr<TileSource>> open_remote_archive(std::string_view url,
                                                        SourceOptions options = {});

// The ETag `vts serve` sends for a stored tile: '"' + 16 lowercase hex digits of the XXH3-64
// checksum in the payload's tile header frame + '"'; the tag the archive sources report, and the
// one `vts serve` and the cache daemon serve. corrupt when the payload has no valid header frame.
Result<std::string> tile_etag(std::span<const std::uint8_t> payload);
// If-None-Match comparison as `vts serve` does it (RFC 9110 §13.1.2, weak): `header` is a list
// of entity tags (W/ prefixes ignored) or "*"; false when empty.
bool etag_matches(std::string_view header, std::string_view etag);

// A source rebuilt from a SourceInfo a cache kept, for when the network is gone: every fetch
// answers Kind::error (io, "offline: ...") before fetch() returns, and local() is true (it costs
// no network). Lets the client serve what its caches hold.
std::unique_ptr<TileSource> offline_source(SourceInfo info);

}  // namespace vts::client
