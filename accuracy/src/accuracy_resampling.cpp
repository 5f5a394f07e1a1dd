// Table: resampling (accuracy/include/vts/accuracy/accuracy.hpp). For each of the warper's
// resampling methods (BuildOptions::resampling): a GeoTIFF in UTM zone 32N whose pixels are an
// analytic, band-limited pattern of the projected coordinates is built onto WorldCRS84Quad, and
// the finest level read back from the archive is compared with the pattern itself evaluated at
// every texel centre (PROJ in double precision): a reference that owes nothing to GDAL's warper.
// Next to it, the build's time.
#include <cpl_conv.h>
#include <cpl_error.h>
#include <gdal.h>
#include <ogr_srs_api.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <memory>
#include <mutex>
#include <new>
#include <numbers>
#include <string>
#include <system_error>
#include <vector>

#include "resampling_detail.hpp"
#include "vts/accuracy/accuracy.hpp"
#include "vts/archive/inspect.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/builder/builder.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/protocol/tileset.hpp"

namespace vts::accuracy {

namespace detail {

namespace {

constexpr double kTwoPi = 2 * std::numbers::pi;

// One plane wave: amplitude, wavelength in source pixels, direction (radians from +x towards
// south, i.e. along increasing pixel rows), phase.
struct Wave {
  double amplitude, wavelength, angle, phase;
};
constexpr Wave kSmooth[] = {{50, 20.0, 0.35, 0.3}, {40, 13.0, 2.1, 1.1}};
constexpr Wave kFine[] = {{45, 3.2, 0.5, 0.7}, {35, 2.6, 1.9, 0.2}};

void register_gdal() {
  static std::once_flag once;
  std::call_once(once, [] { GDALAllRegister(); });
}

std::string gdal_message() {
  const char* m = CPLGetLastErrorMsg();
  return m && *m ? m : "GDAL reported no reason";
}

using SrsPtr = std::unique_ptr<void, void (*)(OGRSpatialReferenceH)>;

SrsPtr epsg_srs(int code) {
  SrsPtr srs(OSRNewSpatialReference(nullptr), OSRDestroySpatialReference);
  OSRImportFromEPSG(srs.get(), code);
  OSRSetAxisMappingStrategy(srs.get(), OAMS_TRADITIONAL_GIS_ORDER);
  return srs;
}

}  // namespace

const char* warp_pattern_name(WarpPattern p) noexcept {
  return p == WarpPattern::smooth ? "smooth" : "fine";
}

double PatternRaster::value(double x, double y) const noexcept {
  const double u = (x - x0) / pixel, v = (y0 - y) / pixel;  // in source pixels
  double f = 127.5;
  for (const Wave& w : pattern == WarpPattern::smooth ? kSmooth : kFine)
    f +=
        w.amplitude *
        std::sin(kTwoPi * (u * std::cos(w.angle) + v * std::sin(w.angle)) / w.wavelength + w.phase);
  return f;
}

Status write_pattern_geotiff(const PatternRaster& r, const std::filesystem::path& path) {
  register_gdal();
  CPLErrorReset();
  GDALDriverH drv = GDALGetDriverByName("GTiff");
  if (!drv) return make_error(ErrorCode::internal, "GDAL has no GTiff driver");
  GDALDatasetH ds = GDALCreate(drv, path.c_str(), r.width, r.height, 1, GDT_Float32, nullptr);
  if (!ds)
    return make_error(ErrorCode::io, "cannot create " + path.string() + ": " + gdal_message());
  double gt[6] = {r.x0, r.pixel, 0, r.y0, 0, -r.pixel};
  const SrsPtr srs = epsg_srs(r.epsg);
  std::vector<float> row(std::size_t(r.width));
  bool ok = GDALSetGeoTransform(ds, gt) == CE_None && GDALSetSpatialRef(ds, srs.get()) == CE_None;
  GDALRasterBandH band = GDALGetRasterBand(ds, 1);
  for (int j = 0; ok && j < r.height; ++j) {
    const double y = r.y0 - (j + 0.5) * r.pixel;
    for (int i = 0; i < r.width; ++i)
      row[std::size_t(i)] = float(r.value(r.x0 + (i + 0.5) * r.pixel, y));
    ok = GDALRasterIO(band, GF_Write, 0, j, r.width, 1, row.data(), r.width, 1, GDT_Float32, 0,
                      0) == CE_None;
  }
  const std::string why = ok ? "" : gdal_message();
  CPLErrorReset();
  GDALClose(ds);  // flushes the file; a failure shows as an error
  ok = ok && CPLGetLastErrorType() < CE_Failure;
  if (!ok)
    return make_error(ErrorCode::io, "cannot write " + path.string() + ": " +
                                         (why.empty() ? gdal_message() : why));
  return {};
}

double WarpError::rms() const noexcept {
  return texels ? std::sqrt(sum_sq / double(texels)) : std::numeric_limits<double>::quiet_NaN();
}
double WarpError::bias() const noexcept {
  return texels ? sum / double(texels) : std::numeric_limits<double>::quiet_NaN();
}
double WarpError::psnr() const noexcept {
  const double e = rms();
  return e > 0 ? 20 * std::log10(255.0 / e) : e == 0 ? std::numeric_limits<double>::infinity() : e;
}

Result<WarpError> score_warp(const std::filesystem::path& archive, const PatternRaster& r,
                             double margin, TexelPoint offset) {
  auto reader = archive::Reader::open(archive);
  if (!reader) return std::move(reader).error();
  auto info = archive::archive_tileset((*reader)->header(), (*reader)->metadata_json());
  if (!info) return std::move(info).error();
  if (!info->georeference)
    return make_error(ErrorCode::invalid_argument, archive.string() + " is not georeferenced");
  const Geometry& g = info->geometry;
  const Tiling tiling = info->georeference->tiling;
  const int z = g.max_zoom();
  const std::uint32_t T = g.tile_size(), S = g.stored_size(), B = g.border();
  const TileRect tr = footprint_tiles(tiling, g, z, info->georeference->bounds);
  // The footprint's tiles of the finest level, stitched: w x h texels from (x0, y0).
  const std::uint64_t x0 = std::uint64_t(tr.x0) * T, y0 = std::uint64_t(tr.y0) * T;
  const std::uint64_t w = std::uint64_t(tr.x1 - tr.x0) * T, h = std::uint64_t(tr.y1 - tr.y0) * T;
  std::vector<std::uint8_t> px(w * h * 4, 0);
  for (std::uint32_t ty = tr.y0; ty < tr.y1; ++ty)
    for (std::uint32_t tx = tr.x0; tx < tr.x1; ++tx) {
      const TileId id{std::uint8_t(z), tx, ty};
      auto bytes = (*reader)->get(id);
      if (!bytes && bytes.error().code == ErrorCode::not_found) continue;
      if (!bytes) return std::move(bytes).error();
      auto tile = decode_tile(*bytes, info->tile_spec());
      if (!tile) return std::move(tile).error();
      if (tile->format != PixelFormat::rgba8)
        return make_error(ErrorCode::corrupt, "tile " + id.to_string() + " is not rgba8");
      const TexelRect c = g.content_rect(id);
      for (std::uint64_t y = c.y0; y < c.y1; ++y)
        std::memcpy(&px[((y - y0) * w + (c.x0 - x0)) * 4],
                    &tile->pixels[((B + y - c.y0) * S + B) * 4], c.width() * 4);
    }

  const SrsPtr lonlat = epsg_srs(4326), projected = epsg_srs(r.epsg);
  OGRCoordinateTransformationH ct = OCTNewCoordinateTransformation(lonlat.get(), projected.get());
  if (!ct)
    return make_error(ErrorCode::internal, "PROJ: no transformation from EPSG:4326 to EPSG:" +
                                               std::to_string(r.epsg) + ": " + gdal_message());
  std::unique_ptr<void, void (*)(OGRCoordinateTransformationH)> ct_owner(
      ct, OCTDestroyCoordinateTransformation);
  WarpError e;
  std::vector<double> xs(w), ys(w);
  std::vector<int> ok(w);
  for (std::uint64_t j = 0; j < h; ++j) {
    for (std::uint64_t i = 0; i < w; ++i) {
      const LonLat p = texel_to_lonlat(
          tiling, T, z, {double(x0 + i) + 0.5 + offset.x, double(y0 + j) + 0.5 + offset.y});
      xs[i] = p.lon;
      ys[i] = p.lat;
    }
    if (!OCTTransformEx(ct, int(w), xs.data(), ys.data(), nullptr, ok.data()))
      return make_error(ErrorCode::internal, "PROJ cannot transform texel centres to EPSG:" +
                                                 std::to_string(r.epsg) + ": " + gdal_message());
    for (std::uint64_t i = 0; i < w; ++i) {
      const std::uint8_t* t = &px[(j * w + i) * 4];
      if (t[3] != 255 || !ok[i]) continue;
      const double u = (xs[i] - r.x0) / r.pixel, v = (r.y0 - ys[i]) / r.pixel;
      if (u < margin || v < margin || u > r.width - margin || v > r.height - margin) continue;
      const double d = double(t[0]) - r.value(xs[i], ys[i]);
      e.sum_sq += d * d;
      e.sum += d;
      e.max_abs = std::max(e.max_abs, std::fabs(d));
      ++e.texels;
    }
  }
  if (e.texels == 0)
    return make_error(ErrorCode::invalid_argument, archive.string() + ": no opaque texel lies " +
                                                       std::to_string(margin) +
                                                       " source pixels inside the source raster");
  return e;
}

}  // namespace detail

namespace {

namespace fs = std::filesystem;
using detail::PatternRaster;
using detail::WarpPattern;

constexpr WarpPattern kPatterns[] = {WarpPattern::smooth, WarpPattern::fine};
const double kDefaultError = BuildOptions{}.warp_error;

// Excluded from the score: texels whose centre is within this many source pixels of the source's
// edge, where the kernels (Lanczos: 3 pixels) reach outside the data.
constexpr double kMargin = 4;

std::string fixed(double v, int digits) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", digits, v);
  return b;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n == 0  ? std::numeric_limits<double>::quiet_NaN()
         : n % 2 ? v[n / 2]
                 : (v[n / 2 - 1] + v[n / 2]) / 2;
}

Result<AccuracyTable> measure_resampling(const AccuracyContext& ctx) {
  std::error_code ec;
  if (!fs::is_directory(ctx.work_dir, ec))
    return make_error(ErrorCode::not_found,
                      "work directory " + ctx.work_dir.string() + " does not exist");
  // WorldCRS84Quad level 6 at T = 256: texels of 360 / 16384 degrees, 2443 m north-south and
  // 1728 m east-west at 45 degrees north. Source pixels of 3200 m make the warp a mild upsampling
  // in both directions (1.31 and 1.85 texels per pixel), where the pattern itself is the ideal
  // result. (A much larger footprint distorts so much that GDAL's chunked Lanczos warp shows
  // seams, a separate matter.)
  const std::uint32_t tile = 256;
  const int level = 6;
  const int side = ctx.quick ? 96 : 256;
  const int runs = ctx.quick ? 1 : 3;
  PatternRaster base;
  base.epsg = 32632;
  base.pixel = 3200;
  base.width = base.height = side;
  base.x0 = 500000 - side * base.pixel / 2;   // centred on the zone's meridian, 9 degrees east
  base.y0 = 4985000 + side * base.pixel / 2;  // 45 degrees north

  AccuracyTable t;
  t.id = "resampling";
  t.title =
      "Resampling in the georeferenced warp: error against the analytic source pattern, and the "
      "build time it costs";
  t.columns = {{"pattern", "pattern", 0},
               {"resampling", "resampling", 0},
               {"rms_error", "RMS error (codes)", 3},
               {"max_error", "max error (codes)", 2},
               {"bias", "mean error (codes)", 3},
               {"psnr_db", "PSNR (dB)", 2},
               {"texels", "texels compared", 0},
               {"build_s", "build (s)", 3},
               {"time_vs_near", "time x near", 2},
               {"warp_error", "transformer error (px)", 3}};
  TablePlot plot;
  plot.id = "resampling_error_time";
  plot.title = "Warp resampling: RMS error against the analytic pattern vs build time";
  plot.x_label = "build time (s, median)";
  plot.y_label = "RMS error (8-bit codes)";
  plot.log_y = true;

  std::vector<std::vector<Cell>> transformer_rows;
  for (WarpPattern pattern : kPatterns) {
    PatternRaster r = base;
    r.pattern = pattern;
    const std::string pname = detail::warp_pattern_name(pattern);
    const fs::path tif = ctx.work_dir / ("resampling_" + pname + ".tif");
    if (Status s = detail::write_pattern_geotiff(r, tif); !s) return s.error();
    PlotSeries series{pname, {}, {}};
    double near_s = std::numeric_limits<double>::quiet_NaN();
    // The four methods at the default transformer error, then cubic with the exact transformer
    // and with gdalwarp's default 0.125 px (rows after both patterns').
    std::vector<std::pair<Resampling, double>> runs_of = {{Resampling::nearest, kDefaultError},
                                                          {Resampling::bilinear, kDefaultError},
                                                          {Resampling::cubic, kDefaultError},
                                                          {Resampling::lanczos, kDefaultError},
                                                          {Resampling::cubic, 0.0},
                                                          {Resampling::cubic, 0.125}};
    for (const auto& [m, et] : runs_of) {
      const std::string mname = resampling_name(m);
      BuildOptions o;
      o.warp_error = et;
      o.inputs = {tif};
      o.tiling = Tiling::world_crs84_quad;
      o.max_level = level;
      o.value_range = std::pair{0.0, 255.0};
      o.resampling = m;
      o.tile_size = tile;
      o.border = 4;
      o.name = "resampling-" + pname + "-" + mname;
      o.output = ctx.work_dir / ("resampling_" + pname + "_" + mname + ".pmtiles");
      const std::string variant = et == kDefaultError ? "" : " (-et " + fixed(et, 3) + ")";
      std::vector<double> seconds;
      for (int run = 0; run < runs; ++run) {
        ctx.say("resampling: " + pname + " pattern, " + mname + variant + " (" +
                std::to_string(run + 1) + "/" + std::to_string(runs) + ")");
        auto built = build_pyramid(o);
        if (!built) return std::move(built).error();
        seconds.push_back(built->seconds);
      }
      auto score = detail::score_warp(o.output, r, kMargin);
      if (!score) return std::move(score).error();
      fs::remove(o.output, ec);
      const double s = median(seconds);
      if (m == Resampling::nearest) near_s = s;
      std::vector<Cell> row{pname,
                            mname,
                            score->rms(),
                            score->max_abs,
                            score->bias(),
                            score->psnr(),
                            double(score->texels),
                            s,
                            s / near_s,
                            et};
      if (et != kDefaultError) {
        transformer_rows.push_back(std::move(row));
        continue;
      }
      t.rows.push_back(std::move(row));
      series.points.push_back({s, score->rms()});
      series.labels.push_back(mname);
    }
    fs::remove(tif, ec);
    plot.series.push_back(std::move(series));
  }
  for (auto& row : transformer_rows) t.rows.push_back(std::move(row));
  t.plots.push_back(std::move(plot));

  const std::string px = fixed(base.pixel, 0);
  t.notes.push_back(
      "source: a " + std::to_string(side) + " x " + std::to_string(side) +
      " one-band Float32 GeoTIFF in EPSG:32632 (WGS 84 / UTM 32N), " + px +
      " m pixels, centred at 9 E 45 N, written with GDAL; each pixel holds the pattern at its "
      "centre: 127.5 plus two plane waves in the projected coordinates (smooth: amplitudes 50 and "
      "40, wavelengths 20 and 13 pixels; fine: 45 and 35, wavelengths 3.2 and 2.6 pixels, near "
      "the 2-pixel Nyquist limit), so values stay inside 0..255 and the samples determine the "
      "pattern exactly");
  t.notes.push_back(
      "build: vts build's georeferenced path (GDAL warp, transformer error 0.01 px, Float32, "
      "--range "
      "0,255) onto WorldCRS84Quad level " +
      std::to_string(level) + " (T " + std::to_string(tile) +
      ", texels of 360/16384 degrees: 2443 m north-south, 1728 m east-west here), a mild "
      "upsampling of 1.31 and 1.85 texels per source pixel, where the ideal result is the pattern "
      "itself; lossless tiles");
  t.notes.push_back(
      "error: the finest level read back from the archive; every opaque texel whose centre lies "
      "at least " +
      fixed(kMargin, 0) +
      " source pixels inside the source (the kernels then see only data) is compared, in 8-bit "
      "codes, with the pattern evaluated exactly at the texel centre: its longitude and latitude "
      "from the tiling scheme, transformed to UTM by PROJ (OGRCoordinateTransformation, double "
      "precision). The reference owes nothing to GDAL's warper. Rounding to 8 bits alone costs "
      "0.289 RMS and 0.5 max");
  t.notes.push_back("build time: the median of " + std::to_string(runs) +
                    " builds of the whole archive (warp, pyramid, encoding, all cores); time x "
                    "near divides by near's median on the same pattern. The build reads only the "
                    "footprint's ~0.16 million texels, so these are small and noisy; the "
                    "transformer rows show what PROJ at every texel costs (-et 0)");
  return t;
}

}  // namespace

Result<AccuracyTable> resampling_table(const AccuracyContext& ctx) {
  try {
    return measure_resampling(ctx);
  } catch (const std::bad_alloc&) {
    return make_error(ErrorCode::too_large, "resampling table: out of memory");
  } catch (const std::exception& e) {
    return make_error(ErrorCode::internal, std::string("resampling table: ") + e.what());
  }
}

}  // namespace vts::accuracy
