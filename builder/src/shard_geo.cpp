// Georeferenced builds in plans (shard_geo.hpp).
#include "shard_geo.hpp"

#include "input_drivers.hpp"

#include <algorithm>

#include "shard_internal.hpp"

namespace vts {
inline namespace builder {
namespace detail {

namespace {

using nlohmann::json;

json bounds_json(const LonLatBounds& b) {
  return json::array({b.west, b.south, b.east, b.north});
}

LonLatBounds bounds_from(const json& j) {
  return {j.at(0).get<double>(), j.at(1).get<double>(), j.at(2).get<double>(),
          j.at(3).get<double>()};
}

json ranges_json(const std::vector<std::pair<double, double>>& ranges) {
  json out = json::array();
  for (const auto& [lo, hi] : ranges) out.push_back({lo, hi});
  return out;
}

std::vector<std::pair<double, double>> ranges_from(const json& j) {
  std::vector<std::pair<double, double>> out;
  for (const json& r : j) out.emplace_back(r.at(0).get<double>(), r.at(1).get<double>());
  return out;
}

std::string tiling_text(Tiling t) {
  return t == Tiling::none ? "none" : std::string(tiling_name(t));
}

Result<Tiling> tiling_from(const std::string& text) {
  if (text == "none") return Tiling::none;
  return parse_tiling(text);
}

}  // namespace

void geo_options_to_json(const BuildOptions& o, json& j) {
  json g;
  g["tiling"] = tiling_text(o.tiling);
  g["bounds"] = o.bounds ? bounds_json(*o.bounds) : json();
  g["max_level"] = o.max_level ? json(*o.max_level) : json();
  g["resampling"] = resampling_name(o.resampling);
  g["warp_error"] = o.warp_error;
  g["max_window_width"] = o.max_window_width;
  g["bands"] = o.bands;
  g["value_range"] = o.value_range ? json({o.value_range->first, o.value_range->second}) : json();
  g["band_ranges"] = ranges_json(o.band_ranges);
  g["auto_range"] = o.auto_range;
  j["georeferenced"] = std::move(g);
}

Status geo_options_from_json(const json& j, BuildOptions& o) {
  if (!j.contains("georeferenced")) return {};
  const json& g = j["georeferenced"];
  auto tiling = tiling_from(g.at("tiling").get<std::string>());
  if (!tiling) return tiling.error();
  o.tiling = *tiling;
  if (!g.at("bounds").is_null()) o.bounds = bounds_from(g["bounds"]);
  if (!g.at("max_level").is_null()) o.max_level = g["max_level"].get<int>();
  auto resampling = parse_resampling(g.at("resampling").get<std::string>());
  if (!resampling) return resampling.error();
  o.resampling = *resampling;
  o.warp_error = g.at("warp_error").get<double>();
  o.max_window_width = g.at("max_window_width").get<std::uint64_t>();
  o.bands = g.at("bands").get<std::vector<int>>();
  if (!g.at("value_range").is_null())
    o.value_range = {g["value_range"].at(0).get<double>(), g["value_range"].at(1).get<double>()};
  o.band_ranges = ranges_from(g.at("band_ranges"));
  o.auto_range = g.at("auto_range").get<bool>();
  return {};
}

json geo_plan_to_json(const GeoPlan& p) {
  json j;
  const Georeference& geo = p.georeference;
  j["tiling"] = tiling_text(geo.tiling);
  j["bounds"] = bounds_json(geo.bounds);
  j["center"] = {geo.center.lon, geo.center.lat, geo.center.level};
  j["inputs"] = p.inputs;
  if (p.inputs) {
    j["max_level"] = p.max_level;
    j["value_ranges"] = ranges_json(p.value_ranges);
    json extents = json::array();
    for (const LonLatBounds& b : p.input_bounds) extents.push_back(bounds_json(b));
    j["input_bounds"] = std::move(extents);
  }
  return j;
}

Result<GeoPlan> geo_plan_from_json(const json& j) {
  GeoPlan p;
  auto tiling = tiling_from(j.at("tiling").get<std::string>());
  if (!tiling) return tiling.error();
  if (*tiling == Tiling::none)
    return make_error(ErrorCode::invalid_argument, "a georeferenced plan needs a tiling scheme");
  p.georeference.tiling = *tiling;
  p.georeference.bounds = bounds_from(j.at("bounds"));
  p.georeference.center = {j.at("center").at(0).get<double>(), j.at("center").at(1).get<double>(),
                           j.at("center").at(2).get<int>()};
  p.inputs = j.at("inputs").get<bool>();
  if (p.inputs) {
    p.max_level = j.at("max_level").get<int>();
    p.value_ranges = ranges_from(j.at("value_ranges"));
    for (const json& b : j.at("input_bounds")) p.input_bounds.push_back(bounds_from(b));
  }
  return p;
}

std::optional<GeoPlan> pin_geo_plan(const PreparedBuild& p) {
  if (!p.georeference) return std::nullopt;
  GeoPlan g;
  g.georeference = *p.georeference;
  if (p.gdal) {
    g.inputs = true;
    g.max_level = p.gdal->max_level();
    g.value_ranges = p.gdal->value_ranges();
    g.input_bounds = p.gdal->input_bounds();
  }
  return g;
}

Result<PreparedBuild> plan_prepared(const ShardPlan& plan) {
  auto geometry = plan_geometry(plan);
  if (!geometry) return std::move(geometry).error();
  PreparedBuild p;
  p.codec = plan.options.codec;
  p.geometry = *geometry;
  p.synthetic = plan.options.synthetic;
  p.input_description = plan.input_description;
  if (plan.geo) {
    const Georeference& geo = plan.geo->georeference;
    p.tiling = geo.tiling;
    p.georeference = geo;
    p.gdal_inputs = plan.geo->inputs;
    // As make_georeference does: a synthetic build's region is the footprint when not given.
    if (p.synthetic && !p.synthetic->region) {
      p.synthetic->region = footprint_texels(geo.tiling, *geometry, geo.bounds);
      p.synthetic->region_level = 0;
    }
  }
  return p;
}

TexelRect plan_window(const ShardPlan& plan, const Geometry& g) {
  if (plan.geo && plan.geo->inputs)
    return footprint_texels(plan.geo->georeference.tiling, g, plan.geo->georeference.bounds);
  return TexelRect{0, 0, g.width(), g.height()};
}

std::uint64_t plan_max_width(const ShardPlan& plan) {
  if (!plan.geo || !plan.geo->inputs) return UINT64_MAX;
  return plan.options.max_window_width ? plan.options.max_window_width : kDefaultWindowWidth;
}

std::vector<std::size_t> plan_inputs_meeting(const ShardPlan& plan, const Geometry& g,
                                             const TexelRect& window) {
  std::vector<std::size_t> chosen;
  for (std::size_t i = 0; i < plan.inputs.size(); ++i) {
    if (plan.geo && plan.geo->inputs) {
      if (i >= plan.geo->input_bounds.size()) break;
      const TexelRect r =
          footprint_texels(plan.geo->georeference.tiling, g, plan.geo->input_bounds[i]);
      if (std::max(r.x0, window.x0) >= std::min(r.x1, window.x1) ||
          std::max(r.y0, window.y0) >= std::min(r.y1, window.y1))
        continue;
    }
    chosen.push_back(i);
  }
  return chosen;
}

Result<PreparedBuild> prepare_shard_build(const ShardPlan& plan, const BuildOptions& o,
                                          const std::vector<std::size_t>& chosen) {
  if (!plan.geo || !plan.geo->inputs) return prepare_build(o);
  if (plan.geo->input_bounds.size() != plan.inputs.size())
    return make_error(ErrorCode::invalid_argument,
                      "the plan records " + std::to_string(plan.geo->input_bounds.size()) +
                          " input extents for its " + std::to_string(plan.inputs.size()) +
                          " inputs");
  auto p = plan_prepared(plan);
  if (!p) return p;
  if (find_codec(p->codec) == nullptr)
    return make_error(ErrorCode::unsupported,
                      std::string("codec '") + codec_name(o.codec) + "' is not available yet");
  GdalSourceOptions go = gdal_source_options(o);
  go.max_level = plan.geo->max_level;
  go.value_ranges.clear();
  go.auto_range = false;
  go.ranges = plan.geo->value_ranges;
  go.bounds = plan.geo->georeference.bounds;
  std::vector<std::filesystem::path> paths;
  for (std::size_t i : chosen) paths.push_back(plan.inputs[i].path);
  auto drivers = input_drivers();
  if (!drivers) return std::move(drivers).error();
  auto src = (*drivers)->open_georeferenced(paths, go);
  if (!src) return std::move(src).error();
  if ((*src)->width() != plan.width || (*src)->height() != plan.height)
    return make_error(ErrorCode::invalid_argument, "the inputs' geometry is not the plan's");
  p->gdal = std::move(src).value();
  return p;
}

}  // namespace detail
}  // namespace builder
}  // namespace vts
