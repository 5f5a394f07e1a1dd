// vts merge: the parts of a sharded build into one archive, or into a set of archives
// (vts/builder/shard.hpp); --join makes one archive of a set.
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
  std::string plan, parts, output, join, max_archive_size = "4TiB";
  long long archive = -1;  // --archive I: one archive of the set
  bool manifest = false;   // --manifest: the set's tileset.json once its archives are merged
  bool json = false, quiet = false, no_verify = false, no_space_check = false;
};

nlohmann::json stats_json(const archive::WriterStats& s) {
  return {{"tiles", s.addressed_tiles},
          {"unique_tiles", s.tile_contents},
          {"entries", s.tile_entries},
          {"tile_bytes", s.tile_bytes},
          {"file_bytes", s.file_bytes}};
}

void print_report(const MergeArgs& a, const MergeReport& r) {
  if (a.json) {
    nlohmann::json j = stats_json(r.stats);
    j["output"] = a.output;
    j["parts"] = r.parts;
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

std::function<void(const archive::MergeProgress&)> merge_progress(ProgressBar& bar) {
  return [&bar](const archive::MergeProgress& p) {
    if (p.copying)
      bar.update(p.bytes_copied, p.bytes_total, "copying " + human_bytes(p.bytes_copied));
    else
      bar.update(p.tiles_done, p.tiles_total, "reading indexes");
  };
}

// A set's folder: "-o DIR/", or any -o of a plan made with --archive-level.
bool set_output(const MergeArgs& a, const ShardPlan& plan) {
  return plan.archive_level > 0 || (!a.output.empty() && a.output.back() == '/');
}

nlohmann::json archive_json(const SetArchiveReport& r) {
  nlohmann::json j = r.empty ? nlohmann::json::object() : stats_json(r.merge.stats);
  j["index"] = r.index;
  j["name"] = r.name;
  j["tile"] = r.root ? nlohmann::json(r.root->to_string()) : nlohmann::json(nullptr);
  j["empty"] = r.empty;
  if (!r.empty) j["seconds"] = r.merge.seconds;
  return j;
}

// Archive `index` of the set: 0, or the exit code of its error (reported).
int merge_one(const MergeArgs& a, const ShardPlan& plan, std::size_t index,
              nlohmann::json& archives) {
  ProgressBar bar("merge " + std::to_string(index), "tiles", !a.quiet && !a.json);
  auto r = merge_set_archive(plan, a.parts, a.output, index, merge_progress(bar),
                             &install_stop_signals(), !a.no_verify);
  bar.finish();
  if (!r) return report_error(r.error());
  if (a.json || a.quiet) {
  } else if (r->empty) {
    std::printf("archive %zu (%s): no tiles, none written\n", index, r->name.c_str());
  } else {
    std::printf("archive %zu: %s, %llu tiles, %s\n", index, r->name.c_str(),
                (unsigned long long)r->merge.stats.addressed_tiles,
                human_bytes(r->merge.stats.file_bytes).c_str());
  }
  archives.push_back(archive_json(*r));
  return 0;
}

int run_set(const MergeArgs& a, ShardPlan plan) {
  if (plan.archive_level == 0) {
    auto cap = parse_byte_size(a.max_archive_size, "--max-archive-size");
    if (!cap) return report_error(cap.error());
    auto k = archive_level_for_size(plan, *cap);
    if (!k) return report_error(k.error());
    set_archive_level(plan, *k);
  }
  if (Status st = check_output_folder(a.output, "-o", true); !st) return report_error(st.error());
  // The whole set, or the one archive this task writes.
  const std::uint64_t need = a.archive >= 0 ? estimate_set_archive_max(plan, plan.archive_level)
                                            : estimate_plan_size(plan).archive;
  if (!a.no_space_check && !a.manifest)
    if (Status st = check_free_space(a.output, "-o", "the set's archives", need); !st)
      return report_error(st.error());
  const std::size_t count = set_archive_roots(plan).size();
  nlohmann::json archives = nlohmann::json::array();
  if (a.archive >= 0) {  // one array task's archive; the manifest comes after all of them
    if (int rc = merge_one(a, plan, static_cast<std::size_t>(a.archive), archives)) return rc;
  } else if (!a.manifest) {
    for (std::size_t i = 0; i < count; ++i)
      if (int rc = merge_one(a, plan, i, archives)) return rc;
  }
  nlohmann::json j;
  j["output"] = a.output;
  j["archive_level"] = plan.archive_level;
  j["archives"] = count;
  j["merged"] = std::move(archives);
  if (a.archive < 0) {
    auto m = write_set_manifest(plan, a.output);
    if (!m) return report_error(m.error());
    j["manifest"] = (std::filesystem::path(a.output) / archive::kSetManifestName).string();
    j["version"] = m->version();
    j["written"] = m->archives.size();
    if (!a.json && !a.quiet)
      std::printf("set %s: %zu archives at level %d, version %s\n",
                  j["manifest"].get_ref<const std::string&>().c_str(), m->archives.size(),
                  plan.archive_level, m->version().c_str());
  }
  if (a.json) std::printf("%s\n", j.dump(2).c_str());
  return 0;
}

int run_join(const MergeArgs& a) {
  if (!a.plan.empty() || !a.parts.empty())
    return report_error(
        make_error(ErrorCode::invalid_argument, "--join takes a set and -o, not --plan or parts"));
  if (Status st = check_output_file(a.output, "-o", {a.join}); !st) return report_error(st.error());
  ProgressBar bar("join", "tiles", !a.quiet && !a.json);
  auto stats = join_set(
      a.join, a.output,
      [&](const JoinProgress& p) { bar.update(p.tiles_done, p.tiles_total, "copying tiles"); },
      &install_stop_signals());
  bar.finish();
  if (!stats) return report_error(stats.error());
  if (a.json) {
    nlohmann::json j = stats_json(*stats);
    j["output"] = a.output;
    std::printf("%s\n", j.dump(2).c_str());
  } else if (!a.quiet) {
    std::printf("joined %s into %s: %llu tiles, %s\n", a.join.c_str(), a.output.c_str(),
                (unsigned long long)stats->addressed_tiles, human_bytes(stats->file_bytes).c_str());
  }
  return 0;
}

int run_merge(const MergeArgs& a) {
  if (!a.join.empty()) return run_join(a);
  if (a.plan.empty() || a.parts.empty())
    return report_error(make_error(ErrorCode::invalid_argument,
                                   "give --plan PLAN and the parts' folder (or --join SET)"));
  auto plan = load_plan(a.plan);
  if (!plan) return report_error(plan.error());
  if (set_output(a, *plan)) return run_set(a, std::move(*plan));
  if (a.archive >= 0 || a.manifest)
    return report_error(make_error(ErrorCode::invalid_argument,
                                   "--archive and --manifest are for a set: -o DIR/, or a plan "
                                   "made with --archive-level"));
  // merge_plan checks the output against the parts; the plan is the command's own input. The
  // output's folder is checked before the parts are read: a planet's merge runs for hours, and
  // the archive is written under a temporary name in that folder.
  const std::filesystem::path out = a.output;
  if (Status st = check_output_file(out, "-o", {a.plan}); !st) return report_error(st.error());
  if (Status st = check_output_folder(out.parent_path(), "-o's folder", false); !st)
    return report_error(st.error());
  // The archive is about the parts' size; it is written whole before the parts can go.
  if (!a.no_space_check)
    if (Status st = check_free_space(out.parent_path(), "-o's folder", "the merged archive",
                                     estimate_plan_size(*plan).archive);
        !st)
      return report_error(st.error());
  ProgressBar bar("merge", "tiles", !a.quiet && !a.json);
  auto report = merge_plan(*plan, a.parts, a.output, merge_progress(bar), &install_stop_signals(),
                           !a.no_verify);
  bar.finish();
  if (!report) return report_error(report.error());
  print_report(a, *report);
  return 0;
}

}  // namespace

Runner add_merge(CLI::App& app) {
  auto a = std::make_shared<MergeArgs>();
  CLI::App* c = app.add_subcommand(
      "merge",
      "Merge the parts of a sharded build (vts plan) into the archive vts build writes, or into "
      "a set of archives (-o DIR/); or join a set into one archive (--join)");
  c->add_option("--plan", a->plan, "The plan the parts were built from");
  c->add_option("parts", a->parts, "The directory of the parts (shard-*.part, apex.part)");
  c->add_option("-o,--output", a->output,
                "Output archive (.pmtiles), or the set's folder (DIR/: archives and tileset.json)")
      ->required();
  c->add_option("--archive", a->archive,
                "Merge only archive I of the set (0 is the top; vts plan --json says how many): "
                "one array task each, then --manifest")
      ->check(CLI::NonNegativeNumber);
  c->add_flag("--manifest", a->manifest,
              "Write the set's tileset.json from the archives merged in -o DIR/ (after every "
              "--archive I has run)");
  c->add_option("--max-archive-size", a->max_archive_size,
                "For -o DIR/ from a plan without --archive-level: the archive level whose "
                "archives stay under this size by the plan's estimate (default 4TiB)");
  c->add_option("--join", a->join,
                "Join this set (its folder or tileset.json) into the one archive -o, the archive "
                "a one-file merge writes");
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
