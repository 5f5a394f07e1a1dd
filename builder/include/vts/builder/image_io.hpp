// Image files as 8-bit RGBA through OpenImageIO: the reader of any 8-bit image OpenImageIO opens,
// straight alpha. (PNG files are written by vts/imaging/web_image.hpp's write_png.)
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>
#include <vector>

#include "vts/base/result.hpp"

namespace vts {
inline namespace builder {

// width x height pixels, 4 bytes each, rows top to bottom.
struct Rgba8Image {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgba;
};

// Reads an image file (PNG, or any 8-bit format OpenImageIO reads) as RGBA8: grey is replicated,
// a missing alpha channel becomes 255. not_found when the file does not exist; corrupt when it
// cannot be decoded, truncated or corrupt when its pixels are cut short or damaged (even where
// the decoder fills them in and carries on); unsupported beyond 32768 pixels a side or 4
// channels.
Result<Rgba8Image> read_rgba8(const std::filesystem::path& path);

}  // namespace builder
}  // namespace vts
