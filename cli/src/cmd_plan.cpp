// vts plan: fixes a sharded build once (vts/builder/shard.hpp) in a JSON plan.
#include <cstdio>
#include <nlohmann/json.hpp>
#include <set>

#include "build_args.hpp"
#include "build_inputs.hpp"
#include "commands.hpp"
#include "progress.hpp"
#include "vts/base/file_io.hpp"
#include "vts/builder/shard.hpp"

namespace vts::cli {

namespace {

struct PlanArgs {
  BuildArgs build;
  std::uint64_t shards = 0;
  int split_level = -1;
  int apex_levels = kDefaultApexLevels;
  std::string update;            // --update OLD-PLAN
  int archive_level = 0;         // --archive-level K: the output is a set
  std::string max_archive_size;  // --max-archive-size: K from the estimate
};

// --archive-level K, or the smallest K whose archives fit --max-archive-size.
Status choose_archive_level(const PlanArgs& a, ShardPlan& plan) {
  if (a.archive_level > 0 && !a.max_archive_size.empty())
    return make_error(ErrorCode::invalid_argument,
                      "give one of --archive-level and --max-archive-size, not both");
  if (a.archive_level > 0) {
    if (a.archive_level > plan.max_zoom)
      return make_error(ErrorCode::invalid_argument,
                        "--archive-level " + std::to_string(a.archive_level) +
                            " is past the finest level, " + std::to_string(plan.max_zoom));
    set_archive_level(plan, a.archive_level);
  } else if (!a.max_archive_size.empty()) {
    auto cap = parse_byte_size(a.max_archive_size, "--max-archive-size");
    if (!cap) return cap.error();
    auto k = archive_level_for_size(plan, *cap);
    if (!k) return k.error();
    set_archive_level(plan, *k);
  }
  return {};
}

// An update keeps the old plan's build: of the options given, only the inputs and -o may come.
Status check_update_options(const CLI::App& c) {
  static const std::set<std::string> kAllowed = {"update", "output", "input-list",
                                                 "json",   "quiet",  "help"};
  for (const CLI::Option* opt : c.get_options()) {
    if (opt->count() == 0 || opt->get_name() == "inputs") continue;
    const auto& names = opt->get_lnames();
    if (!names.empty() && kAllowed.count(names.front())) continue;
    return make_error(ErrorCode::invalid_argument,
                      opt->get_name() + " does not go with --update: the old plan fixes the build");
  }
  return {};
}

// The plan written must not be a file it was made from: an input, the --input-list, the old plan.
Status check_plan_output(const PlanArgs& a, std::vector<std::filesystem::path> inputs) {
  if (!a.build.input_list.empty()) inputs.emplace_back(a.build.input_list);
  if (!a.update.empty()) inputs.emplace_back(a.update);
  return check_output_is_not_an_input(a.build.output, inputs);
}

// The disk a plan's parts and archive will take (estimate_plan_size): what `vts build --plan` and
// `vts merge` check their folders for, and what a volume for the build must hold.
nlohmann::json estimate_json(const PlanSizeEstimate& e) {
  return {{"shard_max", e.shard_max},
          {"apex", e.apex},
          {"archive", e.archive},
          {"tile_bytes", e.tile_bytes}};
}

void print_plan(const PlanArgs& a, const ShardPlan& plan) {
  const PlanSizeEstimate e = estimate_plan_size(plan);
  if (a.build.json) {
    nlohmann::json j;
    j["plan"] = a.build.output;
    j["hash"] = plan.hash;
    j["build_hash"] = plan.build_hash;
    j["width"] = plan.width;
    j["height"] = plan.height;
    j["max_zoom"] = plan.max_zoom;
    j["split_level"] = plan.split_level;
    j["apex_level"] = plan.apex_level;
    j["shards"] = plan.shards.size();
    j["apex"] = plan.apex_level > 0;
    j["estimated_bytes"] = estimate_json(e);
    if (plan.archive_level > 0) {
      j["archive_level"] = plan.archive_level;
      j["archives"] = set_archive_roots(plan).size();
      j["estimated_bytes"]["archive_max"] = estimate_set_archive_max(plan, plan.archive_level);
    }
    std::printf("%s\n", j.dump(2).c_str());
  } else if (!a.build.quiet) {
    std::printf("planned %s: %llu shards at split level %d of 0..%d, apex level %d%s, plan %s\n",
                a.build.output.c_str(), (unsigned long long)plan.shards.size(), plan.split_level,
                plan.max_zoom, plan.apex_level,
                plan.apex_level > 0 ? " plus the apex" : " (no apex)", plan.hash.c_str());
    std::printf(
        "estimated disk: the archive about %s, the parts about as much (each shard's at "
        "most %s, the apex's %s)\n",
        human_bytes(e.archive).c_str(), human_bytes(e.shard_max).c_str(),
        human_bytes(e.apex).c_str());
    if (plan.archive_level > 0)
      std::printf(
          "output: a set of %zu archives cut at level %d (vts merge --archive 0..%zu), "
          "each at most about %s\n",
          set_archive_roots(plan).size(), plan.archive_level, set_archive_roots(plan).size() - 1,
          human_bytes(estimate_set_archive_max(plan, plan.archive_level)).c_str());
  }
}

void print_update(const PlanArgs& a, const PlanUpdate& u) {
  const ShardPlan& p = u.plan;
  const double fraction =
      p.shards.empty() ? 0.0 : double(u.shards.size()) / double(p.shards.size());
  if (a.build.json) {
    nlohmann::json j;
    j["plan"] = a.build.output;
    j["hash"] = p.hash;
    j["build_hash"] = p.build_hash;
    j["changed_inputs"] = nlohmann::json::array();
    for (std::size_t i : u.changed_inputs) j["changed_inputs"].push_back(p.inputs[i].path.string());
    j["shards"] = p.shards.size();
    j["rebuild"] = u.shards;
    j["rebuild_fraction"] = fraction;
    j["apex"] = u.apex;
    j["estimated_bytes"] = estimate_json(estimate_plan_size(p));
    std::printf("%s\n", j.dump(2).c_str());
    return;
  }
  if (a.build.quiet) return;
  std::printf("updated %s from %s: %zu of %zu inputs changed", a.build.output.c_str(),
              a.update.c_str(), u.changed_inputs.size(), p.inputs.size());
  for (std::size_t i : u.changed_inputs) std::printf(" %s", p.inputs[i].path.c_str());
  std::printf("\nrebuild %zu of %zu shards (%.1f%%):", u.shards.size(), p.shards.size(),
              fraction * 100);
  for (std::size_t s : u.shards) std::printf(" %zu", s);
  std::printf("%s\n", u.apex ? "\nthe apex must be rebuilt too (a shard is)" : "");
}

int run_update(const CLI::App& c, const PlanArgs& a) {
  if (Status st = check_update_options(c); !st) return report_error(st.error());
  auto old = load_plan(a.update);
  if (!old) return report_error(old.error());
  auto inputs = expand_inputs(a.build.inputs, a.build.input_list);
  if (!inputs) return report_error(inputs.error());
  std::vector<std::filesystem::path> read = *inputs;
  for (const PlanInput& in : old->inputs) read.push_back(in.path);
  if (Status st = check_plan_output(a, std::move(read)); !st) return report_error(st.error());
  auto u = update_shard_plan(*old, *inputs);
  if (!u) return report_error(u.error());
  if (Status st = save_plan(u->plan, a.build.output); !st) return report_error(st.error());
  print_update(a, *u);
  return 0;
}

int run_plan(const CLI::App& c, const PlanArgs& a) {
  if (!a.update.empty()) return run_update(c, a);
  if ((a.shards == 0) == (a.split_level < 0))
    return report_error(make_error(ErrorCode::invalid_argument,
                                   "give one of --shards N (N >= 1) or --split-level L"));
  auto o = build_options(a.build);
  if (!o) return report_error(o.error());
  if (Status st = check_plan_output(a, o->inputs); !st) return report_error(st.error());
  std::optional<int> level;
  if (a.split_level >= 0) level = a.split_level;
  auto plan = make_shard_plan(*o, level, a.shards, a.apex_levels);
  if (!plan) return report_error(plan.error());
  if (Status st = choose_archive_level(a, *plan); !st) return report_error(st.error());
  if (Status st = save_plan(*plan, a.build.output); !st) return report_error(st.error());
  print_plan(a, *plan);
  return 0;
}

}  // namespace

Runner add_plan(CLI::App& app) {
  auto a = std::make_shared<PlanArgs>();
  CLI::App* c = app.add_subcommand(
      "plan", "Fix a build once for many machines: its options, inputs and shards, in a JSON plan");
  add_build_options(c, a->build);
  c->add_option("-o,--output", a->build.output, "The plan to write (.json)")->required();
  c->add_option("--shards", a->shards,
                "At least this many shards: the smallest split level giving them (capped at the "
                "finest level)");
  c->add_option("--split-level", a->split_level,
                "Split at this level: a shard per tile of it with tiles to build")
      ->check(CLI::Range(0, int(Geometry::kMaxZoom)));
  c->add_option("--apex-levels", a->apex_levels,
                "Shards stop this many levels above the split level, the apex makes the rest "
                "(0: shards make their split-level tile; default 2)")
      ->check(CLI::Range(0, int(Geometry::kMaxZoom)));
  c->add_option("--archive-level", a->archive_level,
                "Make the output a set of archives: one per tile of this level, holding its "
                "sub-pyramid, plus one for the levels above (each small enough for an object "
                "store; vts merge --archive I merges archive I)")
      ->check(CLI::Range(1, int(Geometry::kMaxZoom)));
  c->add_option("--max-archive-size", a->max_archive_size,
                "Make the output a set whose archives are each at most this size by the plan's "
                "estimate (e.g. 4TiB: under S3's and GCS's 5 TiB object limit)");
  c->add_option("--update", a->update,
                "Update this plan with new inputs (given, or its own read again): the same build, "
                "listing the shards to rebuild");
  c->add_flag("--json", a->build.json, "Print the result as JSON");
  c->add_flag("-q,--quiet", a->build.quiet, "No summary");
  return [a, c] { return run_plan(*c, *a); };
}

}  // namespace vts::cli
