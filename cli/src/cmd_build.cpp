// vts build: image(s) or the synthetic source → PMTiles pyramid archive.
#include <cstdio>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <set>
#include <string_view>

#include "build_args.hpp"
#include "build_geo.hpp"
#include "commands.hpp"
#include "plan_build.hpp"
#include "progress.hpp"
#include "vts/base/file_io.hpp"
#include "vts/builder/builder.hpp"

namespace vts::cli {

namespace {

void print_json(const BuildArgs& a, const BuildOptions& o, const BuildReport& r) {
  const Geometry& g = r.info.geometry;
  nlohmann::json j;
  j["output"] = a.output;
  j["input"] = r.input_description;
  j["width"] = g.width();
  j["height"] = g.height();
  j["tile_size"] = g.tile_size();
  j["border"] = g.border();
  j["max_zoom"] = g.max_zoom();
  j["codec"] = codec_name(r.info.codec);
  if (r.info.codec == CodecId::bc1) j["bc1_quality"] = bc1_quality_name(o.encode.bc1);
  j["downsample"] = r.info.downsample;
  j["tiles"] = r.stats.addressed_tiles;
  j["unique_tiles"] = r.stats.tile_contents;
  j["entries"] = r.stats.tile_entries;
  j["tile_bytes"] = r.stats.tile_bytes;
  j["file_bytes"] = r.stats.file_bytes;
  if (const auto& geo = r.info.georeference) {
    const LonLatBounds& b = geo->bounds;
    j["georeference"] = {{"tiling", std::string(tiling_name(geo->tiling))},
                         {"crs", std::string(tiling_crs(geo->tiling))},
                         {"bounds", {b.west, b.south, b.east, b.north}}};
  }
  j["passes"] = r.passes;
  j["window_width"] = r.window_width;
  if (!r.value_ranges.empty()) j["range"] = range_argument(r.value_ranges);
  j["warnings"] = r.warnings;
  j["seconds"] = r.seconds;
  j["tiles_per_second"] = r.seconds > 0 ? double(r.stats.addressed_tiles) / r.seconds : 0.0;
  std::printf("%s\n", j.dump(2).c_str());
}

void print_text(const BuildArgs& a, const BuildReport& r) {
  const Geometry& g = r.info.geometry;
  std::printf("built %s: %llux%llu, %d levels, %llu tiles (%llu unique), %s in %s (%.0f tiles/s)\n",
              a.output.c_str(), (unsigned long long)g.width(), (unsigned long long)g.height(),
              g.level_count(), (unsigned long long)r.stats.addressed_tiles,
              (unsigned long long)r.stats.tile_contents, human_bytes(r.stats.file_bytes).c_str(),
              human_duration(r.seconds).c_str(),
              r.seconds > 0 ? double(r.stats.addressed_tiles) / r.seconds : 0.0);
  if (!r.value_ranges.empty())
    std::printf("value range: --range %s\n", range_argument(r.value_ranges).c_str());
}

// A plan fixes the build: of the options given, only those of running it may come with --plan.
Status check_plan_options(const CLI::App& c) {
  static const std::set<std::string> kAllowed = {
      "plan",           "shard",   "shard-offset", "apex",  "out-dir",
      "no-space-check", "threads", "json",         "quiet", "help"};
  for (const CLI::Option* opt : c.get_options()) {
    if (opt->count() == 0) continue;
    const auto& names = opt->get_lnames();
    if (!names.empty() && kAllowed.count(names.front())) continue;
    return make_error(ErrorCode::invalid_argument,
                      opt->get_name() + " does not go with --plan: the plan fixes the build");
  }
  return {};
}

int run_build(const CLI::App& c, const BuildArgs& a, const PlanBuildArgs& plan_args) {
  if (!plan_args.plan.empty()) {
    if (Status st = check_plan_options(c); !st) return report_error(st.error());
    return run_plan_build(plan_args, a);
  }
  if (plan_args.apex || plan_args.shard || plan_args.shard_offset || !plan_args.out_dir.empty() ||
      plan_args.no_space_check)
    return report_error(make_error(
        ErrorCode::invalid_argument,
        "--shard, --shard-offset, --apex, --out-dir and --no-space-check need --plan PLAN.json"));
  if (a.output.empty())
    return report_error(make_error(ErrorCode::invalid_argument,
                                   "no output given: -o OUT.pmtiles (or --plan for a shard)"));
  // Before the inputs are read: the archive is spooled beside its name, in a folder that exists.
  if (Status st = check_output_file(a.output, "-o", {}); !st) return report_error(st.error());
  // build_pyramid checks the output against the inputs; the --input-list is the command's own.
  if (!a.input_list.empty()) {
    const std::filesystem::path list = a.input_list;
    if (Status st = check_output_is_not_an_input(a.output, {&list, 1}); !st)
      return report_error(st.error());
  }
  auto o = build_options(a);
  if (!o) return report_error(o.error());
  ProgressBar bar("build", "tiles", !a.quiet && !a.json);
  o->on_progress = [&](const BuildProgress& p) {
    if (p.tiles_total == 0 && p.inputs_total > 0)
      return bar.update(p.inputs_checked, p.inputs_total, "checking inputs");
    bar.update(p.tiles_done, p.tiles_total,
               human_bytes(p.bytes_written) + (p.finishing ? "  writing archive..." : ""));
  };
  // SIGINT/SIGTERM ask the build to stop cleanly (no output file is left); a second one kills.
  o->cancel = &install_stop_signals();
  o->on_warning = [&](const std::string& w) {
    bar.finish();
    std::fprintf(stderr, "warning: %s\n", w.c_str());
  };
  auto report = build_pyramid(*o);
  bar.finish();
  if (!report) return report_error(report.error());
  if (a.json)
    print_json(a, *o, *report);
  else if (!a.quiet)
    print_text(a, *report);
  return 0;
}

}  // namespace

Runner add_build(CLI::App& app) {
  auto a = std::make_shared<BuildArgs>();
  auto p = std::make_shared<PlanBuildArgs>();
  CLI::App* c = app.add_subcommand("build", "Cut images into a tile pyramid archive (PMTiles)");
  add_build_options(c, *a);
  c->add_option("-o,--output", a->output, "Output archive (.pmtiles); not with --plan");
  add_plan_build_options(c, *p);
  c->add_flag("--json", a->json, "Print the result as JSON");
  c->add_flag("-q,--quiet", a->quiet, "No progress bar or summary");
  return [a, p, c] { return run_build(*c, *a, *p); };
}

}  // namespace vts::cli
