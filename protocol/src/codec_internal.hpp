// Private entry points of the tile codec layer, shared by codec.cpp, the unit tests and the fuzz
// target. Not installed, not part of the public API: the layout of the lossless body and the
// filter kernels may change with the payload version.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/protocol/codec.hpp"

namespace vts {
inline namespace protocol {
namespace detail {

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

// ---- shared by the codecs -----------------------------------------------------------------------

// invalid_argument naming the range when `level` is not a zstd level.
Status check_zstd_level(int level);
// Compresses `body` (body_size bytes) at zstd `level` into `out`: the header frame (the given
// header with body_size and checksum filled in) followed by one zstd frame declaring its content
// size. `out` is resized to fit exactly.
Status compress_payload(const std::uint8_t* body, std::size_t body_size, int level,
                        TileHeader header, std::vector<std::uint8_t>& out);
// parse_tile_header() + the checksum + the body frame's structure (verify_tile() plus the frame
// checks): after it, the body may be decompressed.
Result<TileHeader> verify_payload(std::span<const std::uint8_t> payload);
// Decompresses a body frame into dst, resized to header.body_size only after every size check of
// decode_lossless_body() passed (no checksum check).
Status decompress_body(const TileHeader& header, std::span<const std::uint8_t> body,
                       std::vector<std::uint8_t>& dst);

// The bc1 codec singleton (codec_bc1.cpp): decode only, the encoder is the builder's.
const Codec& bc1_codec();

}  // namespace detail
}  // namespace protocol
}  // namespace vts
