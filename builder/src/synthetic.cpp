#include "vts/builder/synthetic.hpp"

namespace vts {
inline namespace builder {

TileImage synthetic_tile(const Geometry& g, TileId t) {
  const std::uint32_t s = g.stored_size();
  TileImage img;
  img.width = img.height = s;
  img.format = PixelFormat::rgba8;
  img.pixels.resize(std::size_t{s} * s * 4);
  std::uint8_t* p = img.pixels.data();
  for (std::uint32_t sy = 0; sy < s; ++sy) {
    const std::uint64_t py = g.stored_to_level_y(t, sy);
    for (std::uint32_t sx = 0; sx < s; ++sx, p += 4)
      synthetic_texel(g.stored_to_level_x(t, sx), py, p);
  }
  return img;
}

}  // namespace builder
}  // namespace vts
