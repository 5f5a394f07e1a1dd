// vts build --plan PLAN.json (--shard I | --apex) --out-dir DIR: one part of a sharded build
// (vts/builder/shard.hpp). Built only with the builder.
#pragma once

#include <CLI/CLI.hpp>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

#include "build_args.hpp"

namespace vts::cli {

struct PlanBuildArgs {
  std::string plan, out_dir;
  std::optional<std::uint64_t> shard;
  // Added to an array job's index (--shard-offset, else $VTS_SHARD_OFFSET): an engine whose
  // arrays are smaller than the plan (Slurm's MaxArraySize, AWS Batch's 10,000) runs it in chunks.
  // Text, parsed when the shard is chosen: CLI11 would read "-1" as 2^64-1.
  std::optional<std::string> shard_offset;
  bool apex = false;
  // Build even when --out-dir has less free space than the plan's estimate of the part.
  bool no_space_check = false;
};

void add_plan_build_options(CLI::App* c, PlanBuildArgs& p);
// Builds the shard or the apex; `a` gives --threads, --json and --quiet (a plan fixes the rest:
// inputs or build options beside --plan are an error).
int run_plan_build(const PlanBuildArgs& p, const BuildArgs& a);

// What a command checks of the folder it will write into, before any work: that it is a folder
// (created with its parents when `create` and it is missing) and that a file can be created in it
// (a probe file, removed at once: permissions, a read-only mount, no inodes left). Errors name
// `what` ("--out-dir") and the folder.
Status check_output_folder(const std::filesystem::path& dir, std::string_view what, bool create);

// That the folder has `need` bytes free for an unprivileged writer (statvfs: f_bavail * f_frsize):
// io naming `what` and the folder, the space free and `output` ("the merged archive") with its
// estimate, pointing at --no-space-check (the estimate is the plan's, estimate_plan_size).
Status check_free_space(const std::filesystem::path& dir, std::string_view what,
                        std::string_view output, std::uint64_t need);

}  // namespace vts::cli
