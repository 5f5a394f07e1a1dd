// The built-in synthetic source: every texel encodes its own coordinates at its level, so tests can
// check exactly which texel of which tile a reader, extractor or renderer returned.
//   R = px & 0xFF, G = py & 0xFF, B = ((px >> 8) & 0x0F) | (((py >> 8) & 0x0F) << 4), A = 255
// where (px, py) are level-z texel coordinates. Each level is generated directly (not downsampled),
// so a planet-sized synthetic pyramid costs only the tiles that exist.
#pragma once

#include <cstdint>

#include "vts/protocol/codec.hpp"
#include "vts/protocol/geometry.hpp"

namespace vts {
inline namespace builder {

inline void synthetic_texel(std::uint64_t px, std::uint64_t py, std::uint8_t out[4]) {
  out[0] = static_cast<std::uint8_t>(px & 0xFF);
  out[1] = static_cast<std::uint8_t>(py & 0xFF);
  out[2] = static_cast<std::uint8_t>(((px >> 8) & 0x0F) | (((py >> 8) & 0x0F) << 4));
  out[3] = 255;
}

// The stored tile (content + clamped border) of the synthetic source for tile t.
TileImage synthetic_tile(const Geometry& g, TileId t);

}  // namespace builder
}  // namespace vts
