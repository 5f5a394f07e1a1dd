// Incremental updates of sharded builds (vts/builder/shard.hpp): which inputs a shard reads, which
// shards a changed input reaches, the build hash and input fingerprints a part records, and the
// checks that keep a stale part out of the apex and the merge.
#include <algorithm>
#include <cstdio>
#include <nlohmann/json.hpp>

#include <xxhash.h>

#include "cascade.hpp"
#include "input_drivers.hpp"
#include "shard_geo.hpp"
#include "shard_internal.hpp"
#include "vts/builder/shard.hpp"

namespace vts {
inline namespace builder {

namespace {

using nlohmann::json;

std::string hex16(std::uint64_t h) {
  char text[17];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(h));
  return text;
}

bool meets(const TexelRect& a, const TexelRect& b) {
  return a.x0 < b.x1 && b.x0 < a.x1 && a.y0 < b.y1 && b.y0 < a.y1;
}

std::string list_text(const std::vector<std::uint64_t>& v) {
  std::string s;
  for (std::uint64_t x : v) s += (s.empty() ? "" : ",") + std::to_string(x);
  return s;
}

// The new plan keeps what the old one's parts were built with: else an error naming what moved.
Status check_same_build(const ShardPlan& old, const ShardPlan& p) {
  auto refuse = [](const std::string& what) {
    return make_error(ErrorCode::invalid_argument,
                      what +
                          ": an update keeps the plan's geometry, grid and shards (make a new "
                          "plan with vts plan and build every shard)");
  };
  if (p.width != old.width || p.height != old.height || p.max_zoom != old.max_zoom)
    return refuse("the new inputs make a " + std::to_string(p.width) + "x" +
                  std::to_string(p.height) + " image, the plan's is " + std::to_string(old.width) +
                  "x" + std::to_string(old.height));
  if (p.column_widths != old.column_widths)
    return refuse("the new inputs' grid columns are " + list_text(p.column_widths) +
                  " texels wide, the plan's " + list_text(old.column_widths));
  if (p.row_heights != old.row_heights)
    return refuse("the new inputs' grid rows are " + list_text(p.row_heights) +
                  " texels high, the plan's " + list_text(old.row_heights));
  if (p.shards != old.shards) return refuse("the new inputs give other shards");
  if (p.build_hash != old.build_hash) return refuse("the new plan's build hash differs");
  return {};
}

}  // namespace

namespace detail {

std::string build_hash(const json& body) {
  json j = body;
  j["input_count"] = j.contains("inputs") ? j["inputs"].size() : 0;
  // The archive level says how the merge cuts the output into a set; the parts do not depend on it.
  for (const char* key : {"inputs", "input_description", "build_hash", "hash", "archive_level"})
    j.erase(key);
  const std::string text = j.dump();
  return hex16(XXH3_64bits(text.data(), text.size()));
}

void describe_part_build(const ShardPlan& plan, std::optional<std::size_t> shard, json& m) {
  m["build_hash"] = plan.build_hash;
  if (!shard) return;
  json inputs = json::array();
  for (std::size_t i : shard_inputs(plan, *shard))
    inputs.push_back({{"index", i},
                      {"path", plan.inputs[i].path.string()},
                      {"fingerprint", plan.inputs[i].fingerprint}});
  m["inputs"] = std::move(inputs);
}

Status check_part_build(const ShardPlan& plan, const json& m, const std::filesystem::path& part) {
  const std::string name = "part " + part.string();
  if (!m.contains("build_hash"))
    return make_error(ErrorCode::invalid_argument,
                      name + " records no build hash (an older vts wrote it): rebuild it");
  const std::string build = m.at("build_hash").get<std::string>();
  if (build != plan.build_hash)
    return make_error(ErrorCode::invalid_argument, name + " belongs to another plan (build hash " +
                                                       build + ", not this plan's " +
                                                       plan.build_hash +
                                                       "): its options, geometry or shards differ");
  if (!m.contains("inputs")) return {};
  const std::string shard = m.contains("shard") ? m.at("shard").dump() : "?";
  for (const json& in : m.at("inputs")) {
    const auto i = in.at("index").get<std::size_t>();
    const std::string fp = in.at("fingerprint").get<std::string>();
    if (i >= plan.inputs.size())
      return make_error(ErrorCode::invalid_argument, name + " read input " + std::to_string(i) +
                                                         ", which the plan does not have");
    if (fp != plan.inputs[i].fingerprint)
      return make_error(ErrorCode::invalid_argument,
                        name + " is stale: input " + plan.inputs[i].path.string() +
                            " changed since it was built; rebuild shard " + shard);
  }
  return {};
}

std::uint64_t attachment_hash(const std::vector<std::uint8_t>& attachment) {
  return XXH3_64bits(attachment.data(), attachment.size());
}

std::string shard_tiles_hash(const std::vector<std::uint64_t>& hashes) {
  return hex16(XXH3_64bits(hashes.data(), hashes.size() * sizeof(std::uint64_t)));
}

Status check_apex_shards(const ShardPlan& plan, const json& apex, const std::filesystem::path& path,
                         const std::vector<std::uint64_t>& hashes) {
  if (plan.options.synthetic) return {};  // built without the shards' parts
  const std::string built =
      apex.contains("shard_tiles") ? apex["shard_tiles"].get<std::string>() : std::string("none");
  if (built != shard_tiles_hash(hashes))
    return make_error(ErrorCode::invalid_argument,
                      "part " + path.string() + " is stale: the shards' level-" +
                          std::to_string(plan.apex_level) +
                          " tiles changed since it was built (a shard was rebuilt); rebuild the "
                          "apex");
  return {};
}

}  // namespace detail

Result<ShardWindow> shard_window(const ShardPlan& plan, std::size_t index) {
  if (index >= plan.shards.size())
    return make_error(ErrorCode::invalid_argument, "shard " + std::to_string(index) +
                                                       " is out of range: the plan has " +
                                                       std::to_string(plan.shards.size()));
  auto geometry = detail::plan_geometry(plan);
  if (!geometry) return std::move(geometry).error();
  const Geometry& g = *geometry;
  const TileId root = plan.shards[index];
  const int d = plan.max_zoom - plan.split_level;
  const int levels = plan.max_zoom - plan.apex_level;  // the cascade's, finest .. A
  auto clip = [&](std::uint64_t x0, std::uint64_t y0, std::uint64_t x1, std::uint64_t y1) {
    return TexelRect{x0, y0, std::min(x1, g.width()), std::min(y1, g.height())};
  };
  // The window adds the halo its tiles' borders and the filter need at every level down to the
  // apex level A, level A's tiles included, borders and all (cascade.hpp, stripe_halo: exact out
  // to B around the core at levels finest .. A is its margin for max_zoom - A + 1 levels, as if
  // level A - 1 were made). B texels at level A are B * 2^(max_zoom - A) finest texels around a
  // core of T * 2^d: the halo's share falls by 2^(A - L) against stopping at L.
  const std::uint64_t side = std::uint64_t{g.tile_size()} << d;
  ShardWindow w;
  w.core = clip(root.x * side, root.y * side, (root.x + 1) * side, (root.y + 1) * side);
  const std::uint64_t halo = detail::stripe_halo(g, levels + 1, plan.options.downsample);
  // Within what the whole build reads (the footprint of georeferenced inputs).
  const TexelRect whole = detail::plan_window(plan, g);
  w.window = clip(std::max(whole.x0, w.core.x0 > halo ? w.core.x0 - halo : 0),
                  std::max(whole.y0, w.core.y0 > halo ? w.core.y0 - halo : 0),
                  std::min(whole.x1, w.core.x1 + halo), std::min(whole.y1, w.core.y1 + halo));
  return w;
}

TexelRect input_rect(const ShardPlan& plan, std::size_t input) {
  if (plan.geo && plan.geo->inputs && input < plan.geo->input_bounds.size()) {
    auto g = detail::plan_geometry(plan);
    if (g)
      return footprint_texels(plan.geo->georeference.tiling, *g, plan.geo->input_bounds[input]);
  }
  const std::size_t columns = plan.column_widths.size();
  if (columns == 0 || plan.row_heights.empty()) return TexelRect{0, 0, plan.width, plan.height};
  const std::size_t c = input % columns, r = input / columns;
  TexelRect rect{};
  for (std::size_t i = 0; i < c; ++i) rect.x0 += plan.column_widths[i];
  for (std::size_t i = 0; i < r && i < plan.row_heights.size(); ++i) rect.y0 += plan.row_heights[i];
  rect.x1 = rect.x0 + plan.column_widths[c];
  rect.y1 = rect.y0 + (r < plan.row_heights.size() ? plan.row_heights[r] : 0);
  return rect;
}

std::vector<std::size_t> shard_inputs(const ShardPlan& plan, std::size_t index) {
  std::vector<std::size_t> inputs;
  auto w = shard_window(plan, index);
  if (!w || plan.options.synthetic) return inputs;
  for (std::size_t i = 0; i < plan.inputs.size(); ++i)
    if (meets(w->window, input_rect(plan, i))) inputs.push_back(i);
  return inputs;
}

std::vector<std::size_t> affected_shards(const ShardPlan& plan,
                                         const std::vector<std::size_t>& changed) {
  std::vector<std::size_t> shards;
  if (plan.options.synthetic || changed.empty()) return shards;
  for (std::size_t s = 0; s < plan.shards.size(); ++s) {
    auto w = shard_window(plan, s);
    if (!w) continue;
    for (std::size_t i : changed)
      if (i < plan.inputs.size() && meets(w->window, input_rect(plan, i))) {
        shards.push_back(s);
        break;
      }
  }
  return shards;
}

Result<PlanUpdate> update_shard_plan(const ShardPlan& old,
                                     const std::vector<std::filesystem::path>& inputs) {
  detail::use_image_inputs();
  if (old.options.synthetic) {
    if (!inputs.empty())
      return make_error(ErrorCode::invalid_argument,
                        "the plan is synthetic: it has no inputs to update");
    return PlanUpdate{old, {}, {}, false};
  }
  std::vector<std::filesystem::path> paths = inputs;
  if (paths.empty())
    for (const PlanInput& in : old.inputs) paths.push_back(in.path);
  if (paths.size() != old.inputs.size())
    return make_error(ErrorCode::invalid_argument,
                      std::to_string(paths.size()) + " inputs given, the plan has " +
                          std::to_string(old.inputs.size()) +
                          ": an update takes one for each of the plan's, in its order");
  BuildOptions o = old.options;
  o.inputs = paths;
  auto plan = make_shard_plan(o, old.split_level, 0, old.apex_level - old.split_level);
  if (!plan) return std::move(plan).error();
  if (Status st = check_same_build(old, *plan); !st) return st.error();
  PlanUpdate u;
  for (std::size_t i = 0; i < old.inputs.size(); ++i)
    if (plan->inputs[i].size != old.inputs[i].size ||
        plan->inputs[i].fingerprint != old.inputs[i].fingerprint)
      u.changed_inputs.push_back(i);
  u.shards = affected_shards(*plan, u.changed_inputs);
  u.apex = !u.shards.empty() && plan->apex_level > 0;
  u.plan = std::move(plan).value();
  return u;
}

}  // namespace builder
}  // namespace vts
