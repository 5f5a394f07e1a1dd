#include "gdal_source.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <mutex>

#include <cpl_error.h>
#include <gdal.h>
#include <gdal_alg.h>
#include <gdal_utils.h>
#include <ogr_srs_api.h>

#include "vts/protocol/file_io.hpp"

namespace vts {

const char* resampling_name(Resampling r) noexcept {
  switch (r) {
    case Resampling::nearest:
      return "near";
    case Resampling::bilinear:
      return "bilinear";
    case Resampling::cubic:
      return "cubic";
    case Resampling::lanczos:
      return "lanczos";
  }
  return "?";
}

Result<Resampling> parse_resampling(std::string_view text) {
  for (Resampling r :
       {Resampling::nearest, Resampling::bilinear, Resampling::cubic, Resampling::lanczos})
    if (text == resampling_name(r)) return r;
  return make_error(ErrorCode::invalid_argument, "resampling '" + std::string(text) +
                                                     "' is not near, bilinear, cubic or lanczos");
}

namespace detail {

namespace {

void register_gdal() {
  static std::once_flag once;
  std::call_once(once, [] {
    GDALAllRegister();
    // GDAL's block cache defaults to 5 % of RAM (1.2 GiB here), which would be most of a build's
    // memory; 256 MiB holds the warped windows of a pass (64 MiB thrashes: 3x slower on a
    // stripe build). GDAL_CACHEMAX in the environment still rules.
    if (!std::getenv("GDAL_CACHEMAX")) GDALSetCacheMax64(GIntBig{256} << 20);
  });
}

// Collects GDAL's error messages on this thread instead of letting GDAL print them.
class ErrorCapture {
 public:
  ErrorCapture() {
    CPLPushErrorHandlerEx(&ErrorCapture::handle, this);
    CPLErrorReset();
  }
  ~ErrorCapture() { CPLPopErrorHandler(); }
  ErrorCapture(const ErrorCapture&) = delete;
  ErrorCapture& operator=(const ErrorCapture&) = delete;
  bool failed() const { return CPLGetLastErrorType() >= CE_Failure; }
  std::string text() const { return messages_.empty() ? "GDAL reported no reason" : messages_; }

