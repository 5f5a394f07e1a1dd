#include "vts/renderer/pyramid.hpp"

#include <string>

namespace vts::renderer {

Result<Pyramid> Pyramid::create(int max_level, std::uint32_t finest_tiles_x,
                                std::uint32_t finest_tiles_y) {
  if (max_level < 0 || max_level >= kMaxLevels)
    return make_error(ErrorCode::invalid_argument,
                      "pyramid max level " + std::to_string(max_level) + " is outside [0, " +
                          std::to_string(kMaxLevels - 1) + "]");
  const std::uint64_t side = std::uint64_t{1} << max_level;
  if (finest_tiles_x == 0 || finest_tiles_y == 0 || finest_tiles_x > side || finest_tiles_y > side)
    return make_error(ErrorCode::invalid_argument, "pyramid of " + std::to_string(finest_tiles_x) +
                                                       "x" + std::to_string(finest_tiles_y) +
                                                       " tiles does not fit level " +
                                                       std::to_string(max_level));
  Pyramid p;
  p.max_level_ = max_level;
  for (int z = 0; z <= max_level; ++z) {
    // ceil(finest / 2^d): the same rounding as Geometry::tiles_x, since
    // ceil(ceil(W / 2^d) / T) == ceil(ceil(W / T) / 2^d).
    const int d = max_level - z;
    const std::uint32_t round = (std::uint32_t{1} << d) - 1;
    p.tiles_x_[z] = static_cast<std::uint32_t>((std::uint64_t{finest_tiles_x} + round) >> d);
    p.tiles_y_[z] = static_cast<std::uint32_t>((std::uint64_t{finest_tiles_y} + round) >> d);
  }
  return p;
}

Result<Pyramid> Pyramid::from_geometry(const Geometry& geometry) {
  const int mz = geometry.max_zoom();
  if (mz >= kMaxLevels)
    return make_error(ErrorCode::unsupported,
                      "geometry has " + std::to_string(geometry.level_count()) +
                          " levels; the renderer supports " + std::to_string(kMaxLevels));
  return create(mz, geometry.tiles_x(mz), geometry.tiles_y(mz));
}

}  // namespace vts::renderer
