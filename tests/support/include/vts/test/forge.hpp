// Tiles that lie about themselves, and archives that carry them: inputs for the checks of a tile
// against its tileset (vts::check_tile_against) in the decoders and the caches. Failures throw
// std::runtime_error: a test that cannot make its input cannot run.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <vector>

#include "vts/protocol/geometry.hpp"

namespace vts::test {

// A lossless rgba8 tile of width x height texels all of one byte value that verifies (header,
// checksum, body frame) however large it declares itself: its body is a zstd frame of
// run-length blocks, so an 8192 x 8192 tile (256 MiB decoded) takes 8 KiB. Making it allocates
// nothing of the declared size.
std::vector<std::uint8_t> flat_tile(std::uint32_t width, std::uint32_t height, std::uint8_t value);

// Writes `to` with the real PMTiles writer: the archive `from` (same metadata, same tiles) with
// the payloads of `replace` in place of its own (or added).
void copy_archive_replacing(const std::filesystem::path& from, const std::filesystem::path& to,
                            const std::map<TileId, std::vector<std::uint8_t>>& replace);

}  // namespace vts::test