 private:
  static void CPL_STDCALL handle(CPLErr level, CPLErrorNum, const char* msg) {
    auto* self = static_cast<ErrorCapture*>(CPLGetErrorHandlerUserData());
    if (level < CE_Failure || !self || self->messages_.size() > 400) return;
    if (!self->messages_.empty()) self->messages_ += "; ";
    self->messages_ += msg ? msg : "?";
  }
  std::string messages_;
};

using SrsPtr = std::unique_ptr<void, void (*)(OGRSpatialReferenceH)>;

// WGS 84 in longitude, latitude order.
SrsPtr lonlat_srs() {
  SrsPtr srs(OSRNewSpatialReference(nullptr), OSRDestroySpatialReference);
  OSRImportFromEPSG(srs.get(), 4326);
  OSRSetAxisMappingStrategy(srs.get(), OAMS_TRADITIONAL_GIS_ORDER);
  return srs;
}

const char* scheme_epsg(Tiling t) {
  return t == Tiling::web_mercator_quad ? "EPSG:3857" : "EPSG:4326";
}

std::string fmt(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

std::string short_name(const std::filesystem::path& p) {
  return p.filename().string();
}

}  // namespace

struct GdalSource::Input {
  std::filesystem::path path;
  GDALDatasetH src = nullptr;
  GDALDatasetH warped = nullptr;  // a VRT of the whole grid at the max level
  int bands = 0;                  // of `warped`: data bands (1 grey or 3 RGB) + alpha
  LonLatBounds bounds;            // its extent in degrees, clipped to the scheme
  TexelRect texels;               // the grid texels it touches
  double pixel_size = 0;          // in the scheme's CRS units
  std::string description;
  ~Input() {
    if (warped) GDALClose(warped);
    if (src) GDALClose(src);
  }
};

bool gdal_is_georeferenced(const std::filesystem::path& path) {
  // Only regular files: opening a FIFO or a device would block or read forever.
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return false;
  register_gdal();
  ErrorCapture quiet;
  GDALDatasetH ds =
      GDALOpenEx(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY, nullptr, nullptr, nullptr);
  if (!ds) return false;
  double gt[6];
  const bool geo = GDALGetGeoTransform(ds, gt) == CE_None && GDALGetSpatialRef(ds) != nullptr;
  GDALClose(ds);
  return geo;
}

namespace {

// Widens `b` (degrees) to the extremes of longitude and latitude along the raster's four edges. A
// projected edge can peak between any fixed samples (a UTM edge's latitude at the zone's central
// meridian: OCTTransformBounds' 21 points per edge missed 0.008 degrees), so each edge is sampled
// at 1024 points and every extreme refined between its neighbours by golden-section search.
void widen_to_edge_extremes(OGRCoordinateTransformationH ct, const double gt[6], int w, int h,
                            LonLatBounds& b) {
  const double corner[4][2] = {{0, 0}, {double(w), 0}, {double(w), double(h)}, {0, double(h)}};
  for (int e = 0; e < 4; ++e) {
    const double* p0 = corner[e];
    const double* p1 = corner[(e + 1) % 4];
    // Longitude (k = 0) or latitude (k = 1) at t along the edge; NaN where PROJ fails.
    auto at = [&](double t, int k) {
      const double px = p0[0] + t * (p1[0] - p0[0]), py = p0[1] + t * (p1[1] - p0[1]);
      double x = gt[0] + px * gt[1] + py * gt[2], y = gt[3] + px * gt[4] + py * gt[5], z = 0;
      int ok = 0;
      if (!OCTTransformEx(ct, 1, &x, &y, &z, &ok) || !ok) return double(NAN);
      return k == 0 ? x : y;
    };
    constexpr int kSamples = 1024;
    for (int k = 0; k < 2; ++k)
      for (const double sign : {-1.0, 1.0}) {  // minimum, maximum
        int best = -1;
        double best_v = -INFINITY;
        for (int i = 0; i <= kSamples; ++i) {
          const double v = sign * at(double(i) / kSamples, k);
          if (v > best_v) best = i, best_v = v;
        }
        if (best < 0) continue;
        double lo = double(std::max(best - 1, 0)) / kSamples;
        double hi = double(std::min(best + 1, kSamples)) / kSamples;
        const double g = (std::sqrt(5.0) - 1) / 2;
        for (int it = 0; it < 60; ++it) {
          const double m1 = hi - g * (hi - lo), m2 = lo + g * (hi - lo);
          const double v1 = sign * at(m1, k), v2 = sign * at(m2, k);
          if (v1 > v2 || std::isnan(v2))
            hi = m2;
          else
            lo = m1;
          best_v = std::max({best_v, v1, v2});
        }
        double& bound = k == 0 ? (sign < 0 ? b.west : b.east) : (sign < 0 ? b.south : b.north);
        bound = sign < 0 ? std::min(bound, -best_v) : std::max(bound, best_v);
      }
  }
}

// Opens one input and checks what the build needs of it: a georeference, 1..4 bands, 8-bit data
// or a value range; its extent in degrees and its pixel size in the scheme's CRS.
Status open_input(GdalSource::Input& in, const GdalSourceOptions& o, const SrsPtr& lonlat) {
  const std::string name = in.path.string();
  // Not a FIFO or a device (GDAL would block on it or read forever), not missing, not empty.
  if (Status st = check_input_file(in.path); !st) {
    if (st.error().code == ErrorCode::not_found)
      return make_error(ErrorCode::not_found, "input '" + name + "' does not exist");
    return st.error();
  }
  std::error_code ec;
  if (std::filesystem::file_size(in.path, ec) == 0 && !ec)
    return make_error(ErrorCode::truncated, "input '" + name + "' is truncated: empty");
  ErrorCapture errors;
  if (!GDALIdentifyDriverEx(name.c_str(), GDAL_OF_RASTER, nullptr, nullptr))
    return make_error(ErrorCode::invalid_argument, name + ": not a raster GDAL reads");
  in.src = GDALOpenEx(name.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY, nullptr, nullptr, nullptr);
  if (!in.src) return make_error(ErrorCode::corrupt, name + ": cannot open: " + errors.text());
  double gt[6];
  OGRSpatialReferenceH srs = GDALGetSpatialRef(in.src);
  if (GDALGetGeoTransform(in.src, gt) != CE_None || !srs)
    return make_error(ErrorCode::invalid_argument,
                      name +
                          ": no georeference (a CRS and a geotransform); inputs of a "
                          "georeferenced build must all have one");
  const int bands = GDALGetRasterCount(in.src);
  if (bands < 1 || bands > 4)
    return make_error(ErrorCode::invalid_argument,
                      name + ": " + std::to_string(bands) +
                          " bands; 1 (grey), 2 (grey, alpha), 3 (RGB) or 4 (RGBA) are supported");
  const GDALDataType type = GDALGetRasterDataType(GDALGetRasterBand(in.src, 1));
  const int w = GDALGetRasterXSize(in.src), h = GDALGetRasterYSize(in.src);
  if (type != GDT_Byte && !o.value_range) {
    double lo = INFINITY, hi = -INFINITY;
    for (int b = 1; b <= (bands == 2 || bands == 4 ? bands - 1 : bands); ++b) {
      double mm[2] = {0, 0};
      GDALComputeRasterMinMax(GDALGetRasterBand(in.src, b), TRUE, mm);
      lo = std::min(lo, mm[0]);
      hi = std::max(hi, mm[1]);
    }
    return make_error(ErrorCode::invalid_argument,
                      name + ": " + GDALGetDataTypeName(type) + " data (values about " + fmt(lo) +
                          " .. " + fmt(hi) +
                          "); give --range MIN,MAX to map values linearly to 0..255");
  }
  // The extent in its own CRS (the corners, for a rotated geotransform too), then in degrees.
  double min_x = INFINITY, min_y = INFINITY, max_x = -INFINITY, max_y = -INFINITY;
  for (int c = 0; c < 4; ++c) {
    const double px = (c & 1) ? w : 0, py = (c & 2) ? h : 0;
    const double x = gt[0] + px * gt[1] + py * gt[2], y = gt[3] + px * gt[4] + py * gt[5];
    min_x = std::min(min_x, x), max_x = std::max(max_x, x);
    min_y = std::min(min_y, y), max_y = std::max(max_y, y);
  }
  OGRSpatialReferenceH src_srs = OSRClone(srs);
  OSRSetAxisMappingStrategy(src_srs, OAMS_TRADITIONAL_GIS_ORDER);
  OGRCoordinateTransformationH ct = OCTNewCoordinateTransformation(src_srs, lonlat.get());
  OSRDestroySpatialReference(src_srs);
  LonLatBounds& b = in.bounds;
  const bool ok = ct && OCTTransformBounds(ct, min_x, min_y, max_x, max_y, &b.west, &b.south,
                                           &b.east, &b.north, 21);
  if (ok && b.west <= b.east) widen_to_edge_extremes(ct, gt, w, h, b);
  if (ct) OCTDestroyCoordinateTransformation(ct);
  if (!ok)
    return make_error(ErrorCode::invalid_argument,
                      name + ": its extent cannot be transformed to degrees: " + errors.text());
  // Its pixel size on the scheme's CRS: what gdalwarp would choose without -tr.
  const std::string dst = std::string("DST_SRS=") + scheme_epsg(o.tiling);
  const char* topts[] = {dst.c_str(), nullptr};
  void* tr = GDALCreateGenImgProjTransformer2(in.src, nullptr, const_cast<char**>(topts));
  double ogt[6];
  int pixels = 0, lines = 0;
  const bool sized = tr && GDALSuggestedWarpOutput(in.src, GDALGenImgProjTransform, tr, ogt,
                                                   &pixels, &lines) == CE_None;
  if (tr) GDALDestroyGenImgProjTransformer(tr);
  if (!sized)
    return make_error(
        ErrorCode::invalid_argument,
        name + ": cannot be transformed to " + scheme_epsg(o.tiling) + ": " + errors.text());
  in.pixel_size = ogt[1];
  in.description = short_name(in.path) + " " + std::to_string(w) + "x" + std::to_string(h) + " " +
                   std::to_string(bands) + "ch " + GDALGetDataTypeName(type);
  return {};
}

// The level: the given one, or the first whose texel is no larger than the finest input pixel,
// within 1 %: an input made for a level (1.19 m pixels for WebMercatorQuad z17's 1.1943 m) lands
// on it, not on the next with four times the texels for 0.4 % more detail.
Result<int> pick_level(const GdalSourceOptions& o, double pixel_size) {
  const int min_level = o.tiling == Tiling::world_crs84_quad ? 1 : 0;
  if (o.max_level) {
    if (*o.max_level < min_level || *o.max_level > int(Geometry::kMaxZoom))
      return make_error(ErrorCode::invalid_argument,
                        "max level " + std::to_string(*o.max_level) + " is outside " +
                            std::to_string(min_level) + ".." + std::to_string(Geometry::kMaxZoom) +
                            " for " + std::string(tiling_name(o.tiling)));
    return *o.max_level;
  }
  for (int z = min_level; z <= int(Geometry::kMaxZoom); ++z)
    if (level_cell_size(o.tiling, o.tile_size, z) <= pixel_size * 1.01) return z;
  return make_error(ErrorCode::invalid_argument,
                    "the inputs' pixels (" + fmt(pixel_size) + ") are finer than the finest level");
}

// gdalwarp onto the grid: a VRT dataset (nothing is computed until it is read).
Status warp_input(GdalSource::Input& in, const GdalSourceOptions& o, const Geometry& g, int z) {
  ErrorCapture errors;
  const CrsBounds top_left = tile_bounds_crs(o.tiling, o.tile_size, TileId{std::uint8_t(z), 0, 0});
  const double cell = level_cell_size(o.tiling, o.tile_size, z);
  const double west = top_left.min_x, north = top_left.max_y;
  const double east = west + cell * double(g.width()), south = north - cell * double(g.height());
  // -et 0: the exact transformer at every texel, not a linear approximation within 1/8 texel
  // (which depends on how the warper chunks the grid, so reading windows would shift it).
  std::vector<std::string> args = {"-of",
                                   "VRT",
                                   "-t_srs",
                                   scheme_epsg(o.tiling),
                                   "-te",
                                   fmt(west),
                                   fmt(south),
                                   fmt(east),
                                   fmt(north),
                                   "-ts",
                                   std::to_string(g.width()),
                                   std::to_string(g.height()),
                                   "-r",
                                   resampling_name(o.resampling),
                                   "-et",
                                   "0",
                                   "-ot",
                                   "Float32",
                                   "-dstalpha",
                                   "-wo",
                                   "DST_ALPHA_MAX=255"};
  const int bands = GDALGetRasterCount(in.src);
  if ((bands == 2 || bands == 4) &&
      GDALGetRasterColorInterpretation(GDALGetRasterBand(in.src, bands)) != GCI_AlphaBand)
    args.push_back("-srcalpha");
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  GDALWarpAppOptions* wo = GDALWarpAppOptionsNew(argv.data(), nullptr);
  int usage_error = 0;
  in.warped = wo ? GDALWarp("", nullptr, 1, &in.src, wo, &usage_error) : nullptr;
  if (wo) GDALWarpAppOptionsFree(wo);
  if (!in.warped)
    return make_error(ErrorCode::corrupt, in.path.string() + ": cannot warp: " + errors.text());
  in.bands = GDALGetRasterCount(in.warped);
  if (in.bands != 2 && in.bands != 4)
    return make_error(ErrorCode::internal, in.path.string() + ": the warped VRT has " +
                                               std::to_string(in.bands) + " bands");
  return {};
}

}  // namespace

Result<std::unique_ptr<GdalSource>> GdalSource::open(
    const std::vector<std::filesystem::path>& inputs, const GdalSourceOptions& options) {
  register_gdal();
  if (options.tiling == Tiling::none)
    return make_error(ErrorCode::invalid_argument, "georeferenced inputs need a tiling scheme");
  if (options.value_range && !(options.value_range->first < options.value_range->second))
    return make_error(ErrorCode::invalid_argument, "--range MIN,MAX needs MIN < MAX");
  std::unique_ptr<GdalSource> s(new GdalSource());
  s->options_ = options;
  const SrsPtr lonlat = lonlat_srs();
  double finest = INFINITY;
  const LonLatBounds extent = scheme_extent(options.tiling);
  bool first = true;
  for (const auto& path : inputs) {
    auto in = std::make_unique<Input>();
    in->path = path;
    if (Status st = open_input(*in, options, lonlat); !st) return st.error();
    LonLatBounds& b = in->bounds;
    if (b.west > b.east)
      return make_error(ErrorCode::unsupported, path.string() + ": crosses the antimeridian (" +
                                                    fmt(b.west) + " .. " + fmt(b.east) +
                                                    " degrees); not supported: split it in two");
    b = {std::max(b.west, extent.west), std::max(b.south, extent.south),
         std::min(b.east, extent.east), std::min(b.north, extent.north)};
    if (!(b.west < b.east && b.south < b.north))
      return make_error(ErrorCode::invalid_argument, path.string() + ": lies outside " +
                                                         std::string(tiling_name(options.tiling)) +
                                                         "'s extent");
    finest = std::min(finest, in->pixel_size);
    LonLatBounds& u = s->bounds_;
    u = first ? b
              : LonLatBounds{std::min(u.west, b.west), std::min(u.south, b.south),
                             std::max(u.east, b.east), std::max(u.north, b.north)};
    first = false;
    s->inputs_.push_back(std::move(in));
  }
  auto level = pick_level(options, finest);
  if (!level) return level.error();
  s->max_level_ = *level;
  const std::uint64_t width = std::uint64_t{options.tile_size} << *level;
  if (width > kMaxGeoreferencedWidth)
    return make_error(
        ErrorCode::too_large,
        "level " + std::to_string(*level) + " of " + std::string(tiling_name(options.tiling)) +
            " is " + std::to_string(width) + " texels wide; a georeferenced grid is limited to " +
            std::to_string(kMaxGeoreferencedWidth) +
            " (GDAL addresses rasters with int): give a coarser --max-level");
  auto g = tiling_geometry(options.tiling, tms_level(options.tiling, *level), options.tile_size,
                           options.border);
  if (!g) return g.error();
  s->width_ = g->width();
  s->height_ = g->height();
  for (auto& in : s->inputs_) {
    in->texels = footprint_texels(options.tiling, *g, in->bounds);
    if (Status st = warp_input(*in, options, *g, *level); !st) return st.error();
    if (!s->description_.empty()) s->description_ += ", ";
    s->description_ += in->description;
  }
  s->description_ += " -> " + std::string(tiling_name(options.tiling)) + " level " +
                     std::to_string(*level) + " (" + resampling_name(options.resampling) + ")";
  return s;
}

GdalSource::~GdalSource() = default;

Status GdalSource::read_window(std::uint64_t x0, std::uint64_t x1, std::uint64_t y,
                               std::uint32_t count, std::uint8_t* out) {
  const std::uint64_t out_w = x1 - x0;
  std::memset(out, 0, std::size_t(out_w) * count * 4);
  ErrorCapture errors;
  const double lo = options_.value_range ? options_.value_range->first : 0.0;
  const double scale = options_.value_range ? 255.0 / (options_.value_range->second - lo) : 1.0;
  for (auto& in : inputs_) {
    const TexelRect& r = in->texels;
    const std::uint64_t y0 = std::max(y, r.y0), y1 = std::min(y + count, r.y1);
    const std::uint64_t c0 = std::max(x0, r.x0), c1 = std::min(x1, r.x1);
    if (y0 >= y1 || c0 >= c1) continue;
    const std::uint64_t w = c1 - c0, h = y1 - y0;
    const int nb = in->bands;
    scratch_.resize(std::size_t(w) * h * nb);
    CPLErrorReset();
    const CPLErr err = GDALDatasetRasterIO(in->warped, GF_Read, int(c0), int(y0), int(w), int(h),
                                           scratch_.data(), int(w), int(h), GDT_Float32, nb,
                                           nullptr, nb * 4, GSpacing(w) * nb * 4, 4);
    if (err != CE_None || errors.failed())
      return make_error(ErrorCode::corrupt, in->path.string() + ": reading grid rows " +
                                                std::to_string(y0) + ".." + std::to_string(y1) +
                                                ": " + errors.text());
    for (std::uint64_t row = 0; row < h; ++row) {
      const float* src = scratch_.data() + row * w * nb;
      std::uint8_t* dst = out + ((y0 - y + row) * out_w + (c0 - x0)) * 4;
      for (std::uint64_t x = 0; x < w; ++x, src += nb, dst += 4) {
        const double a = std::clamp(double(src[nb - 1]), 0.0, 255.0) / 255.0;
        if (a <= 0) continue;
        double c[3];
        for (int k = 0; k < 3; ++k) {
          const double v = (src[nb == 2 ? 0 : k] - lo) * scale;
          c[k] = std::clamp(v, 0.0, 255.0);
        }
        // Over: later inputs win where they are opaque.
        const double da = dst[3] / 255.0, oa = a + da * (1 - a);
        for (int k = 0; k < 3; ++k)
          dst[k] = std::uint8_t(std::lround((c[k] * a + dst[k] * da * (1 - a)) / oa));
        dst[3] = std::uint8_t(std::lround(oa * 255));
      }
    }
  }
  return {};
}

}  // namespace detail

}  // namespace vts
