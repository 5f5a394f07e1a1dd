// Shorthands the renderer's unit tests share: a tile id from plain integers, a valid pyramid.
#pragma once

#include <gtest/gtest.h>

#include <cstdint>

#include "vts/renderer/pyramid.hpp"

namespace vts::renderer::testing {

inline TileId tile(int z, std::uint32_t x, std::uint32_t y) {
  return TileId{static_cast<std::uint8_t>(z), x, y};
}

// The pyramid of `max_level` over tx x ty finest tiles (a test failure if that is not valid).
inline Pyramid pyramid(int max_level, std::uint32_t tx, std::uint32_t ty) {
  auto p = Pyramid::create(max_level, tx, ty);
  EXPECT_TRUE(p.ok());
  return *p;
}

}  // namespace vts::renderer::testing
