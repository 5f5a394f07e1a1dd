// vts plan: fixes a sharded build once (vts/builder/shard.hpp) in a JSON plan.
#include <cstdio>
#include <nlohmann/json.hpp>

#include "build_args.hpp"
#include "commands.hpp"
#include "vts/builder/shard.hpp"

namespace vts::cli {

namespace {

struct PlanArgs {
  BuildArgs build;
  std::uint64_t shards = 0;
  int split_level = -1;
};

int run_plan(const PlanArgs& a) {
  if ((a.shards == 0) == (a.split_level < 0))
    return report_error(make_error(ErrorCode::invalid_argument,
                                   "give one of --shards N (N >= 1) or --split-level L"));
  auto o = build_options(a.build);
  if (!o) return report_error(o.error());
  std::optional<int> level;
  if (a.split_level >= 0) level = a.split_level;
  auto plan = make_shard_plan(*o, level, a.shards);
  if (!plan) return report_error(plan.error());
  if (Status st = save_plan(*plan, a.build.output); !st) return report_error(st.error());
  if (a.build.json) {
    nlohmann::json j;
    j["plan"] = a.build.output;
    j["hash"] = plan->hash;
    j["width"] = plan->width;
    j["height"] = plan->height;
    j["max_zoom"] = plan->max_zoom;
    j["split_level"] = plan->split_level;
    j["shards"] = plan->shards.size();
    j["apex"] = plan->split_level > 0;
    std::printf("%s\n", j.dump(2).c_str());
  } else if (!a.build.quiet) {
    std::printf("planned %s: %llu shards at split level %d of 0..%d%s, plan %s\n",
                a.build.output.c_str(), (unsigned long long)plan->shards.size(), plan->split_level,
                plan->max_zoom, plan->split_level > 0 ? " plus the apex" : " (no apex)",
                plan->hash.c_str());
  }
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
  c->add_flag("--json", a->build.json, "Print the result as JSON");
  c->add_flag("-q,--quiet", a->build.quiet, "No summary");
  return [a] { return run_plan(*a); };
}

}  // namespace vts::cli
