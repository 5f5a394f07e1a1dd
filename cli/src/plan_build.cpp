// vts build --plan: one shard of a sharded build, or its apex (plan_build.hpp).
#include "plan_build.hpp"

#include <sys/statvfs.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "progress.hpp"
#include "vts/base/file_io.hpp"
#include "vts/builder/shard.hpp"

namespace vts::cli {

namespace {

// The offset an array task's index is shifted by: --shard-offset, else $VTS_SHARD_OFFSET, else 0;
// `source` says which, for the messages ("" when none).
struct ShardOffset {
  std::uint64_t value = 0;
  std::string source;
};

Result<ShardOffset> shard_offset(const PlanBuildArgs& p) {
  const char* env = std::getenv("VTS_SHARD_OFFSET");
  if (!p.shard_offset && (!env || !*env)) return ShardOffset{};
  const std::string text = p.shard_offset ? *p.shard_offset : env;
  const std::string source =
      p.shard_offset ? "--shard-offset " + text : "$VTS_SHARD_OFFSET=" + text;
  std::uint64_t value = 0;
  if (!parse_u64(text, value))
    return make_error(ErrorCode::invalid_argument,
                      (p.shard_offset ? "--shard-offset '" : "$VTS_SHARD_OFFSET='") + text +
                          "' is not a shard offset (a number of shards, decimal digits)");
  return ShardOffset{value, source};
}

// --shard, else the first array-index variable of Kubernetes, Slurm or AWS Batch that is set plus
// the offset. An array task's shard is checked against the plan here, where the message can say
// which variables made it (build_shard checks --shard's).
Result<std::uint64_t> shard_index(const PlanBuildArgs& p, std::uint64_t shards) {
  if (p.shard) {
    if (p.shard_offset)
      return make_error(ErrorCode::invalid_argument,
                        "give --shard or --shard-offset, not both (the offset shifts an array "
                        "job's index)");
    return *p.shard;
  }
  auto offset = shard_offset(p);
  if (!offset) return offset.error();
  auto index = array_job_index("shard index");
  if (!index) return index.error();
  if (!*index)
    return make_error(ErrorCode::invalid_argument,
                      "no shard given: --shard I, or $JOB_COMPLETION_INDEX, $SLURM_ARRAY_TASK_ID "
                      "or $AWS_BATCH_JOB_ARRAY_INDEX (an array job's index)");
  const std::uint64_t i = **index;
  if (i < shards && offset->value < shards - i) return i + offset->value;
  std::string from = std::string("$") + array_job_index_name() + "=" + std::to_string(i);
  if (!offset->source.empty()) from += " + " + offset->source;
  return make_error(ErrorCode::invalid_argument,
                    "shard index " + from + " is out of range: the plan has " +
                        std::to_string(shards) + " shards (0.." + std::to_string(shards - 1) + ")");
}

// The arguments that go with --plan, before the plan is read.
Status check_plan_build_args(const PlanBuildArgs& p, const BuildArgs& a) {
  if (!a.inputs.empty() || !a.input_list.empty() || !a.synthetic.empty() || !a.grid.empty() ||
      !a.output.empty())
    return make_error(ErrorCode::invalid_argument,
                      "--plan fixes the build: give no inputs, --synthetic, --grid or -o with it "
                      "(vts merge writes the archive)");
  if (p.out_dir.empty())
    return make_error(ErrorCode::invalid_argument, "--plan needs --out-dir DIR");
  if (p.apex && (p.shard || p.shard_offset))
    return make_error(ErrorCode::invalid_argument,
                      "give --shard (or --shard-offset) or --apex, not both");
  return {};
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
  c->add_option("--shard-offset", p.shard_offset,
                "With --plan: added to the array job's index (default: $VTS_SHARD_OFFSET, else "
                "0), to run a plan in arrays smaller than its shard count");
  c->add_flag("--apex", p.apex,
              "With --plan: build the levels above the apex level from the shards' parts");
  c->add_option("--out-dir", p.out_dir, "With --plan: the directory of the parts");
  c->add_flag("--no-space-check", p.no_space_check,
              "With --plan: build even when --out-dir has less free space than the plan's "
              "estimate of the part");
}

Status check_output_folder(const std::filesystem::path& dir, std::string_view what, bool create) {
  const std::filesystem::path folder = dir.empty() ? "." : dir;
  const std::string name = std::string(what) + " " + folder.string();
  std::error_code ec;
  if (create && !std::filesystem::exists(folder, ec)) {
    std::filesystem::create_directories(folder, ec);
    if (ec) return make_error(ErrorCode::io, name + ": cannot create the folder: " + ec.message());
  }
  if (!std::filesystem::is_directory(folder, ec))
    return make_error(
        ErrorCode::invalid_argument,
        name + (std::filesystem::exists(folder, ec) ? ": not a folder" : ": no such folder"));
  // A real file, not access(): root passes access() on a read-only mount's folders too.
  std::string probe = (folder / ".vts-write-check.XXXXXX").string();
  const int fd = ::mkstemp(probe.data());
  if (fd < 0) {
    const int err = errno;
    return make_error(ErrorCode::io, name + ": cannot write in the folder: " + std::strerror(err));
  }
  ::close(fd);
  ::unlink(probe.c_str());
  return {};
}

Status check_free_space(const std::filesystem::path& dir, std::string_view what,
                        std::string_view output, std::uint64_t need) {
  const std::filesystem::path folder = dir.empty() ? "." : dir;
  struct statvfs fs {};
  if (::statvfs(folder.c_str(), &fs) != 0) {
    const int err = errno;
    return make_error(ErrorCode::io, std::string(what) + " " + folder.string() +
                                         ": cannot read its free space: " + std::strerror(err));
  }
  const std::uint64_t free = std::uint64_t{fs.f_bavail} * fs.f_frsize;
  if (free >= need) return {};
  return make_error(ErrorCode::io, std::string(what) + " " + folder.string() + ": " +
                                       human_bytes(free) + " free, " + std::string(output) +
                                       " needs about " + human_bytes(need) +
                                       " (the plan's estimate; --no-space-check to try anyway)");
}

int run_plan_build(const PlanBuildArgs& p, const BuildArgs& a) {
  if (Status st = check_plan_build_args(p, a); !st) return report_error(st.error());
  auto plan = load_plan(p.plan);
  if (!plan) return report_error(plan.error());
  if (p.apex && plan->apex_level == 0) {
    if (!a.quiet) std::printf("the plan's shards make level 0: no apex to build\n");
    return 0;
  }
  std::optional<std::uint64_t> index;
  if (!p.apex) {
    auto i = shard_index(p, plan->shards.size());
    if (!i) return report_error(i.error());
    index = *i;
  }
  // Before any work: a shard of a planet runs for minutes, and an array runs thousands of them.
  if (Status st = check_output_folder(p.out_dir, "--out-dir", true); !st)
    return report_error(st.error());
  if (!p.no_space_check) {
    const std::uint64_t need =
        index ? estimate_shard_part_bytes(*plan, *index) : estimate_plan_size(*plan).apex;
    if (Status st =
            check_free_space(p.out_dir, "--out-dir", index ? "the part" : "the apex part", need);
        !st)
      return report_error(st.error());
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
