// What a plan's parts and archive take on disk, estimated (vts/builder/shard.hpp,
// estimate_plan_size): `vts plan` prints it, `vts build --plan` and `vts merge` refuse an output
// folder without the room before any work, and deploy/batch/k8s/render.sh sizes its volume with
// the same rule (tests/integration/k8s_render.sh compares the two).
#include <algorithm>

#include "vts/builder/shard.hpp"

namespace vts {
inline namespace builder {

namespace {

// Bytes per stored tile of 264 x 264 texels (T = 256, border 4), measured by `vts bench accuracy`
// on the 8192x4096 Earth at zstd level 3 (docs/PLANET.md, "Bytes"; docs/ACCURACY.md, table 1):
// lossless with the gradient filter, and with none. Real imagery is less smooth: an estimate.
constexpr std::uint64_t kLosslessFiltered = 34'478, kLosslessUnfiltered = 66'475;
constexpr std::uint64_t kMeasuredSide = 264;

std::uint64_t lossless_tile_bytes(const ShardPlan& plan, std::uint64_t side) {
  const std::uint64_t measured =
      plan.options.encode.filter == FilterChoice::none ? kLosslessUnfiltered : kLosslessFiltered;
  // Scaled by the texels; rounded up.
  return (measured * side * side + kMeasuredSide * kMeasuredSide - 1) /
         (kMeasuredSide * kMeasuredSide);
}

std::uint64_t ceil_div(std::uint64_t a, std::uint64_t b) {
  return (a + b - 1) / b;
}

// Level z's tiles across and down, dense: its texels ceil(size / 2^(maxz - z)) in tiles.
std::pair<std::uint64_t, std::uint64_t> level_tiles(const ShardPlan& plan, int z) {
  const std::uint64_t scale = std::uint64_t{1} << (plan.max_zoom - z);
  const std::uint64_t t = plan.options.tile_size;
  return {ceil_div(ceil_div(plan.width, scale), t), ceil_div(ceil_div(plan.height, scale), t)};
}

// The descendants of `root` at level z >= root.z, clipped to the level.
std::uint64_t subtree_level_tiles(const ShardPlan& plan, TileId root, int z) {
  const std::uint64_t span = std::uint64_t{1} << (z - root.z);
  const auto [w, h] = level_tiles(plan, z);
  const auto clip = [span](std::uint64_t start, std::uint64_t size) {
    const std::uint64_t from = start * span;
    return from >= size ? 0 : std::min(span, size - from);
  };
  return clip(root.x, w) * clip(root.y, h);
}

// Shard `index`'s tiles at level z >= split level.
std::uint64_t shard_level_tiles(const ShardPlan& plan, std::size_t index, int z) {
  return subtree_level_tiles(plan, plan.shards[index], z);
}

// Shard `index`'s tiles of levels from..to (all >= the split level).
std::uint64_t shard_tiles(const ShardPlan& plan, std::size_t index, int from, int to) {
  std::uint64_t n = 0;
  for (int z = from; z <= to; ++z) n += shard_level_tiles(plan, index, z);
  return n;
}

// The apex's tiles: of the levels above the split level, the shards' ancestors (distinct); of the
// levels from it to the apex level, the shards' own. A sparse plan (a planet's land) has few.
std::uint64_t apex_tiles(const ShardPlan& plan) {
  std::uint64_t n = 0;
  std::vector<std::uint64_t> keys;
  for (int z = 0; z < std::min(plan.split_level, plan.apex_level); ++z) {
    const int up = plan.split_level - z;
    keys.clear();
    for (const TileId& t : plan.shards)
      keys.push_back((std::uint64_t{t.x >> up} << 32) | std::uint64_t{t.y >> up});
    std::sort(keys.begin(), keys.end());
    n += std::uint64_t(std::unique(keys.begin(), keys.end()) - keys.begin());
  }
  for (std::size_t i = 0; i < plan.shards.size(); ++i)
    n += shard_tiles(plan, i, plan.split_level, plan.apex_level - 1);
  return n;
}

}  // namespace

std::uint64_t estimate_shard_part_bytes(const ShardPlan& plan, std::size_t index) {
  if (index >= plan.shards.size()) return 0;  // build_shard refuses it, naming the range
  const std::uint64_t side = std::uint64_t{plan.options.tile_size} + 2 * plan.options.border;
  const std::uint64_t per_tile = estimate_plan_size_tile_bytes(plan);
  const std::uint64_t tiles = shard_tiles(plan, index, plan.apex_level, plan.max_zoom);
  // The attachment: the level-A tiles once more, lossless (none when the shards make level 0).
  const std::uint64_t attached =
      plan.apex_level > 0 ? shard_level_tiles(plan, index, plan.apex_level) : 0;
  return tiles * per_tile + attached * lossless_tile_bytes(plan, side);
}

std::uint64_t estimate_plan_size_tile_bytes(const ShardPlan& plan) {
  const std::uint64_t side = std::uint64_t{plan.options.tile_size} + 2 * plan.options.border;
  // BC1's stored size (8 bytes a 4x4 block) is its upper bound: zstd only shrinks it.
  return plan.options.codec == CodecId::bc1 ? side * side / 2 : lossless_tile_bytes(plan, side);
}

std::uint64_t estimate_set_archive_max(const ShardPlan& plan, int k) {
  if (k < 1 || k > plan.max_zoom) return 0;
  const std::uint64_t per_tile = estimate_plan_size_tile_bytes(plan);
  std::uint64_t top = 0;
  for (int z = 0; z < k; ++z) {
    const auto [w, h] = level_tiles(plan, z);
    top += w * h;
  }
  // The archive under level-k tile (0, 0) is the fullest: every other one is clipped as much or
  // more by the image's right and bottom edges.
  std::uint64_t first = 0;
  for (int z = k; z <= plan.max_zoom; ++z)
    first += subtree_level_tiles(plan, TileId{static_cast<std::uint8_t>(k), 0, 0}, z);
  return std::max(top, first) * per_tile;
}

Result<int> archive_level_for_size(const ShardPlan& plan, std::uint64_t max_bytes) {
  for (int k = 1; k <= plan.max_zoom; ++k)
    if (estimate_set_archive_max(plan, k) <= max_bytes) return k;
  return make_error(ErrorCode::invalid_argument,
                    "no archive level keeps every archive of the set under " +
                        std::to_string(max_bytes) + " bytes (the finest, " +
                        std::to_string(plan.max_zoom) + ", needs " +
                        std::to_string(estimate_set_archive_max(plan, plan.max_zoom)) + ")");
}

PlanSizeEstimate estimate_plan_size(const ShardPlan& plan) {
  PlanSizeEstimate e;
  e.tile_bytes = estimate_plan_size_tile_bytes(plan);
  // Every tile a shard's sub-pyramid can have (dense within it: a sparse plan's shards are those
  // with tiles, not their tiles), plus the apex's: what render.sh counts too.
  std::uint64_t tiles = apex_tiles(plan);
  e.apex = tiles * e.tile_bytes;
  for (std::size_t i = 0; i < plan.shards.size(); ++i) {
    e.shard_max = std::max(e.shard_max, estimate_shard_part_bytes(plan, i));
    tiles += shard_tiles(plan, i, plan.apex_level, plan.max_zoom);
  }
  e.archive = tiles * e.tile_bytes;
  return e;
}

}  // namespace builder
}  // namespace vts
