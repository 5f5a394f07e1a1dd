// vts export: a vtstream archive → standard web tiles (PNG/WebP/JPEG) in a raster PMTiles archive,
// a {z}/{x}/{y}.ext folder or an MBTiles file, or one level as a Cloud Optimized GeoTIFF
// (builder/include/vts/builder/export.hpp).
#include <cstdio>
#include <nlohmann/json.hpp>
#include <optional>

#include "commands.hpp"
#include "export_args.hpp"
#include "progress.hpp"
#include "vts/archive/inspect.hpp"
#include "vts/base/file_io.hpp"
#include "vts/builder/export.hpp"

namespace vts::cli {

namespace {

// The flags that apply to one kind of output only, refused with the others.
Status check_flags(const ExportArgs& a) {
  const auto refuse = [](const std::string& flag, const std::string& why) {
    return make_error(ErrorCode::invalid_argument, flag + " " + why);
  };
  if (!is_gtiff(a) && (a.level || !a.bbox.empty()))
    return refuse(a.level ? "--level" : "--bbox", "applies to --format gtiff");
  if (is_gtiff(a) && (!a.tiling.empty() || a.quality))
    return refuse(a.quality ? "--quality" : "--tiling",
                  "does not apply to --format gtiff (lossless, in the archive's own grid)");
  if (!a.tile_format.empty() && !is_mbtiles(a))
    return refuse("--tile-format", "applies to --format mbtiles");
  if (!a.layout.empty() && (is_gtiff(a) || is_mbtiles(a)))
    return refuse("--layout", "applies to --format png, webp and jpg");
  return {};
}

Result<ExportOptions> export_options(const ExportArgs& a) {
  ExportOptions o;
  const std::string& tile_format = is_mbtiles(a) ? a.tile_format : a.format;
  auto format = imaging::parse_web_format(tile_format.empty() ? "png" : tile_format);
  if (!format)
    return Error{ErrorCode::invalid_argument, (is_mbtiles(a) ? "--tile-format: " : "--format: ") +
                                                  format.error().message +
                                                  (is_mbtiles(a) ? "" : ", gtiff or mbtiles")};
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
    auto t = a.tiling == "native" ? Result<Tiling>(Tiling::none) : parse_tiling(a.tiling);
    if (!t) return Error{ErrorCode::invalid_argument, "--tiling: " + t.error().message};
    o.tiling = *t;
  }
  o.layout = is_mbtiles(a)       ? ExportLayout::mbtiles
             : a.layout == "xyz" ? ExportLayout::xyz
                                 : ExportLayout::pmtiles;
  o.output = a.output;
  o.threads = a.threads;
  // The archive's file name; a set's folder ("planet/" names "planet").
  std::filesystem::path source = a.archive;
  if (!source.has_filename()) source = source.parent_path();
  o.source_name = source.filename().string();
  return o;
}

Result<GeoTiffOptions> geotiff_options(const ExportArgs& a) {
  GeoTiffOptions o;
  o.output = a.output;
  o.level = a.level;
  o.threads = a.threads;
  if (!a.bbox.empty()) {
    auto v = parse_numbers(a.bbox, 4, "--bbox", "W,S,E,N (degrees)");
    if (!v) return v.error();
    o.bbox = LonLatBounds{(*v)[0], (*v)[1], (*v)[2], (*v)[3]};
  }
  return o;
}

int run_export(const ExportArgs& a) {
  if (Status s = check_flags(a); !s) return report_error(s.error());
  std::optional<ExportOptions> web;
  std::optional<GeoTiffOptions> gtiff;
  if (is_gtiff(a)) {
    auto o = geotiff_options(a);
    if (!o) return report_error(o.error());
    gtiff = std::move(o).value();
  } else {
    auto o = export_options(a);
    if (!o) return report_error(o.error());
    web = std::move(o).value();
  }
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
  ProgressBar bar("export", gtiff ? "blocks" : "tiles", !a.quiet && !a.json);
  const auto progress = [&](std::uint64_t done, std::uint64_t total) { bar.update(done, total); };
  // SIGINT/SIGTERM stop the export cleanly (no output left); a second one kills.
  const std::atomic<bool>* cancel = &install_stop_signals();
  if (gtiff) {
    gtiff->on_progress = progress;
    gtiff->cancel = cancel;
    auto report = export_geotiff(**reader, *info, *gtiff);
    bar.finish();
    if (!report) return report_error(report.error());
    print_geotiff_report(a, *report);
    return 0;
  }
  web->on_progress = progress;
  web->cancel = cancel;
  note_grid(a, *info, *web);
  auto report = export_web_tiles(**reader, *info, *web);
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
      "PMTiles archive, a {z}/{x}/{y} folder or an MBTiles file, for stock web maps; or a "
      "level as a Cloud Optimized GeoTIFF, for GIS tools");
  c->add_option("archive", a->archive, "vtstream archive (.pmtiles)")->required();
  c->add_option("-o,--output", a->output,
                "Output archive (.pmtiles), folder (--layout xyz), .mbtiles or .tif")
      ->required();
  c->add_option("--format", a->format,
                "webp, png or jpg (web tiles), mbtiles (raster MBTiles 1.3) or gtiff (COG)")
      ->required();
  c->add_option("--tile-format", a->tile_format,
                "mbtiles: the tiles' format, png, webp or jpg "
                "[default: png]");
  c->add_option("--level", a->level, "gtiff: the level to write [default: the finest]");
  c->add_option("--bbox", a->bbox,
                "gtiff: W,S,E,N in degrees, snapped outward to texels [default: the footprint]");
  c->add_option("--quality", a->quality, "webp (0..100) or jpg (1..100) quality [default: 90]");
  c->add_option("--layout", a->layout,
                "pmtiles (one archive) or xyz (a {z}/{x}/{y}.ext folder for static hosting) "
                "[default: pmtiles]")
      ->check(CLI::IsMember({"pmtiles", "xyz"}));
  c->add_option("--tiling", a->tiling,
                "Output grid: WebMercatorQuad (the default for a georeferenced archive: native "
                "for a WebMercatorQuad one, reprojected from a WorldCRS84Quad one), or native "
                "(= WorldCRS84Quad for such an archive): the archive's own");
  c->add_option("--threads", a->threads, "Encoder threads (0 = all cores)")
      ->check(CLI::Range(0u, kMaxThreads))
      ->capture_default_str();
  c->add_flag("--json", a->json, "Print the result as JSON");
  c->add_flag("-q,--quiet", a->quiet, "No progress bar or summary");
  return [a] { return run_export(*a); };
}

}  // namespace vts::cli
