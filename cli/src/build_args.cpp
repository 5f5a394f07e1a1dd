// The options of a build, shared by `vts build` and `vts plan`.
#include "build_args.hpp"

#include "build_inputs.hpp"
#include "commands.hpp"
#include "progress.hpp"

namespace vts::cli {

namespace {

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

}  // namespace

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

void add_build_options(CLI::App* c, BuildArgs& a_ref) {
  BuildArgs* a = &a_ref;
  c->add_option("inputs", a->inputs,
                "Input image(s): anything OpenImageIO reads (C*R images row-major with --grid), "
                "or georeferenced rasters GDAL reads (placed by their georeference; a VRT too); "
                "a quoted pattern ('tiles/*.tif') is expanded here, sorted");
  c->add_option("--input-list", a->input_list,
                "A file of input paths, one a line, after the inputs given (blank lines and lines "
                "starting with # skipped; relative paths from the current directory, like "
                "gdalbuildvrt -input_file_list)");
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
}

}  // namespace vts::cli
