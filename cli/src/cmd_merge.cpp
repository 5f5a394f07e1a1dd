// vts merge: the parts of a sharded build into one archive (vts/builder/shard.hpp).
#include <cstdio>
#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "plan_build.hpp"
#include "progress.hpp"
#include "vts/base/file_io.hpp"
#include "vts/builder/shard.hpp"

namespace vts::cli {

namespace {

struct MergeArgs {
  std::string plan, parts, output;
  bool json = false, quiet = false, no_verify = false, no_space_check = false;
};

void print_report(const MergeArgs& a, const MergeReport& r) {
  if (a.json) {
    nlohmann::json j;
    j["output"] = a.output;
    j["parts"] = r.parts;
    j["tiles"] = r.stats.addressed_tiles;
    j["unique_tiles"] = r.stats.tile_contents;
    j["entries"] = r.stats.tile_entries;
    j["tile_bytes"] = r.stats.tile_bytes;
    j["file_bytes"] = r.stats.file_bytes;
    j["content_hash"] = r.info.content_hash;
    j["seconds"] = r.seconds;
    std::printf("%s\n", j.dump(2).c_str());
  } else if (!a.quiet) {
    std::printf("merged %zu parts into %s: %llu tiles (%llu unique), %s in %s\n", r.parts,
                a.output.c_str(), (unsigned long long)r.stats.addressed_tiles,
                (unsigned long long)r.stats.tile_contents, human_bytes(r.stats.file_bytes).c_str(),
                human_duration(r.seconds).c_str());
  }
}

int run_merge(const MergeArgs& a) {
  // merge_plan checks the output against the parts; the plan is the command's own input. The
  // output's folder is checked before the parts are read: a planet's merge runs for hours, and
  // the archive is written under a temporary name in that folder.
  const std::filesystem::path out = a.output;
  if (Status st = check_output_file(out, "-o", {a.plan}); !st) return report_error(st.error());
  if (Status st = check_output_folder(out.parent_path(), "-o's folder", false); !st)
    return report_error(st.error());
  auto plan = load_plan(a.plan);
  if (!plan) return report_error(plan.error());
  // The archive is about the parts' size; it is written whole before the parts can go.
  if (!a.no_space_check)
    if (Status st = check_free_space(out.parent_path(), "-o's folder", "the merged archive",
                                     estimate_plan_size(*plan).archive);
        !st)
      return report_error(st.error());
  ProgressBar bar("merge", "tiles", !a.quiet && !a.json);
  auto progress = [&](const archive::MergeProgress& p) {
    if (p.copying)
      bar.update(p.bytes_copied, p.bytes_total, "copying " + human_bytes(p.bytes_copied));
    else
      bar.update(p.tiles_done, p.tiles_total, "reading indexes");
  };
  auto report =
      merge_plan(*plan, a.parts, a.output, progress, &install_stop_signals(), !a.no_verify);
  bar.finish();
  if (!report) return report_error(report.error());
  print_report(a, *report);
  return 0;
}

}  // namespace

Runner add_merge(CLI::App& app) {
  auto a = std::make_shared<MergeArgs>();
  CLI::App* c = app.add_subcommand(
      "merge", "Merge the parts of a sharded build (vts plan) into the archive vts build writes");
  c->add_option("--plan", a->plan, "The plan the parts were built from")->required();
  c->add_option("parts", a->parts, "The directory of the parts (shard-*.part, apex.part)")
      ->required();
  c->add_option("-o,--output", a->output, "Output archive (.pmtiles)")->required();
  c->add_flag("--no-verify", a->no_verify,
              "Copy payloads in the kernel (copy_file_range: shared extents on XFS/Btrfs with "
              "reflink) without checking each against its checksum; indexes are still checked");
  c->add_flag("--no-space-check", a->no_space_check,
              "Merge even when the archive's folder has less free space than the plan's estimate "
              "of the archive");
  c->add_flag("--json", a->json, "Print the result as JSON");
  c->add_flag("-q,--quiet", a->quiet, "No progress bar or summary");
  return [a] { return run_merge(*a); };
}

}  // namespace vts::cli
