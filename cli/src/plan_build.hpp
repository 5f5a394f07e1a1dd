// vts build --plan PLAN.json (--shard I | --apex) --out-dir DIR: one part of a sharded build
// (vts/builder/shard.hpp). Built only with the builder.
#pragma once

#include <CLI/CLI.hpp>
#include <optional>
#include <string>

#include "build_args.hpp"

namespace vts::cli {

struct PlanBuildArgs {
  std::string plan, out_dir;
  std::optional<std::uint64_t> shard;
  bool apex = false;
};

void add_plan_build_options(CLI::App* c, PlanBuildArgs& p);
// Builds the shard or the apex; `a` gives --threads, --json and --quiet (a plan fixes the rest:
// inputs or build options beside --plan are an error).
int run_plan_build(const PlanBuildArgs& p, const BuildArgs& a);

}  // namespace vts::cli
