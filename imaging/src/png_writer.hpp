// The PNG writer behind encode_web_image and write_png: rows filtered here, one IDAT from
// libdeflate's zlib compressor (a compressor per thread and level, kept), CRCs by libdeflate.
// What libpng's writer did, several times faster per core at comparable bytes (docs/ACCURACY.md,
// "Web tile encoding"). Thread-safe.
#pragma once

#include <cstdint>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/imaging/web_image.hpp"

namespace vts::imaging::detail {

// The libdeflate level of a public png_level 0..9 (0 stored .. 9 libdeflate's slowest, 12).
int deflate_level(int png_level) noexcept;

// A complete PNG (signature, IHDR, an sRGB chunk when `srgb`, one IDAT, IEND) of width x height
// 8-bit pixels of `channels` (3: RGB, 4: RGBA, straight alpha), rows top to bottom, tightly
// packed (`pixels` holds width * height * channels bytes). `png_level` 0..9. io when libdeflate
// cannot allocate its compressor or the image is too large for one PNG chunk.
Result<std::vector<std::uint8_t>> png_bytes(const std::uint8_t* pixels, std::uint32_t width,
                                            std::uint32_t height, int channels, int png_level,
                                            PngFilter filter, bool srgb);

}  // namespace vts::imaging::detail
