// Reading a third-party TileJSON (2.x / 3.0, no "vtstream" object) into an ImageLayout.
#pragma once

#include <cstdint>
#include <span>
#include <string>

#include "vts/archive/pmtiles.hpp"
#include "vts/base/result.hpp"
#include "vts/client/image_tiles.hpp"
#include "vts/client/source.hpp"

namespace vts::client {

// corrupt for a body that is not a JSON object with a "tiles" array of URL templates holding
// {z}, {x} and {y} (or {-y}); invalid_argument for "minzoom"/"maxzoom"/"bounds" of the wrong type
// or out of range. The format comes from "format" when present, else the template's suffix
// (.png, .jpg/.jpeg, .webp), else "image". Options' bounds and zoom range override the document's.
Result<ImageLayout> read_image_tilejson(std::span<const std::uint8_t> body, const std::string& url,
                                        const SourceOptions& options);

// The image format a URL template's path suffix names: "png", "jpeg", "webp" or "image".
std::string format_from_suffix(const std::string& url_template);

// The validator of a stock archive's tile, which has no tile header: the archive version and the
// tile's place in it ('"' + version + '-' + offset + '-' + length + '"').
std::string stock_tile_etag(const std::string& version, std::uint64_t offset, std::uint64_t length);

}  // namespace vts::client
