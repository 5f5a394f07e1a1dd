// Standard image tiles: which archives hold them and how one tile is decoded and checked
// (image_tiles.hpp). The decode itself is imaging's (libpng, libwebp, TurboJPEG).
#include "vts/client/image_tiles.hpp"

#include <algorithm>
#include <string_view>

#include "vts/imaging/web_image.hpp"

namespace vts::client {
namespace {

bool starts_with_bytes(std::span<const std::uint8_t> b, std::size_t at, std::string_view magic) {
  if (b.size() < at + magic.size()) return false;
  return std::equal(magic.begin(), magic.end(), b.begin() + std::ptrdiff_t(at),
                    [](char m, std::uint8_t c) { return static_cast<std::uint8_t>(m) == c; });
}

// What the bytes' signature says they are: "png", "jpeg", "webp", or "" for none of them.
std::string_view sniff(std::span<const std::uint8_t> b) {
  if (starts_with_bytes(b, 0, "\x89PNG\r\n\x1a\n")) return "png";
  if (starts_with_bytes(b, 0, "\xff\xd8\xff")) return "jpeg";
  if (starts_with_bytes(b, 0, "RIFF") && starts_with_bytes(b, 8, "WEBP")) return "webp";
  return "";
}

}  // namespace

bool is_stock_image_archive(const archive::Header& h) noexcept {
  return h.tile_type == archive::TileType::png || h.tile_type == archive::TileType::jpeg ||
         h.tile_type == archive::TileType::webp;
}

Result<TileImage> decode_image_tile(std::span<const std::uint8_t> payload,
                                    const std::string& declared, std::uint32_t tile_size) {
  const bool any = declared.empty() || declared == "image";
  const std::string_view found = sniff(payload);
  if (!any && found != declared)
    return make_error(ErrorCode::corrupt,
                      "a " + declared + " tileset's tile is " +
                          (found.empty() ? std::string("not an image of a known type")
                                         : "a " + std::string(found) + " image") +
                          " (" + std::to_string(payload.size()) + " bytes)");
  auto image = imaging::decode_web_image(payload);
  if (!image) return image;
  if (image->width != tile_size || image->height != tile_size)
    return make_error(ErrorCode::corrupt, "image tile of " + std::to_string(image->width) + "x" +
                                              std::to_string(image->height) +
                                              " pixels in a tileset of " +
                                              std::to_string(tile_size) + " px tiles");
  return image;
}

}  // namespace vts::client
