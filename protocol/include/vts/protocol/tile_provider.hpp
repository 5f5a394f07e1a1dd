// Tilesets whose tiles come from elsewhere, asynchronously (the cache daemon, `vts cache serve`):
// the interface between an HTTP front (the server's router, which implements the HTTP semantics)
// and whatever holds the tiles (the client's cache). It lives here so that both sides implement
// it without depending on each other.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <stop_token>
#include <string>
#include <string_view>
#include <vector>

#include "vts/protocol/geometry.hpp"
#include "vts/protocol/tileset.hpp"

namespace vts {
inline namespace protocol {

// A server may host, besides the archives of its registry, tilesets whose tiles come from
// elsewhere, asynchronously: an AsyncTileProvider. The router answers everything it can for them
// synchronously (index, TileJSON, target validation, access control, pyramid bounds) and hands
// back a *deferred* tile response; the network layer asks the provider for the tile and, when the
// provider calls back, finishes the response with complete_deferred() (vts/server/router.hpp). So
// the HTTP semantics of a provided tile (ETag from the payload's header frame, 304, Cache-Control,
// 204/404 for absent tiles, CORS, HEAD) are the router's, exactly as for an archive tile. A
// registry tileset hides a provided one of the same name.

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
  //
  // `abandon` is requested when nobody waits for the answer any more (the HTTP front requests it
  // when the client's connection ends, from the connection's thread): the provider should then
  // give up the work done for this request alone (e.g. cancel an upstream fetch no other request
  // shares) and call `done` soon, with any answer (it is dropped). A stop callback the provider
  // registers on it runs on the requesting thread, must not block, and must not be destroyed
  // while holding a lock that callback takes (std::stop_callback's destructor waits for it).
  virtual void tile(const std::shared_ptr<const ProvidedTileset>& tileset, TileId id,
                    std::function<void(ProvidedTile)> done, std::stop_token abandon = {}) = 0;
  // Extra Prometheus text appended to the server's /metrics (e.g. cache counters); may be empty.
  virtual std::string metrics_text() const { return {}; }
  // Empty while the provider works as it should; else one line (no newline) saying what is
  // wrong although it still serves (e.g. its disk cache cannot write): /health then answers
  // 503 "degraded: <line>". Called for every /health request, from any thread. Must not block.
  virtual std::string health_problem() const { return {}; }
};

}  // namespace protocol
}  // namespace vts
