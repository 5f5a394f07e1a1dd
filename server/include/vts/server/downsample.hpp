// The builder's 2x2 reduction: each coarser texel is the mean of its (up to) four children,
// computed in linear light — sRGB-decoded to linear, averaged, re-encoded to sRGB with correct
// rounding — with alpha averaged directly. At an odd edge the last row/column is repeated (clamp),
// matching Geometry's clamp-to-edge convention.
#pragma once

#include <cstdint>

namespace vts {

// sRGB (IEC 61966-2-1) transfer functions on [0, 1], double precision references.
double srgb_to_linear(double v);
double linear_to_srgb(double v);

// Nearest 8-bit sRGB code of a linear value (exact rounding in sRGB space). Thread-safe.
std::uint8_t encode_srgb8(float linear);
// Linear value of an 8-bit sRGB code (table lookup).
float decode_srgb8(std::uint8_t code);

// Makes one row of `out_width` RGBA8 texels from rows a and b (b may equal a at an odd bottom
// edge) of `in_width` texels: out[i] = mean of a[2i], a[2i+1], b[2i], b[2i+1] with 2i+1 clamped
// to in_width - 1. out_width must be ceil(in_width / 2).
void downsample_row_rgba8(const std::uint8_t* a, const std::uint8_t* b, std::uint64_t in_width,
                          std::uint8_t* out, std::uint64_t out_width);

}  // namespace vts
