// vts export: a vtstream archive → standard web tiles (PNG/WebP/JPEG) in a raster PMTiles archive
// or a {z}/{x}/{y}.ext folder (builder/include/vts/builder/export.hpp).
#include <cstdio>
#include <nlohmann/json.hpp>
#include <optional>

#include "commands.hpp"
#include "progress.hpp"
#include "vts/archive/inspect.hpp"
#include "vts/base/file_io.hpp"
#include "vts/builder/export.hpp"

namespace vts::cli {

namespace {

struct ExportArgs {
  std::string archive, output, format, layout = "pmtiles", tiling;
  std::optional<int> quality;  // unset: the format's default
  unsigned threads = 0;
  bool json = false, quiet = false;
};

Result<ExportOptions> export_options(const ExportArgs& a) {
  ExportOptions o;
  auto format = imaging::parse_web_format(a.format);
  if (!format) return Error{ErrorCode::invalid_argument, "--format: " + format.error().message};
  o.format = *format;
  if (a.quality) {
    if (o.format == imaging::WebFormat::png)
      return make_error(ErrorCode::invalid_argument,
                        "--quality applies to webp and jpg; png is lossless (leave it out)");
    const int lo = o.format == imaging::WebFormat::jpeg ? 1 : 0;
    if (*a.quality < lo || *a.quality > 100)
      return make_error(ErrorCode::invalid_argument, "--quality " + std::to_string(*a.quality) +
                                                         " is outside " + std::to_string(lo) +
                                                         "..100");
    o.encode.webp_quality = o.encode.jpeg_quality = *a.quality;
  }
  if (!a.tiling.empty()) {
    auto t = parse_tiling(a.tiling);
    if (!t) return Error{ErrorCode::invalid_argument, "--tiling: " + t.error().message};
    o.tiling = *t;
  }
  o.layout = a.layout == "xyz" ? ExportLayout::xyz : ExportLayout::pmtiles;
  o.output = a.output;
  o.threads = a.threads;
  // The archive's file name; a set's folder ("planet/" names "planet").
  std::filesystem::path source = a.archive;
  if (!source.has_filename()) source = source.parent_path();
  o.source_name = source.filename().string();
  return o;
}

void print_report(const ExportArgs& a, const ExportReport& r) {
  if (a.json) {
    nlohmann::json j{{"output", a.output},
                     {"layout", a.layout},
                     {"format", a.format},
                     {"source_tiles", r.source_tiles},
                     {"tiles", r.tiles_written},
                     {"skipped_transparent", r.tiles_skipped},
                     {"unique_tiles", r.unique_tiles},
                     {"tile_bytes", r.tile_bytes},
                     {"file_bytes", r.file_bytes},
                     {"min_zoom", r.min_zoom},
                     {"max_zoom", r.max_zoom},
                     {"bounds", {r.bounds.west, r.bounds.south, r.bounds.east, r.bounds.north}},
                     {"seconds", r.seconds}};
    std::printf("%s\n", j.dump(2).c_str());
  } else if (!a.quiet) {
    std::printf("exported %s: %llu tiles (%llu unique, %llu transparent skipped), %s in %s\n",
                a.output.c_str(), (unsigned long long)r.tiles_written,
                (unsigned long long)r.unique_tiles, (unsigned long long)r.tiles_skipped,
                human_bytes(r.file_bytes ? r.file_bytes : r.tile_bytes).c_str(),
                human_duration(r.seconds).c_str());
  }
}

int run_export(const ExportArgs& a) {
  auto o = export_options(a);
  if (!o) return report_error(o.error());
  const std::filesystem::path archive = a.archive;
  if (Status s = check_output_is_not_an_input(a.output, {&archive, 1}); !s)
    return report_error(s.error());
  auto reader = open_archive(a.archive);  // a file, a set, or either in an object store
  if (!reader) return report_error(reader.error());
  auto info = archive::archive_tileset((*reader)->header(), (*reader)->metadata_json());
  if (!info) {
    Error e = info.error();
    e.message = "'" + a.archive + "': " + e.message;
    return report_error(e);
  }
  ProgressBar bar("export", "tiles", !a.quiet && !a.json);
  o->on_progress = [&](std::uint64_t done, std::uint64_t total) { bar.update(done, total); };
  // SIGINT/SIGTERM stop the export cleanly (no output left); a second one kills.
  o->cancel = &install_stop_signals();
  auto report = export_web_tiles(**reader, *info, *o);
  bar.finish();
  if (!report) return report_error(report.error());
  print_report(a, *report);
  return 0;
}

}  // namespace

Runner add_export(CLI::App& app) {
  auto a = std::make_shared<ExportArgs>();
  CLI::App* c = app.add_subcommand(
      "export",
      "Write an archive's tiles as standard web images (PNG, WebP, JPEG) in a raster "
      "PMTiles archive or a {z}/{x}/{y} folder, for stock web maps");
  c->add_option("archive", a->archive, "vtstream archive (.pmtiles)")->required();
  c->add_option("-o,--output", a->output, "Output archive (.pmtiles), or folder with --layout xyz")
      ->required();
  c->add_option("--format", a->format, "Tile image format: webp, png or jpg")->required();
  c->add_option("--quality", a->quality, "webp (0..100) or jpg (1..100) quality [default: 90]");
  c->add_option("--layout", a->layout,
                "pmtiles (one archive) or xyz (a {z}/{x}/{y}.ext folder for static hosting)")
      ->check(CLI::IsMember({"pmtiles", "xyz"}))
      ->capture_default_str();
  c->add_option("--tiling", a->tiling,
                "Output grid: the archive's own (default) or WebMercatorQuad (native for a "
                "WebMercatorQuad archive, reprojected from a WorldCRS84Quad one)");
  c->add_option("--threads", a->threads, "Encoder threads (0 = all cores)")
      ->check(CLI::Range(0u, kMaxThreads))
      ->capture_default_str();
  c->add_flag("--json", a->json, "Print the result as JSON");
  c->add_flag("-q,--quiet", a->quiet, "No progress bar or summary");
  return [a] { return run_export(*a); };
}

}  // namespace vts::cli
