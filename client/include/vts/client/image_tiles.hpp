// Standard image tiles (PNG, JPEG, WebP) of third-party tilesets and stock raster PMTiles
// archives: recognising such an archive, describing it as an image tileset, and decoding one of
// its tiles. What the viewer's decoders, the sources and `vts info` / `vts verify` share, so an
// archive is judged the same way whichever of them reads it. Every function is thread-safe.
#pragma once

#include <cstdint>
#include <span>
#include <string>

#include "vts/archive/pmtiles.hpp"
#include "vts/base/result.hpp"
#include "vts/client/source.hpp"
#include "vts/protocol/codec.hpp"

namespace vts::client {

// True for a header whose tile type is png, jpeg or webp: a raster archive a stock PMTiles
// reader displays. Whether it is ours is the metadata's business (archive_tileset()).
bool is_stock_image_archive(const archive::Header& header) noexcept;

// A stock PMTiles archive of standard images (tile type png, jpeg or webp; no "vtstream"
// metadata) as an image tileset (SourceInfo::image_format): zoom range and bounds from the header
// (options override them), tile size from the metadata's "tileSize" (default 256), key as given.
// unsupported for another tile type or tiles compressed again (tile compression other than none
// or unknown);
// invalid_argument, naming the key and the field, for a zoom range, bounds or tile size
// image_source_info() refuses.
Result<SourceInfo> stock_archive_info(const archive::Header& header,
                                      const std::string& metadata_json, std::string key,
                                      const SourceOptions& options = {});

// Decodes one standard image tile to rgba8 (JPEG: alpha 255). `declared` is what the tileset
// says its tiles are ("png", "jpeg", "webp"); the bytes' own signature must agree with it, except
// for "image" or "" (a template that does not say), which takes any of the three. corrupt, naming
// what was expected and what was found, for bytes of another type, bytes no decoder accepts, or
// an image that is not tile_size x tile_size pixels.
Result<TileImage> decode_image_tile(std::span<const std::uint8_t> payload,
                                    const std::string& declared, std::uint32_t tile_size);

}  // namespace vts::client
