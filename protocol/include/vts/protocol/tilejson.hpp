// TileJSON 3.0 with our "vtstream" object: how a tile server describes a tileset to clients
// (docs/PROTOCOL.md §5). The server writes it; the client's HTTP source reads it.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "vts/base/result.hpp"
#include "vts/protocol/tileset.hpp"

namespace vts {
inline namespace protocol {

// A 404 for a versioned tile URL whose version is no longer current carries this header and
// value (the body keeps a human message): the client then refetches the TileJSON.
inline constexpr const char* kVtsErrorHeader = "Vts-Error";
inline constexpr std::string_view kVersionNotCurrent = "version-not-current";

// What a writer puts in a TileJSON document.
struct TileJsonFields {
  std::string_view tileset;           // the tileset's name, used when info.name is empty
  const TilesetInfo* info = nullptr;  // required
  std::string_view version;           // the archive version ("" = unknown)
  std::string_view tiles_url;         // the one URL template, with {z}, {x} and {y}
  std::string_view archive_url;       // "" = no "archive" key in the "vtstream" object
};

// The document, pretty-printed (two-space indent) with a trailing newline. Its "vtstream" object
// is the one info.to_json() writes (plus "archive"): made from what this build read of the
// archive's metadata, never copied from it, so keys it does not know do not travel. Invalid UTF-8
// in strings is replaced, never an error.
std::string write_tilejson(const TileJsonFields& fields);

// What a reader takes from a TileJSON document.
struct TileJson {
  TilesetInfo info;
  std::string tiles;    // "tiles"[0], resolved against the document's URL
  std::string version;  // "" when the document has none
};

// Parses a TileJSON document fetched from `url` (used to resolve a relative "tiles" entry and to
// name the document in errors). Errors: corrupt (not valid JSON, objects or arrays nested deeper
// than parse_json() allows, not a JSON object, no "tiles" array of non-empty strings, a template
// without {z}, {x} or {y}), unsupported (no "vtstream" object), and whatever TilesetInfo says of
// the "vtstream" object's keys it knows (the others are ignored).
Result<TileJson> read_tilejson(std::span<const std::uint8_t> body, const std::string& url);

// Resolves a reference against a base URL (RFC 3986 §5.2, for the forms that occur in TileJSON:
// absolute, scheme-relative, absolute-path and relative-path references).
std::string resolve_url(const std::string& base, const std::string& ref);

}  // namespace protocol
}  // namespace vts
