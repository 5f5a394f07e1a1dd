// Private entry points of the tile codec layer, shared by codec.cpp, the unit tests and the fuzz
// target. Not installed, not part of the public API: the layout of the lossless body and the
// filter kernels may change with the payload version.
#pragma once

#include <cstdint>
#include <span>

#include "vts/protocol/codec.hpp"
#include "vts/protocol/result.hpp"

namespace vts::detail {

// Gradient prediction filter (Filter::gradient). `rgba` holds width*height interleaved RGBA8
// texels; `planes` receives width*height*4 bytes: the R plane, then G, B and A, each row-major.
// Every plane byte is (value - pred) mod 256 with
//   pred = clamp(left + up - upleft, 0, 255),
// where left/up/upleft are the neighbours in the same channel and are 0 outside the image (so the
// first row predicts from the left, the first column from above, and the first texel from 0).
// Buffers must not overlap. width, height >= 1. Pure and thread-safe.
void gradient_filter(const std::uint8_t* rgba, std::uint32_t width, std::uint32_t height,
                     std::uint8_t* planes);
// Exact inverse of gradient_filter(): planes (width*height*4 bytes) -> interleaved rgba.
void gradient_unfilter(const std::uint8_t* planes, std::uint32_t width, std::uint32_t height,
                       std::uint8_t* rgba);

// Decodes the body of a lossless payload (the bytes after the header frame) WITHOUT verifying the
// checksum: the frame must declare its content size, equal header.body_size, end exactly at the
// end of `body` (trailing bytes -> corrupt, missing bytes -> truncated) and decompress to exactly
// body_size bytes, which are then unfiltered according to header.filter. `header` is re-checked
// for consistency (codec lossless, rgba8, dimensions, body_size) so hostile headers are safe too.
// Used by Codec::decode() after verify_tile(), and by the fuzz target to reach the zstd and
// unfilter paths that the checksum gate otherwise shields.
Result<TileImage> decode_lossless_body(const TileHeader& header,
                                       std::span<const std::uint8_t> body);

}  // namespace vts::detail
