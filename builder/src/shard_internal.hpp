// What shard.cpp (plans) gives shard_build.cpp (shards, apex, merge).
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "vts/archive/pmtiles_part.hpp"

#include "vts/builder/shard.hpp"

namespace vts {
inline namespace builder {
namespace detail {

// The tiles of `level` (one level's rect) at level z that lie under `root`.
TileRect shard_rect(const TileRect& level, TileId root, int z);
// The tiles a whole build of the plan writes at each level (index z).
std::vector<TileRect> plan_emit_rects(const ShardPlan& plan, const Geometry& g);
Result<Geometry> plan_geometry(const ShardPlan& plan);

// merge_plan(), with `scope` adjusting the merge before it runs (a set's archive: its tile-id
// ranges, zooms and bounds; set_merge.cpp) and the tileset named after `named_after`'s stem
// unless the plan names it (a set is named after its folder).
Result<MergeReport> merge_plan_scoped(
    const ShardPlan& plan, const std::filesystem::path& parts_dir,
    const std::filesystem::path& output, const std::filesystem::path& named_after,
    const std::function<void(archive::MergeOptions&)>& scope,
    const std::function<void(const archive::MergeProgress&)>& progress,
    const std::atomic<bool>* cancel, bool verify);

// shard_update.cpp: what parts record of the build they belong to and how they are checked.
// The build hash of a plan's JSON body (plan_body without build_hash and hash).
std::string build_hash(const nlohmann::json& body);
// What a part's manifest adds: the build hash, and for a shard the inputs it read ({index, path,
// fingerprint}).
void describe_part_build(const ShardPlan& plan, std::optional<std::size_t> shard,
                         nlohmann::json& manifest);
// A part's manifest against the plan: another build, or an input changed since the part was
// built (stale: naming the input and the shard to rebuild), is an error naming the part.
Status check_part_build(const ShardPlan& plan, const nlohmann::json& manifest,
                        const std::filesystem::path& part);
// The apex records the shards' level-A tiles it was built from: XXH3-64 of each part's
// attachment (index: shard), folded in shard order into 16 hex digits.
std::uint64_t attachment_hash(const std::vector<std::uint8_t>& attachment);
std::string shard_tiles_hash(const std::vector<std::uint64_t>& attachment_hashes);
// The apex part against the shards' parts there now (their attachment hashes).
Status check_apex_shards(const ShardPlan& plan, const nlohmann::json& apex_manifest,
                         const std::filesystem::path& apex,
                         const std::vector<std::uint64_t>& attachment_hashes);

}  // namespace detail
}  // namespace builder
}  // namespace vts
