// What shard.cpp (plans) gives shard_build.cpp (shards, apex, merge).
#pragma once

#include <vector>

#include "vts/builder/shard.hpp"

namespace vts::detail {

// The tiles of `level` (one level's rect) at level z that lie under `root`.
TileRect shard_rect(const TileRect& level, TileId root, int z);
// The tiles a whole build of the plan writes at each level (index z).
std::vector<TileRect> plan_emit_rects(const ShardPlan& plan, const Geometry& g);
Result<Geometry> plan_geometry(const ShardPlan& plan);

}  // namespace vts::detail
