// Standard web images (PNG, WebP, JPEG) of a tile's content: what stock web maps and PMTiles
// readers display. The content of tile (z, x, y) is its T x T texels without the border, padded
// with transparent texels beyond the image's edge; encoders are our PNG writer over libdeflate,
// libwebp and libjpeg-turbo (TurboJPEG API); decoders libpng, libwebp and TurboJPEG. Every
// function is thread-safe.
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>
#include <string_view>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/protocol/geometry.hpp"

namespace vts::imaging {

enum class WebFormat : std::uint8_t { png, webp, jpeg };

// "png", "webp", "jpg": the file extension and URL suffix.
std::string_view web_format_extension(WebFormat f) noexcept;
// "image/png", "image/webp", "image/jpeg".
std::string_view web_format_content_type(WebFormat f) noexcept;
// "png", "webp", "jpg" or "jpeg" (case-insensitive); invalid_argument naming the known ones.
Result<WebFormat> parse_web_format(std::string_view text);

// The PNG row filter (PNG spec §9): one of the five for every row, or `adaptive`, a choice per
// row by libpng's heuristic (the smallest sum of absolute filtered bytes).
enum class PngFilter : std::uint8_t { none, sub, up, average, paeth, adaptive };

// The defaults are chosen from the measured table in docs/ACCURACY.md ("Web tile encoding").
struct WebEncodeOptions {
  // 0 (stored, fastest) .. 9 (smallest): libdeflate's levels 0..8, and 12 for 9.
  int png_level = 4;
  PngFilter png_filter = PngFilter::average;
  int webp_quality = 90;  // 0..100, lossy
  bool webp_lossless = false;
  int webp_method = 2;    // 0 (fast) .. 6 (small)
  int jpeg_quality = 90;  // 1..100, 4:2:0 chroma subsampling
};
// invalid_argument naming the field when a value is out of its range.
Status validate(const WebEncodeOptions& o);

// Encodes an rgba8 image (straight alpha). JPEG has no alpha: colours are composited over black
// (transparent texels become black). invalid_argument for a non-rgba8 or empty image.
Result<std::vector<std::uint8_t>> encode_web_image(const TileImage& rgba, WebFormat format,
                                                   const WebEncodeOptions& options = {});
// Decodes PNG, WebP or JPEG (sniffed from the bytes) to rgba8 (JPEG: alpha 255). corrupt, naming
// the format, for bytes none of the three decoders accepts; at most TileHeader::kMaxDimension
// texels per side.
Result<TileImage> decode_web_image(std::span<const std::uint8_t> bytes);

// The T x T content of tile `id` from its decoded stored texels (rgba8, or bc1, decoded to rgba8
// first): the border cropped, texels beyond the level's image edge transparent (0, 0, 0, 0).
// invalid_argument when `stored` is not the geometry's stored size or `id` does not exist.
Result<TileImage> tile_content(const TileImage& stored, const Geometry& geometry, TileId id);

// Writes an 8-bit RGBA PNG file (whatever the extension) of width x height pixels, rows top to
// bottom, straight alpha, tagged sRGB, through write_file_atomically: the one PNG writer of
// screenshots, plots, references and extracted tiles. With `channels` 3 the file is RGB (alpha
// dropped). `level` as WebEncodeOptions::png_level, with its default filter. invalid_argument
// when `rgba` does not hold width * height * 4 bytes, `level` is not 0..9 or `channels` is
// neither 3 nor 4; io when the file cannot be written.
Status write_png(const std::filesystem::path& path, int width, int height,
                 std::span<const std::uint8_t> rgba, int level = 4, int channels = 4);

}  // namespace vts::imaging
