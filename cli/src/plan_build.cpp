// vts build --plan: one shard of a sharded build, or its apex (plan_build.hpp).
#include "plan_build.hpp"

#include <cstdio>
#include <cstdlib>
#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "progress.hpp"
#include "vts/base/file_io.hpp"
#include "vts/builder/shard.hpp"

namespace vts::cli {

namespace {

// --shard, else the first array-index variable of Kubernetes, Slurm or AWS Batch that is set.
Result<std::uint64_t> shard_index(const PlanBuildArgs& p) {
  if (p.shard) return *p.shard;
  auto index = array_job_index("shard index");
  if (!index) return index.error();
  if (*index) return **index;
  return make_error(ErrorCode::invalid_argument,
                    "no shard given: --shard I, or $JOB_COMPLETION_INDEX, $SLURM_ARRAY_TASK_ID or "
                    "$AWS_BATCH_JOB_ARRAY_INDEX (an array job's index)");
}

std::string root_text(const std::optional<TileId>& t) {
  if (!t) return "apex";
  return std::to_string(t->z) + "/" + std::to_string(t->x) + "/" + std::to_string(t->y);
}

double overhead(const ShardReport& r) {
  return r.core_texels ? double(r.texels_read) / double(r.core_texels) : 0.0;
}

void print_report(const BuildArgs& a, const ShardPlan& plan, std::optional<std::uint64_t> index,
                  const ShardReport& r) {
  if (a.json) {
    nlohmann::json j;
    j["part"] = r.part.string();
    j["plan_hash"] = plan.hash;
    j["shards"] = plan.shards.size();
    j["split_level"] = plan.split_level;
    j["apex_level"] = plan.apex_level;
    if (index) j["shard"] = *index;
    j["root"] = root_text(r.root);
    j["tiles"] = r.tiles;
    j["file_bytes"] = r.stats.file_bytes;
    j["texels_read"] = r.texels_read;
    j["core_texels"] = r.core_texels;
    j["halo_overhead"] = overhead(r);
    if (r.root) j["inputs_opened"] = r.inputs_opened;
    j["seconds"] = r.seconds;
    std::printf("%s\n", j.dump(2).c_str());
    return;
  }
  if (a.quiet) return;
  std::printf("built %s (%s): %llu tiles, %s in %s", r.part.string().c_str(),
              root_text(r.root).c_str(), (unsigned long long)r.tiles,
              human_bytes(r.stats.file_bytes).c_str(), human_duration(r.seconds).c_str());
  if (r.core_texels)
    std::printf("; read %.3fx its own texels (halo overhead %.1f%%)", overhead(r),
                (overhead(r) - 1) * 100);
  std::printf("\n");
}

}  // namespace

void add_plan_build_options(CLI::App* c, PlanBuildArgs& p) {
  c->add_option(
      "--plan", p.plan,
      "Build one part of a sharded build (vts plan): --shard I or --apex, into --out-dir");
  c->add_option("--shard", p.shard,
                "With --plan: the shard to build (default: $JOB_COMPLETION_INDEX, "
                "$SLURM_ARRAY_TASK_ID or $AWS_BATCH_JOB_ARRAY_INDEX)");
  c->add_flag("--apex", p.apex,
              "With --plan: build the levels above the apex level from the shards' parts");
  c->add_option("--out-dir", p.out_dir, "With --plan: the directory of the parts");
}

int run_plan_build(const PlanBuildArgs& p, const BuildArgs& a) {
  if (!a.inputs.empty() || !a.input_list.empty() || !a.synthetic.empty() || !a.grid.empty() ||
      !a.output.empty())
    return report_error(make_error(ErrorCode::invalid_argument,
                                   "--plan fixes the build: give no inputs, --synthetic, --grid "
                                   "or -o with it (vts merge writes the archive)"));
  if (p.out_dir.empty())
    return report_error(make_error(ErrorCode::invalid_argument, "--plan needs --out-dir DIR"));
  if (p.apex && p.shard)
    return report_error(
        make_error(ErrorCode::invalid_argument, "give --shard or --apex, not both"));
  auto plan = load_plan(p.plan);
  if (!plan) return report_error(plan.error());
  if (p.apex && plan->apex_level == 0) {
    if (!a.quiet) std::printf("the plan's shards make level 0: no apex to build\n");
    return 0;
  }
  std::optional<std::uint64_t> index;
  if (!p.apex) {
    auto i = shard_index(p);
    if (!i) return report_error(i.error());
    index = *i;
  }
  // The part is not the plan (build_shard/build_apex check it against the inputs and parts).
  const std::filesystem::path plan_path = p.plan;
  const std::filesystem::path part =
      std::filesystem::path(p.out_dir) / (index ? shard_part_name(*index) : kApexPartName);
  if (Status st = check_output_is_not_an_input(part, {&plan_path, 1}); !st)
    return report_error(st.error());
  ProgressBar bar(p.apex ? "apex" : "shard", "tiles", !a.quiet && !a.json);
  ShardBuildOptions so;
  so.out_dir = p.out_dir;
  so.threads = a.threads;
  so.cancel = &install_stop_signals();
  so.on_progress = [&](const BuildProgress& pr) {
    bar.update(pr.tiles_done, pr.tiles_total, human_bytes(pr.bytes_written));
  };
  auto report = index ? build_shard(*plan, *index, so) : build_apex(*plan, so);
  bar.finish();
  if (!report) return report_error(report.error());
  print_report(a, *plan, index, *report);
  return 0;
}

}  // namespace vts::cli
