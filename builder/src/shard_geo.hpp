// Georeferenced builds in plans (vts/builder/shard.hpp's GeoPlan): what a whole build resolves
// from all its inputs, pinned in the plan, and the inputs a shard opens.
#pragma once

#include <cstddef>
#include <nlohmann/json.hpp>
#include <optional>
#include <vector>

#include "build_core.hpp"
#include "vts/builder/shard.hpp"

namespace vts {
inline namespace builder {
namespace detail {

// The georeferenced options of BuildOptions (tiling, bounds, max level, resampling, warp error,
// window width, bands, value ranges) in a plan's options JSON, and back.
void geo_options_to_json(const BuildOptions& o, nlohmann::json& j);
Status geo_options_from_json(const nlohmann::json& j, BuildOptions& o);
nlohmann::json geo_plan_to_json(const GeoPlan& g);
Result<GeoPlan> geo_plan_from_json(const nlohmann::json& j);

// What a whole build resolved of its georeference (nullopt for a build without one).
std::optional<GeoPlan> pin_geo_plan(const PreparedBuild& p);

// The plan's build resolved, without a source: geometry, synthetic region, tiling, georeference
// (what the apex and the merge need).
Result<PreparedBuild> plan_prepared(const ShardPlan& plan);

// The finest-level texels a whole build of the plan reads (the footprint of georeferenced inputs,
// else the whole grid) and the widest pass it keeps.
TexelRect plan_window(const ShardPlan& plan, const Geometry& g);
std::uint64_t plan_max_width(const ShardPlan& plan);

// The inputs (indexes, in the plan's order) whose extent at the finest level meets `window`:
// those GdalSource::read_window would read for any texel of it. All of them for plain images.
std::vector<std::size_t> plan_inputs_meeting(const ShardPlan& plan, const Geometry& g,
                                             const TexelRect& window);

// The build a shard runs: for georeferenced inputs, only `chosen` opened, with the plan's pinned
// level, bounds and value mapping, so that its grid is the whole build's; else prepare_build(o).
Result<PreparedBuild> prepare_shard_build(const ShardPlan& plan, const BuildOptions& o,
                                          const std::vector<std::size_t>& chosen);

}  // namespace detail
}  // namespace builder
}  // namespace vts
