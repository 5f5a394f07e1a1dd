// vts build: image(s) or the synthetic source → PMTiles pyramid archive.
#include <cstdio>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <string_view>

#include "build_geo.hpp"
#include "build_inputs.hpp"
#include "commands.hpp"
#include "progress.hpp"
#include "vts/builder/builder.hpp"

namespace vts::cli {

namespace {

struct BuildArgs {
  std::vector<std::string> inputs;
  std::string input_list;
  std::string output;
  std::uint32_t tile = 256, border = 4;
  std::string codec = "lossless";
  int zstd_level = 3;
  std::string filter = "auto";
  std::string bc1_quality = "fast";
  std::string downsample = downsample_filter_name(BuildOptions{}.downsample);
  unsigned threads = 0;
  std::string grid, synthetic, region;
  GeoArgs geo;
  int region_level = 6;
  std::string name;
  bool json = false, quiet = false;
};

// The synthetic source's options: --synthetic WxH, --region, --region-level.
Result<SyntheticSpec> synthetic_spec(const BuildArgs& a) {
  SyntheticSpec s;
  if (!parse_pair(a.synthetic, 'x', s.width, s.height))
    return make_error(ErrorCode::invalid_argument,
                      "--synthetic '" + a.synthetic + "' is not of the form WxH");
  if (!a.region.empty()) {
    auto r = parse_texel_rect(a.region, "--region");
    if (!r) return r.error();
    s.region = *r;
  }
  s.region_level = a.region_level;
  return s;
}

Result<BuildOptions> build_options(const BuildArgs& a) {
  BuildOptions o;
  auto inputs = expand_inputs(a.inputs, a.input_list);
  if (!inputs) return inputs.error();
  o.inputs = std::move(inputs).value();
  o.output = a.output;
  o.tile_size = a.tile;
  o.border = a.border;
  auto codec = parse_codec_name(a.codec);
  if (!codec) return codec.error();
  o.codec = *codec;
  o.encode.zstd_level = a.zstd_level;
  o.encode.filter = a.filter == "none"       ? FilterChoice::none
                    : a.filter == "gradient" ? FilterChoice::gradient
                                             : FilterChoice::automatic;
  auto bc1 = parse_bc1_quality(a.bc1_quality);
  if (!bc1) return bc1.error();
  o.encode.bc1 = *bc1;
  auto filter = parse_downsample_filter(a.downsample);
  if (!filter)
    return make_error(ErrorCode::invalid_argument,
                      "--downsample '" + a.downsample + "' is not box or lanczos3");
  o.downsample = *filter;
  o.threads = a.threads;
  o.name = a.name;
  if (!a.grid.empty() && !parse_pair(a.grid, 'x', o.grid_columns, o.grid_rows))
    return make_error(ErrorCode::invalid_argument,
                      "--grid '" + a.grid + "' is not of the form CxR, e.g. 4x2");
  if (!a.synthetic.empty()) {
    auto s = synthetic_spec(a);
    if (!s) return s.error();
    o.synthetic = *s;
  } else if (!a.region.empty()) {
    return make_error(ErrorCode::invalid_argument, "--region applies to --synthetic builds only");
  }
  if (Status s = apply_geo_options(a.geo, o); !s) return s.error();
  return o;
}

void print_json(const BuildArgs& a, const BuildOptions& o, const BuildReport& r) {
  const Geometry& g = r.info.geometry;
  nlohmann::json j;
  j["output"] = a.output;
  j["input"] = r.input_description;
  j["width"] = g.width();
  j["height"] = g.height();
  j["tile_size"] = g.tile_size();
  j["border"] = g.border();
  j["max_zoom"] = g.max_zoom();
  j["codec"] = codec_name(r.info.codec);
  if (r.info.codec == CodecId::bc1) j["bc1_quality"] = bc1_quality_name(o.encode.bc1);
  j["downsample"] = r.info.downsample;
  j["tiles"] = r.stats.addressed_tiles;
  j["unique_tiles"] = r.stats.tile_contents;
  j["entries"] = r.stats.tile_entries;
  j["tile_bytes"] = r.stats.tile_bytes;
  j["file_bytes"] = r.stats.file_bytes;
  if (const auto& geo = r.info.georeference) {
    const LonLatBounds& b = geo->bounds;
    j["georeference"] = {{"tiling", std::string(tiling_name(geo->tiling))},
                         {"crs", std::string(tiling_crs(geo->tiling))},
                         {"bounds", {b.west, b.south, b.east, b.north}}};
  }
  j["passes"] = r.passes;
  j["window_width"] = r.window_width;
  if (!r.value_ranges.empty()) j["range"] = range_argument(r.value_ranges);
  j["warnings"] = r.warnings;
  j["seconds"] = r.seconds;
  j["tiles_per_second"] = r.seconds > 0 ? double(r.stats.addressed_tiles) / r.seconds : 0.0;
  std::printf("%s\n", j.dump(2).c_str());
}

void print_text(const BuildArgs& a, const BuildReport& r) {
  const Geometry& g = r.info.geometry;
  std::printf("built %s: %llux%llu, %d levels, %llu tiles (%llu unique), %s in %s (%.0f tiles/s)\n",
              a.output.c_str(), (unsigned long long)g.width(), (unsigned long long)g.height(),
              g.level_count(), (unsigned long long)r.stats.addressed_tiles,
              (unsigned long long)r.stats.tile_contents, human_bytes(r.stats.file_bytes).c_str(),
              human_duration(r.seconds).c_str(),
              r.seconds > 0 ? double(r.stats.addressed_tiles) / r.seconds : 0.0);
  if (!r.value_ranges.empty())
    std::printf("value range: --range %s\n", range_argument(r.value_ranges).c_str());
}

int run_build(const BuildArgs& a) {
  auto o = build_options(a);
  if (!o) return report_error(o.error());
  ProgressBar bar("build", "tiles", !a.quiet && !a.json);
  o->on_progress = [&](const BuildProgress& p) {
    if (p.tiles_total == 0 && p.inputs_total > 0)
      return bar.update(p.inputs_checked, p.inputs_total, "checking inputs");
    bar.update(p.tiles_done, p.tiles_total,
               human_bytes(p.bytes_written) + (p.finishing ? "  writing archive..." : ""));
  };
  // SIGINT/SIGTERM ask the build to stop cleanly (no output file is left); a second one kills.
  o->cancel = &install_stop_signals();
  o->on_warning = [&](const std::string& w) {
    bar.finish();
    std::fprintf(stderr, "warning: %s\n", w.c_str());
  };
  auto report = build_pyramid(*o);
  bar.finish();
  if (!report) return report_error(report.error());
  if (a.json)
    print_json(a, *o, *report);
  else if (!a.quiet)
    print_text(a, *report);
  return 0;
}

}  // namespace

Runner add_build(CLI::App& app) {
  auto a = std::make_shared<BuildArgs>();
  CLI::App* c = app.add_subcommand("build", "Cut images into a tile pyramid archive (PMTiles)");
  c->add_option("inputs", a->inputs,
                "Input image(s): anything OpenImageIO reads (C*R images row-major with --grid), "
                "or georeferenced rasters GDAL reads (placed by their georeference; a VRT too); "
                "a quoted pattern ('tiles/*.tif') is expanded here, sorted");
  c->add_option("--input-list", a->input_list,
                "A file of input paths, one a line, after the inputs given (blank lines and lines "
                "starting with # skipped; relative paths from the current directory, like "
                "gdalbuildvrt -input_file_list)");
  c->add_option("-o,--output", a->output, "Output archive (.pmtiles)")->required();
  c->add_option("--tile", a->tile, "Tile content size T, a power of two")->capture_default_str();
  c->add_option("--border", a->border, "Border B copied from neighbours")->capture_default_str();
  c->add_option("--codec", a->codec,
                "Tile codec: lossless (RGBA8, exact) or bc1 (GPU-native 4 bpp, lossy)")
      ->check(CLI::IsMember({"lossless", "bc1"}))
      ->capture_default_str();
  c->add_option("--bc1-quality", a->bc1_quality,
                "bc1 encoder effort: fast (stb_dxt), high (libsquish cluster fit), best "
                "(libsquish iterative cluster fit)")
      ->check(CLI::IsMember({"fast", "high", "best"}))
      ->capture_default_str();
  c->add_option("--downsample", a->downsample,
                "Filter making each level from the next finer one, in linear light: box (2x2 "
                "mean, fastest) or lanczos3 (separable Lanczos-3: sharper coarse levels, no moire)")
      ->check(CLI::IsMember({"box", "lanczos3"}))
      ->capture_default_str();
  c->add_option("--zstd-level", a->zstd_level, "zstd level (1..19)")
      ->check(CLI::Range(1, 19))
      ->capture_default_str();
  c->add_option("--filter", a->filter, "Prediction filter before zstd: auto|none|gradient")
      ->check(CLI::IsMember({"auto", "none", "gradient"}))
      ->capture_default_str();
  c->add_option("--threads", a->threads, "Encoder threads (0 = all cores)")
      ->check(CLI::Range(0u, kMaxThreads))
      ->capture_default_str();
  c->add_option("--grid", a->grid, "Inputs form a CxR mosaic, e.g. 4x2 (row-major order)");
  c->add_option("--synthetic", a->synthetic,
                "Build the built-in coordinate-encoding source of WxH texels instead of inputs");
  c->add_option("--region", a->region,
                "With --synthetic: only tiles over x0,y0,x1,y1 (finest texels) exist at levels "
                ">= --region-level");
  c->add_option("--region-level", a->region_level, "First level restricted to --region")
      ->check(CLI::Range(0, int(Geometry::kMaxZoom)))
      ->capture_default_str();
  add_geo_options(c, a->geo);
  c->add_option("--name", a->name, "Tileset name (default: output file stem)")
      ->check(CLI::Validator(
          [](std::string& name) { return name.empty() ? std::string("is empty") : ""; }, "NAME"));
  c->add_flag("--json", a->json, "Print the result as JSON");
  c->add_flag("-q,--quiet", a->quiet, "No progress bar or summary");
  return [a] { return run_build(*a); };
}

}  // namespace vts::cli
