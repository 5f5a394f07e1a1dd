// web_mercator_tile: renders one WebMercatorQuad tile from a WorldCRS84Quad archive with
// vts::render_web_mercator_tile, reading and decoding the archive's real tiles, and writes its
// T x T texels as raw RGBA (rows top to bottom). For web_mercator_gdalwarp.sh.
//
//   web_mercator_tile ARCHIVE Z X Y OUT.rgba [codes]
//
// "codes" blends sRGB codes instead of linear light. Prints "level L fetched N" on success.
// Exit status: 0 written, 3 the tile lies outside the footprint (nothing written), 1 an error
// (message on stderr), 2 bad usage.
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>

#include "vts/archive/pmtiles.hpp"
#include "vts/base/file_io.hpp"
#include "vts/imaging/web_mercator.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/protocol/tileset.hpp"

namespace {

int fail(const vts::Error& e) {
  std::fprintf(stderr, "web_mercator_tile: %s\n", e.to_string().c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 6 && !(argc == 7 && std::string_view(argv[6]) == "codes")) {
    std::fprintf(stderr, "usage: web_mercator_tile ARCHIVE Z X Y OUT.rgba [codes]\n");
    return 2;
  }
  auto reader = vts::archive::Reader::open(argv[1]);
  if (!reader) return fail(reader.error());
  auto info = vts::TilesetInfo::from_json((*reader)->metadata_json());
  if (!info) return fail(info.error());
  int fetched = 0;
  const vts::imaging::FetchStoredTile fetch =
      [&](vts::TileId id) -> vts::Result<std::optional<vts::TileImage>> {
    ++fetched;
    auto payload = (*reader)->get(id);
    if (!payload && payload.error().code == vts::ErrorCode::not_found)
      return std::optional<vts::TileImage>{};
    if (!payload) return std::move(payload).error();
    auto image = vts::decode_tile(*payload, info->tile_spec());
    if (!image) return std::move(image).error();
    if (image->format == vts::PixelFormat::bc1) image = vts::bc1_to_rgba8(*image);
    if (!image) return std::move(image).error();
    return std::optional<vts::TileImage>(std::move(*image));
  };
  const int z = std::atoi(argv[2]);
  const auto x = static_cast<std::uint32_t>(std::strtoul(argv[3], nullptr, 10));
  const auto y = static_cast<std::uint32_t>(std::strtoul(argv[4], nullptr, 10));
  vts::imaging::WebMercatorOptions options;
  options.linear_light = argc == 6;
  auto tile = vts::imaging::render_web_mercator_tile(*info, z, x, y, fetch, options);
  if (!tile) return fail(tile.error());
  if (!tile->has_value()) return 3;
  if (vts::Status s = vts::write_file_atomically(
          argv[5], std::string_view(reinterpret_cast<const char*>((*tile)->pixels.data()),
                                    (*tile)->pixels.size()));
      !s)
    return fail(s.error());
  std::printf("level %d fetched %d\n", vts::imaging::web_mercator_source_level(info->geometry, z),
              fetched);
  return 0;
}
