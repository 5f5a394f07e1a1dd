#include "gdal_source.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <mutex>
#include <numbers>

#include <cpl_error.h>
#include <cpl_minixml.h>
#include <cpl_string.h>
#include <gdal.h>
#include <gdal_alg.h>
#include <gdal_utils.h>
#include <ogr_srs_api.h>

#include "gdal_output.hpp"
#include "lonlat_pieces.hpp"
#include "vts/base/file_io.hpp"

namespace vts {
inline namespace builder {

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

// The deepest chain of VRTs naming VRTs as sources that check_vrt_sources follows.
constexpr int kMaxVrtDepth = 16;

bool is_vrt(const std::filesystem::path& path) {
  GDALDriverH d = GDALIdentifyDriverEx(path.c_str(), GDAL_OF_RASTER, nullptr, nullptr);
  return d && std::strcmp(GDALGetDriverShortName(d), "VRT") == 0;
}

// What check_vrt_sources needs of a VRT's XML: the local files it names (SourceFilename,
// SourceDataset: sources, raw bands, overviews, a warped VRT's dataset), resolved as GDAL resolves
// them, and whether it has a raw band. /vsi paths are GDAL's virtual file systems, not files here:
// left to GDAL.
struct VrtScan {
  std::vector<std::filesystem::path> files;
  bool raw_band = false;
};
VrtScan scan_vrt(const CPLXMLNode* root, const std::filesystem::path& dir) {
  VrtScan scan;
  std::vector<const CPLXMLNode*> todo{root};  // no recursion: the XML may nest deep
  while (!todo.empty()) {
    const CPLXMLNode* n = todo.back();
    todo.pop_back();
    for (; n; n = n->psNext) {
      if (n->eType != CXT_Element) continue;
      if (n->psChild) todo.push_back(n->psChild);
      if (std::strcmp(n->pszValue, "VRTRasterBand") == 0 &&
          EQUAL(CPLGetXMLValue(n, "subClass", ""), "VRTRawRasterBand"))
        scan.raw_band = true;
      if (std::strcmp(n->pszValue, "SourceFilename") != 0 &&
          std::strcmp(n->pszValue, "SourceDataset") != 0)
        continue;
      const std::string name = CPLGetXMLValue(n, nullptr, "");
      if (name.empty() || name.rfind("/vsi", 0) == 0) continue;
      const bool relative = CPLTestBool(CPLGetXMLValue(n, "relativeToVRT", "0"));
      scan.files.push_back(relative ? dir / name : std::filesystem::path(name));
    }
  }
  return scan;
}

// A VRT input, checked before GDAL opens it (opening it opens its sources):
// - a raw band (VRTRawRasterBand: any local file's bytes as pixels) is invalid_argument unless
//   GDAL_VRT_ENABLE_RAWRASTERBAND=YES is in the environment (GDAL before 3.7 has no such switch of
//   its own; register_gdal() sets GDAL's for later ones);
// - each source that exists is a regular file (open_input_file): GDAL would block on a FIFO or
//   read a device forever. A name that is no file here may be GDAL's own syntax
//   (NETCDF:"f.nc":v): GDAL resolves it;
// - a source that is a VRT in turn is checked too, at most kMaxVrtDepth deep.
// invalid_argument naming the VRT (and the source).
Status check_vrt_sources(const std::filesystem::path& vrt, int depth = 0) {
  if (depth > kMaxVrtDepth)
    return make_error(ErrorCode::invalid_argument, vrt.string() +
                                                       ": VRTs name VRTs as sources more than " +
                                                       std::to_string(kMaxVrtDepth) + " deep");
  std::unique_ptr<CPLXMLNode, void (*)(CPLXMLNode*)> xml(CPLParseXMLFile(vrt.c_str()),
                                                         CPLDestroyXMLNode);
  if (!xml) return {};  // GDAL's open reports what is wrong with it
  const VrtScan scan = scan_vrt(xml.get(), vrt.parent_path());
  const char* raw = std::getenv("GDAL_VRT_ENABLE_RAWRASTERBAND");
  if (scan.raw_band && !(raw && CPLTestBool(raw)))
    return make_error(ErrorCode::invalid_argument,
                      vrt.string() +
                          ": has a raw band (VRTRawRasterBand), which reads any file as pixels; "
                          "refused unless GDAL_VRT_ENABLE_RAWRASTERBAND=YES is set");
  for (const std::filesystem::path& source : scan.files) {
    const Status checked = check_input_file(source);
    if (!checked && checked.error().code != ErrorCode::not_found) {
      Error e = checked.error();
      e.message = vrt.string() + ": its source " + e.message;
      return e;
    }
    if (checked && is_vrt(source))
      if (Status st = check_vrt_sources(source, depth + 1); !st) return st;
  }
  return {};
}

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

// A data value: 8 significant digits.
std::string fmt_value(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.8g", v);
  return buf;
}

std::string short_name(const std::filesystem::path& p) {
  return p.filename().string();
}

}  // namespace

struct GdalSource::Input {
  std::filesystem::path path;
  // Found by probing.
  int src_bands = 0;
  std::vector<int> data_bands;  // 1-based bands of the file: 1 (grey) or 3 (RGB)
  int alpha_band = 0;           // its alpha band, 0 for none
  bool tagged_alpha = false;    // the alpha band's colour interpretation says alpha
  bool integer = true;          // integer data
  std::uint64_t pixels = 0;
  std::vector<std::pair<double, double>> observed;  // per data band: approximate min, max
  // Its extent in degrees, clipped to the scheme: one piece, or two when it crosses the
  // antimeridian (lonlat_pieces.hpp); `bounds` holds them all (every longitude for two).
  std::vector<LonLatBounds> pieces;
  LonLatBounds bounds;
  std::vector<TexelRect> texels;  // the grid texels each piece touches
  // A geographic raster crossing the antimeridian: the source column where it lies (else NaN).
  // Each piece is then warped from its own side of the raster (cut_columns), so no warped block
  // meets the place where GDAL wraps the raster's longitudes: a block there takes the whole raster
  // as its source window and blurs (GDAL widens its kernel by the window's scale).
  double seam_column = NAN;
  double pixel_size = 0;  // in the scheme's CRS units
  std::string description;
  std::string warning;  // what probing found to tell the user (probe_input), or empty
  // While open (GdalSource::acquire).
  GDALDatasetH src = nullptr;
  GDALDatasetH selected = nullptr;  // a VRT of the chosen bands of `src` (with --bands)
  GDALDatasetH warped = nullptr;    // a VRT of the whole grid at the max level
  // With a seam: per piece, a VRT of its side of the raster's columns, and its warped VRT.
  std::vector<GDALDatasetH> sides, warped_sides;
  int bands = 0;  // of `warped`: the data bands + alpha
  std::uint64_t last_use = 0;
  GDALDatasetH warped_piece(std::size_t k) const {
    return warped_sides.empty() ? warped : warped_sides[k];
  }
  void close() {
    for (GDALDatasetH d : warped_sides) GDALClose(d);
    for (GDALDatasetH d : sides) GDALClose(d);
    warped_sides.clear(), sides.clear();
    if (warped) GDALClose(warped);
    if (selected) GDALClose(selected);
    if (src) GDALClose(src);
    warped = selected = src = nullptr;
  }
  ~Input() { close(); }
};

bool gdal_is_georeferenced(const std::filesystem::path& path) {
  // Only regular files: opening a FIFO or a device would block or read forever.
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return false;
  register_gdal();
  GdalErrors quiet;
  // A VRT is GDAL's alone, and opening it opens its sources: GdalSource::open checks them first
  // (and reports a VRT without a georeference).
  if (is_vrt(path)) return true;
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
// Latitudes only for an extent crossing the antimeridian: its longitudes peak at +-180 there.
void widen_to_edge_extremes(OGRCoordinateTransformationH ct, const double gt[6], int w, int h,
                            LonLatBounds& b, bool longitudes) {
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
    for (int k = longitudes ? 0 : 1; k < 2; ++k)
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

// Which bands of an input are data and which is alpha: by --bands, else by the band count.
Status choose_bands(GdalSource::Input& in, GDALDatasetH ds, const GdalSourceOptions& o) {
  const std::string name = in.path.string();
  const int n = in.src_bands;
  const auto is_alpha = [&](int b) {
    return GDALGetRasterColorInterpretation(GDALGetRasterBand(ds, b)) == GCI_AlphaBand;
  };
  if (o.bands.empty()) {
    if (n < 1 || n > 4)
      return make_error(ErrorCode::invalid_argument,
                        name + ": " + std::to_string(n) +
                            " bands; 1 (grey), 2 (grey, alpha), 3 (RGB) or 4 (RGBA) are supported "
                            "as they are: pick 1 or 3 with --bands, e.g. --bands 4,3,2");
    in.data_bands = n <= 2 ? std::vector<int>{1} : std::vector<int>{1, 2, 3};
    in.alpha_band = n == 2 || n == 4 ? n : 0;
  } else {
    for (int b : o.bands)
      if (b < 1 || b > n)
        return make_error(ErrorCode::invalid_argument,
                          name + ": has " + std::to_string(n) + " band" + (n == 1 ? "" : "s") +
                              "; --bands asks for band " + std::to_string(b));
    in.data_bands = o.bands;
    for (int b = 1; b <= n && !in.alpha_band; ++b)
      if (is_alpha(b) && std::find(o.bands.begin(), o.bands.end(), b) == o.bands.end())
        in.alpha_band = b;
  }
  in.tagged_alpha = in.alpha_band && is_alpha(in.alpha_band);
  return {};
}

// The approximate min and max of each data band (GDAL's approximate statistics: an overview or a
// sample of the blocks). A band with no valid value (all nodata) gets an empty range (min > max).
void observe_values(GdalSource::Input& in, GDALDatasetH ds) {
  in.observed.clear();
  for (int b : in.data_bands) {
    double mm[2] = {INFINITY, -INFINITY};
    CPLErrorReset();
    if (GDALComputeRasterMinMax(GDALGetRasterBand(ds, b), TRUE, mm) != CE_None ||
        !std::isfinite(mm[0]) || !std::isfinite(mm[1]))
      mm[0] = INFINITY, mm[1] = -INFINITY;
    in.observed.emplace_back(mm[0], mm[1]);
  }
  CPLErrorReset();
}

std::pair<double, double> observed_union(const GdalSource::Input& in) {
  std::pair<double, double> u{INFINITY, -INFINITY};
  for (const auto& [lo, hi] : in.observed) u = {std::min(u.first, lo), std::max(u.second, hi)};
  return u;
}

// Values used as they are (no range): refused when they go beyond 0..255 (they would clip).
Status check_unmapped(const GdalSource::Input& in, GDALDataType type) {
  const auto [lo, hi] = observed_union(in);
  if (lo > hi || (lo >= 0 && hi <= 255)) return {};
  return make_error(ErrorCode::invalid_argument,
                    in.path.string() + ": " + GDALGetDataTypeName(type) + " data (values about " +
                        fmt_value(lo) + " .. " + fmt_value(hi) +
                        ") would clip to 0..255: give --range MIN,MAX to map values linearly to "
                        "0..255, or --range auto (the mosaic's 2%..98% percentiles per band)");
}

// The source pixel (column, row) at `p` (degrees), nullopt where PROJ cannot take it there. A
// longitude a whole turn away is the same place, and the one on the raster is taken (a file in
// EPSG:4326 from 150 to 210 holds -170 as 190); off every raster, the nearest point of it.
std::optional<std::pair<double, double>> source_pixel_at(GDALDatasetH ds, const double gt[6],
                                                         const SrsPtr& lonlat, LonLat p) {
  double inv[6];
  if (!GDALInvGeoTransform(const_cast<double*>(gt), inv)) return std::nullopt;
  OGRSpatialReferenceH src = OSRClone(GDALGetSpatialRef(ds));
  OSRSetAxisMappingStrategy(src, OAMS_TRADITIONAL_GIS_ORDER);
  OGRCoordinateTransformationH ct = OCTNewCoordinateTransformation(lonlat.get(), src);
  OSRDestroySpatialReference(src);
  const double w = GDALGetRasterXSize(ds), h = GDALGetRasterYSize(ds);
  std::optional<std::pair<double, double>> first;
  for (const double turn : {0.0, 360.0, -360.0}) {
    double x = p.lon + turn, y = p.lat, z = 0;
    int ok = 0;
    if (!ct || !OCTTransformEx(ct, 1, &x, &y, &z, &ok) || !ok) continue;
    const double px = inv[0] + x * inv[1] + y * inv[2], py = inv[3] + x * inv[4] + y * inv[5];
    if (px >= 0 && px <= w && py >= 0 && py <= h) {
      first = {px, py};
      break;
    }
    if (!first) first = {std::clamp(px, 0.0, w), std::clamp(py, 0.0, h)};
  }
  if (ct) OCTDestroyCoordinateTransformation(ct);
  CPLErrorReset();  // a failed candidate is no error of the input's
  return first;
}

// The input's pixel size on the scheme's CRS, at resolution_point() of its pieces (the equator
// when it spans it): GDALSuggestedWarpOutput's rule (the diagonal of the footprint on the target
// over the diagonal in pixels) applied to a copy of the raster's shape one pixel long at that
// point. For the whole raster GDAL's rule is degenerate where the target stretches without bound
// (a +-90 degree input on Web Mercator: one 256-texel tile); at one point it is the resolution
// there, and for a small input it is what GDAL suggests. nullopt where PROJ cannot take it.
std::optional<double> input_pixel_size(GDALDatasetH ds, const double gt[6], const SrsPtr& lonlat,
                                       const std::vector<LonLatBounds>& pieces, Tiling t) {
  const std::string dst = std::string("DST_SRS=") + scheme_epsg(t);
  const char* topts[] = {dst.c_str(), nullptr};
  void* tr = GDALCreateGenImgProjTransformer2(ds, nullptr, const_cast<char**>(topts));
  if (!tr) return std::nullopt;
  const double w = GDALGetRasterXSize(ds), h = GDALGetRasterYSize(ds);
  const auto [cx, cy] =
      source_pixel_at(ds, gt, lonlat, resolution_point(pieces)).value_or(std::pair{w / 2, h / 2});
  const double sx = w / std::max(w, h), sy = h / std::max(w, h);
  double x[4] = {cx - sx / 2, cx + sx / 2, cx - sx / 2, cx + sx / 2};
  double y[4] = {cy - sy / 2, cy - sy / 2, cy + sy / 2, cy + sy / 2};
  double z[4] = {0, 0, 0, 0};
  int ok[4] = {0, 0, 0, 0};
  const bool done = GDALGenImgProjTransform(tr, FALSE, 4, x, y, z, ok) != 0;
  GDALDestroyGenImgProjTransformer(tr);
  if (!done || !(ok[0] && ok[1] && ok[2] && ok[3])) return std::nullopt;
  // A step across the antimeridian comes back a whole turn away (179.9 .. -179.9).
  const double turn = t == Tiling::web_mercator_quad ? 2 * kWebMercatorHalfSide : 360.0;
  for (double& v : x) v -= turn * std::round((v - x[0]) / turn);
  const auto [x0, x1] = std::minmax_element(x, x + 4);
  const auto [y0, y1] = std::minmax_element(y, y + 4);
  const double size = std::hypot(*x1 - *x0, *y1 - *y0) / std::hypot(sx, sy);
  if (!std::isfinite(size) || !(size > 0)) return std::nullopt;
  return size;
}

// Whether GDAL's warp onto the scheme's grid reads any of the raster inside `piece`: a 5 x 5 grid
// of points across it taken back to source pixels as the warper takes them (its transformer,
// target to source, which wraps a geographic source's longitudes to its own range). False for
// the part of an EPSG:3857 raster past x = 20037508 m: PROJ puts 190 degrees at -170.
bool piece_reached(GDALDatasetH ds, Tiling t, const LonLatBounds& piece) {
  const std::string dst = std::string("DST_SRS=") + scheme_epsg(t);
  const char* topts[] = {dst.c_str(), nullptr};
  void* tr = GDALCreateGenImgProjTransformer2(ds, nullptr, const_cast<char**>(topts));
  if (!tr) return false;
  constexpr int kSide = 5;
  double x[kSide * kSide], y[kSide * kSide], z[kSide * kSide] = {};
  int ok[kSide * kSide] = {};
  for (int i = 0; i < kSide * kSide; ++i) {
    const double lon = piece.west + (piece.east - piece.west) * (i % kSide + 0.5) / kSide;
    const double lat = piece.south + (piece.north - piece.south) * (i / kSide + 0.5) / kSide;
    x[i] = lon, y[i] = lat;
    if (t == Tiling::web_mercator_quad) {  // spherical Mercator, EPSG:3857's formulas
      x[i] = lon / 180 * kWebMercatorHalfSide;
      y[i] = std::log(std::tan(std::numbers::pi / 4 + lat * std::numbers::pi / 360)) /
             std::numbers::pi * kWebMercatorHalfSide;
    }
  }
  GDALGenImgProjTransform(tr, TRUE, kSide * kSide, x, y, z, ok);
  GDALDestroyGenImgProjTransformer(tr);
  CPLErrorReset();  // points PROJ cannot take are not reached, no error of the input's
  const double w = GDALGetRasterXSize(ds), h = GDALGetRasterYSize(ds);
  for (int i = 0; i < kSide * kSide; ++i)
    if (ok[i] && x[i] >= 0 && x[i] <= w && y[i] >= 0 && y[i] <= h) return true;
  return false;
}

// Opens one input, checks what the build needs of it (a georeference, its bands; its extent in
// degrees and its pixel size in the scheme's CRS, its approximate values) and closes it.
Status probe_input(GdalSource::Input& in, const GdalSourceOptions& o, const SrsPtr& lonlat) {
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
  GdalErrors errors;
  if (!GDALIdentifyDriverEx(name.c_str(), GDAL_OF_RASTER, nullptr, nullptr))
    return make_error(ErrorCode::invalid_argument, name + ": not a raster GDAL reads");
  if (is_vrt(in.path))
    if (Status st = check_vrt_sources(in.path); !st) return st;
  std::unique_ptr<void, void (*)(GDALDatasetH)> ds(
      GDALOpenEx(name.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY, nullptr, nullptr, nullptr),
      [](GDALDatasetH d) { GDALClose(d); });
  if (!ds) return make_error(ErrorCode::corrupt, name + ": cannot open: " + errors.text());
  double gt[6];
  OGRSpatialReferenceH srs = GDALGetSpatialRef(ds.get());
  if (GDALGetGeoTransform(ds.get(), gt) != CE_None || !srs)
    return make_error(ErrorCode::invalid_argument,
                      name +
                          ": no georeference (a CRS and a geotransform); inputs of a "
                          "georeferenced build must all have one");
  for (const double v : gt)
    if (!std::isfinite(v))
      return make_error(ErrorCode::invalid_argument,
                        name + ": its geotransform is not finite (" + fmt(gt[0]) + ", " +
                            fmt(gt[1]) + ", " + fmt(gt[2]) + ", " + fmt(gt[3]) + ", " + fmt(gt[4]) +
                            ", " + fmt(gt[5]) + "): fix its georeference");
  in.src_bands = GDALGetRasterCount(ds.get());
  if (Status st = choose_bands(in, ds.get(), o); !st) return st;
  if (!o.value_ranges.empty() && o.value_ranges.size() != 1 &&
      o.value_ranges.size() != in.data_bands.size())
    return make_error(ErrorCode::invalid_argument,
                      name + ": " + std::to_string(o.value_ranges.size()) +
                          " value ranges for its " + std::to_string(in.data_bands.size()) +
                          " data band(s): give one MIN,MAX for all, or one per band");
  const GDALDataType type = GDALGetRasterDataType(GDALGetRasterBand(ds.get(), in.data_bands[0]));
  in.integer = GDALDataTypeIsInteger(type);
  const int w = GDALGetRasterXSize(ds.get()), h = GDALGetRasterYSize(ds.get());
  in.pixels = std::uint64_t(w) * std::uint64_t(h);
  observe_values(in, ds.get());
  if (o.value_ranges.empty() && !o.auto_range && !o.ranges)
    if (Status st = check_unmapped(in, type); !st) return st;
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
  LonLatBounds b;
  const bool ok = ct && OCTTransformBounds(ct, min_x, min_y, max_x, max_y, &b.west, &b.south,
                                           &b.east, &b.north, 21);
  if (ok) widen_to_edge_extremes(ct, gt, w, h, b, b.west <= b.east);
  if (ct) OCTDestroyCoordinateTransformation(ct);
  if (!ok)
    return make_error(ErrorCode::invalid_argument,
                      name + ": its extent cannot be transformed to degrees: " + errors.text());
  // Cut at the antimeridian: a piece crossing it, or a 0..360 grid, is placed in two pieces.
  in.pieces = clip_pieces(split_at_antimeridian(b), scheme_extent(o.tiling));
  in.bounds = pieces_hull(in.pieces);
  if (in.pieces.empty()) return {};  // open() refuses it, naming the scheme
  // Its pixel size on the scheme's CRS, where it is measured (input_pixel_size).
  const std::optional<double> size = input_pixel_size(ds.get(), gt, lonlat, in.pieces, o.tiling);
  if (!size)
    return make_error(
        ErrorCode::invalid_argument,
        name + ": cannot be transformed to " + scheme_epsg(o.tiling) + ": " + errors.text());
  in.pixel_size = *size;
  if (in.pieces.size() == 2 && OSRIsGeographic(srs) && gt[1] > 0 && gt[2] == 0 && gt[4] == 0)
    for (double lon = -180; lon <= 540 && std::isnan(in.seam_column); lon += 360)
      if (const double c = (lon - gt[0]) / gt[1]; c > 0 && c < w) in.seam_column = c;
  // A piece of a crossing input that GDAL's warp cannot reach (a projected raster whose x goes
  // past its CRS's 180 degrees) would be silently empty: said, as gdalwarp leaves it out too.
  for (const LonLatBounds& piece : in.pieces)
    if (in.pieces.size() > 1 && !piece_reached(ds.get(), o.tiling, piece))
      in.warning = name + ": its part at longitudes " + fmt_value(piece.west) + " .. " +
                   fmt_value(piece.east) +
                   " lies beyond its CRS's own range of x (past 180 degrees); GDAL's warp, as "
                   "gdalwarp, leaves it out: reproject it (gdalwarp -t_srs) or fix its "
                   "georeference";
  in.description = short_name(in.path) + " " + std::to_string(w) + "x" + std::to_string(h) + " " +
                   std::to_string(in.src_bands) + "ch " + GDALGetDataTypeName(type);
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

std::vector<char*> argv_of(std::vector<std::string>& args) {
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  return argv;
}

// With --bands: a VRT of the chosen data bands of in.src, then its alpha band (gdal_translate -b).
Status select_bands(GdalSource::Input& in) {
  std::vector<std::string> args = {"-of", "VRT"};
  for (int b : in.data_bands) args.insert(args.end(), {"-b", std::to_string(b)});
  if (in.alpha_band) args.insert(args.end(), {"-b", std::to_string(in.alpha_band)});
  std::vector<char*> argv = argv_of(args);
  GDALTranslateOptions* to = GDALTranslateOptionsNew(argv.data(), nullptr);
  int usage_error = 0;
  in.selected = to ? GDALTranslate("", in.src, to, &usage_error) : nullptr;
  if (to) GDALTranslateOptionsFree(to);
  if (!in.selected) return make_error(ErrorCode::corrupt, in.path.string() + ": cannot pick bands");
  return {};
}

// Columns [c0, c1) of `ds`, every row, as a VRT keeping their georeference (gdal_translate
// -srcwin); nullptr when GDAL cannot make it.
GDALDatasetH source_columns(GDALDatasetH ds, int c0, int c1, int h) {
  std::vector<std::string> args = {
      "-of", "VRT", "-srcwin", std::to_string(c0), "0", std::to_string(c1 - c0), std::to_string(h)};
  std::vector<char*> argv = argv_of(args);
  GDALTranslateOptions* to = GDALTranslateOptionsNew(argv.data(), nullptr);
  int usage_error = 0;
  GDALDatasetH out = to ? GDALTranslate("", ds, to, &usage_error) : nullptr;
  if (to) GDALTranslateOptionsFree(to);
  return out;
}

// gdalwarp onto the grid (`width` x `height` texels at level z): a VRT dataset (nothing is
// computed until it is read).
Status warp_input(GdalSource::Input& in, const GdalSourceOptions& o, std::uint64_t width,
                  std::uint64_t height, int z) {
  GdalErrors errors;
  in.src =
      GDALOpenEx(in.path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY, nullptr, nullptr, nullptr);
  if (!in.src)
    return make_error(ErrorCode::corrupt, in.path.string() + ": cannot open: " + errors.text());
  if (!o.bands.empty())
    if (Status st = select_bands(in); !st) return st;
  const CrsBounds top_left = tile_bounds_crs(o.tiling, o.tile_size, TileId{std::uint8_t(z), 0, 0});
  const double cell = level_cell_size(o.tiling, o.tile_size, z);
  const double west = top_left.min_x, north = top_left.max_y;
  const double east = west + cell * double(width), south = north - cell * double(height);
  // -et: the transformer is exact at sample points and linear within warp_error pixels between
  // them (PROJ's trigonometry at every texel, -et 0, was 70 % of a UTM mosaic's build). The warped
  // VRT warps whole blocks of its own grid, so the approximation does not depend on the windows a
  // build reads (GdalSource.TexelsDoNotDependOnTheWindowsThatReadThem).
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
                                   std::to_string(width),
                                   std::to_string(height),
                                   "-r",
                                   resampling_name(o.resampling),
                                   "-et",
                                   fmt(o.warp_error),
                                   "-ot",
                                   "Float32",
                                   "-dstalpha",
                                   "-wo",
                                   "DST_ALPHA_MAX=255"};
  // An alpha band is the last band of what is warped; GDAL finds it alone when it says alpha.
  if (in.alpha_band && !in.tagged_alpha) args.push_back("-srcalpha");
  std::vector<char*> argv = argv_of(args);
  GDALWarpAppOptions* wo = GDALWarpAppOptionsNew(argv.data(), nullptr);
  if (!wo) return make_error(ErrorCode::internal, in.path.string() + ": bad warp options");
  int usage_error = 0;
  GDALDatasetH from = in.selected ? in.selected : in.src;
  if (std::isnan(in.seam_column)) {
    in.warped = GDALWarp("", nullptr, 1, &from, wo, &usage_error);
  } else {
    // Each side with a margin past the seam of the kernel's reach (4 source pixels, times the
    // texel's size in pixels when the level is coarser): the texels by the seam see what
    // gdalwarp's see.
    const double texel = level_cell_size(o.tiling, o.tile_size, z) / in.pixel_size;
    const int pad = 4 + int(std::ceil(4 * std::max(1.0, texel)));
    const int w = GDALGetRasterXSize(from), h = GDALGetRasterYSize(from);
    const int cut = int(std::floor(in.seam_column));
    const std::pair<int, int> sides[2] = {{0, std::min(w, cut + 1 + pad)},
                                          {std::max(0, cut - pad), w}};
    for (const auto& [c0, c1] : sides) {
      in.sides.push_back(source_columns(from, c0, c1, h));
      GDALDatasetH side = in.sides.back();
      in.warped_sides.push_back(side ? GDALWarp("", nullptr, 1, &side, wo, &usage_error) : nullptr);
      if (!in.warped_sides.back()) break;
    }
  }
  GDALWarpAppOptionsFree(wo);
  GDALDatasetH any = in.warped_sides.empty() ? in.warped : in.warped_sides.back();
  if (!any)
    return make_error(ErrorCode::corrupt, in.path.string() + ": cannot warp: " + errors.text());
  in.bands = GDALGetRasterCount(any);
  if (in.bands != int(in.data_bands.size()) + 1 ||
      (!in.warped_sides.empty() && GDALGetRasterCount(in.warped_sides[0]) != in.bands))
    return make_error(ErrorCode::internal, in.path.string() + ": the warped VRT has " +
                                               std::to_string(in.bands) + " bands");
  return {};
}

// A value for a --range argument: 6 significant digits, as it will be printed and reused.
double round6(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return std::strtod(buf, nullptr);
}

// Without a range: when the values of all the inputs together span under 1/16 of 0..255 (a dark or
// flat result, e.g. 12-bit data read as it is), one warning per input naming it and its values (at
// most kMaxWarnings, then how many more). A uniform input in a mosaic whose values vary (an ocean
// or ice tile) is no reason for one.
std::vector<std::string> narrow_values_warnings(
    const std::vector<std::unique_ptr<GdalSource::Input>>& inputs) {
  std::pair<double, double> all{INFINITY, -INFINITY};
  for (const auto& in : inputs) {
    const auto [lo, hi] = observed_union(*in);
    all = {std::min(all.first, lo), std::max(all.second, hi)};
  }
  std::vector<std::string> out;
  if (all.first > all.second || all.second - all.first >= 256.0 / 16) return out;
  std::size_t named = 0;
  for (const auto& in : inputs) {
    const auto [lo, hi] = observed_union(*in);
    if (lo > hi) continue;
    if (++named > GdalSource::kMaxWarnings) continue;
    out.push_back(in->path.string() + ": values " + fmt_value(lo) + " .. " + fmt_value(hi) +
                  " use under 1/16 of 0..255 (the result will look flat or dark): give --range "
                  "MIN,MAX to stretch them, or --range auto");
  }
  if (named > GdalSource::kMaxWarnings)
    out.push_back("... and " + std::to_string(named - GdalSource::kMaxWarnings) +
                  " more inputs whose values use under 1/16 of 0..255");
  return out;
}

// A histogram of band `b` of `ds`: hist.size() buckets from lo to hi (values beyond go to the end
// buckets), from a sample: the band read at most 1024 x 1024 (nearest; GDAL uses an overview when
// there is one), without the texels its mask says are invalid (nodata, alpha or a mask). Done here
// rather than by GDALGetRasterHistogramEx, which stores its result beside the file (.aux.xml).
bool sample_histogram(GDALDatasetH ds, int b, double lo, double hi, std::vector<double>& hist,
                      double& counted) {
  GDALRasterBandH band = GDALGetRasterBand(ds, b);
  const int w = GDALGetRasterXSize(ds), h = GDALGetRasterYSize(ds);
  const int sw = std::min(w, 1024), sh = std::min(h, 1024);
  std::vector<double> values(std::size_t(sw) * std::size_t(sh));
  std::vector<std::uint8_t> valid(values.size());
  if (GDALRasterIO(band, GF_Read, 0, 0, w, h, values.data(), sw, sh, GDT_Float64, 0, 0) !=
          CE_None ||
      GDALRasterIO(GDALGetMaskBand(band), GF_Read, 0, 0, w, h, valid.data(), sw, sh, GDT_Byte, 0,
                   0) != CE_None)
    return false;
  std::fill(hist.begin(), hist.end(), 0.0);
  counted = 0;
  const double scale = double(hist.size()) / (hi - lo);
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (!valid[i] || !std::isfinite(values[i])) continue;
    const double at = std::clamp((values[i] - lo) * scale, 0.0, double(hist.size() - 1));
    hist[std::size_t(at)] += 1;
    counted += 1;
  }
  return true;
}

}  // namespace

Result<std::unique_ptr<GdalSource>> GdalSource::open(
    const std::vector<std::filesystem::path>& inputs, const GdalSourceOptions& options) {
  register_gdal();
  if (options.tiling == Tiling::none)
    return make_error(ErrorCode::invalid_argument, "georeferenced inputs need a tiling scheme");
  if (options.bands.size() != 1 && options.bands.size() != 3 && !options.bands.empty())
    return make_error(ErrorCode::invalid_argument, "--bands takes 1 band (grey) or 3 (RGB), not " +
                                                       std::to_string(options.bands.size()));
  for (const auto& [lo, hi] : options.value_ranges)
    if (!(lo < hi))
      return make_error(ErrorCode::invalid_argument, "--range MIN,MAX needs MIN < MAX");
  std::unique_ptr<GdalSource> s(new GdalSource());
  s->options_ = options;
  s->options_.max_open = std::max<std::size_t>(1, options.max_open);
  const SrsPtr lonlat = lonlat_srs();
  double finest = INFINITY;
  bool first = true;
  for (const auto& path : inputs) {
    auto in = std::make_unique<Input>();
    in->path = path;
    if (Status st = probe_input(*in, options, lonlat); !st) return st.error();
    if (options.on_probe) options.on_probe(s->inputs_.size() + 1, inputs.size());
    // Its pieces (probe_input): two for one crossing the antimeridian, placed side by side.
    const LonLatBounds& b = in->bounds;
    if (in->pieces.empty())
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
  if (options.bounds) s->bounds_ = *options.bounds;
  if (options.value_ranges.empty() && !options.auto_range && !options.ranges)
    s->warnings_ = narrow_values_warnings(s->inputs_);
  for (const auto& in : s->inputs_)
    if (!in->warning.empty() && s->warnings_.size() < kMaxWarnings)
      s->warnings_.push_back(in->warning);
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
  if (options.ranges) {
    s->ranges_ = *options.ranges;
  } else if (options.auto_range) {
    if (Status st = s->choose_auto_ranges(); !st) return st.error();
  } else {
    s->ranges_ = options.value_ranges;
  }
  std::size_t described = 0;
  for (auto& in : s->inputs_) {
    in->texels.clear();
    for (const LonLatBounds& piece : in->pieces)
      in->texels.push_back(footprint_texels(options.tiling, *g, piece));
    // Warped once here, so that an input GDAL cannot warp is refused before the build starts.
    if (Status st = s->acquire(*in); !st) return st.error();
    if (++described > 3) continue;
    if (!s->description_.empty()) s->description_ += ", ";
    s->description_ += in->description;
  }
  if (described > 3) s->description_ += ", ... (" + std::to_string(described) + " inputs)";
  s->description_ += " -> " + std::string(tiling_name(options.tiling)) + " level " +
                     std::to_string(*level) + " (" + resampling_name(options.resampling) + ")";
  return s;
}

// --range auto: per data band, the kAutoRangeLow..kAutoRangeHigh percentiles of all the inputs'
// values together, from a sample of each input (sample_histogram: read at most 1024 x 1024), each
// input weighted by its pixel count. Buckets: one per integer value for integer data (at
// most 65536), else 65536 between the smallest and the largest value seen.
Status GdalSource::choose_auto_ranges() {
  std::size_t nb = 0;
  bool integer = true;
  for (const auto& in : inputs_) {
    nb = std::max(nb, in->data_bands.size());
    integer = integer && in->integer;
  }
  ranges_.assign(nb, {INFINITY, -INFINITY});
  for (const auto& in : inputs_)
    for (std::size_t k = 0; k < in->observed.size(); ++k)
      ranges_[k] = {std::min(ranges_[k].first, in->observed[k].first),
                    std::max(ranges_[k].second, in->observed[k].second)};
  GdalErrors errors;
  for (std::size_t k = 0; k < nb; ++k) {
    auto [gmin, gmax] = ranges_[k];
    if (gmin > gmax)
      return make_error(ErrorCode::invalid_argument,
                        "--range auto: band " + std::to_string(k + 1) + " has no valid value");
    const bool per_value = integer && gmax - gmin < 65536;
    const int buckets = per_value ? int(gmax - gmin) + 1 : 65536;
    const double lo = per_value ? gmin - 0.5 : gmin, hi = per_value ? gmax + 0.5 : gmax;
    std::vector<double> sum(std::size_t(buckets), 0.0);
    std::vector<double> hist(sum.size());
    for (auto& in : inputs_) {
      if (k >= in->data_bands.size()) continue;
      GDALDatasetH ds = GDALOpenEx(in->path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY, nullptr,
                                   nullptr, nullptr);
      if (!ds)
        return make_error(ErrorCode::corrupt,
                          in->path.string() + ": cannot open: " + errors.text());
      double counted = 0;
      const bool ok = sample_histogram(ds, in->data_bands[k], lo, hi, hist, counted);
      GDALClose(ds);
      if (!ok)
        return make_error(ErrorCode::corrupt,
                          in->path.string() + ": cannot read its values: " + errors.text());
      if (counted <= 0) continue;
      const double weight = double(in->pixels) / counted;
      for (std::size_t i = 0; i < hist.size(); ++i) sum[i] += hist[i] * weight;
    }
    double total = 0;
    for (double c : sum) total += c;
    // The value below which `p` percent of all values lie (interpolated within its bucket).
    const auto percentile = [&](double p) {
      const double want = total * p / 100, width = (hi - lo) / buckets;
      double acc = 0;
      for (std::size_t i = 0; i < sum.size(); ++i) {
        if (acc + sum[i] >= want && sum[i] > 0) {
          if (per_value) return gmin + double(i);
          return lo + width * (double(i) + (want - acc) / sum[i]);
        }
        acc += sum[i];
      }
      return gmax;
    };
    double a = round6(percentile(kAutoRangeLow)), b = round6(percentile(kAutoRangeHigh));
    if (!(a < b)) a = round6(gmin), b = round6(gmax);
    if (!(a < b)) b = round6(a + std::max(1.0, std::abs(a) * 1e-3));
    ranges_[k] = {a, b};
  }
  return {};
}

Status GdalSource::acquire(Input& in) {
  in.last_use = ++tick_;
  if (in.warped || !in.warped_sides.empty()) return {};
  if (open_.size() >= options_.max_open) {
    auto lru = std::min_element(open_.begin(), open_.end(), [](const Input* a, const Input* b) {
      return a->last_use < b->last_use;
    });
    (*lru)->close();
    open_.erase(lru);
  }
  const int z = max_level_;
  if (Status st = warp_input(in, options_, width_, height_, z); !st) {
    in.close();
    return st;
  }
  open_.push_back(&in);
  peak_open_ = std::max(peak_open_, open_.size());
  return {};
}

GdalSource::~GdalSource() = default;

std::vector<LonLatBounds> GdalSource::input_bounds() const {
  std::vector<LonLatBounds> out;
  for (const auto& in : inputs_) out.push_back(in->bounds);
  return out;
}

std::vector<GdalSource*> GdalSource::split(unsigned n) {
  n = std::max(1u, std::min<unsigned>(n, unsigned(options_.max_open)));
  for (Input* in : open_) in->close();
  open_.clear();
  options_.max_open = std::max<std::size_t>(1, options_.max_open / n);
  std::vector<GdalSource*> readers{this};
  copies_.clear();
  for (unsigned i = 1; i < n; ++i) {
    std::unique_ptr<GdalSource> c(new GdalSource());
    c->options_ = options_;
    c->width_ = width_;
    c->height_ = height_;
    c->max_level_ = max_level_;
    c->bounds_ = bounds_;
    c->ranges_ = ranges_;
    for (const auto& in : inputs_) {
      auto copy = std::make_unique<Input>();
      copy->path = in->path;
      copy->src_bands = in->src_bands;
      copy->data_bands = in->data_bands;
      copy->alpha_band = in->alpha_band;
      copy->tagged_alpha = in->tagged_alpha;
      copy->integer = in->integer;
      copy->pixels = in->pixels;
      copy->pieces = in->pieces;
      copy->bounds = in->bounds;
      copy->texels = in->texels;
      copy->pixel_size = in->pixel_size;
      copy->seam_column = in->seam_column;
      c->inputs_.push_back(std::move(copy));
    }
    readers.push_back(c.get());
    copies_.push_back(std::move(c));
  }
  return readers;
}

Status GdalSource::read_window(std::uint64_t x0, std::uint64_t x1, std::uint64_t y,
                               std::uint32_t count, std::uint8_t* out) {
  std::memset(out, 0, std::size_t(x1 - x0) * count * 4);
  for (auto& in : inputs_)
    for (std::size_t k = 0; k < in->texels.size(); ++k)
      if (Status st = read_piece(*in, k, x0, x1, y, count, out); !st) return st;
  return {};
}

Status GdalSource::read_piece(Input& in, std::size_t piece, std::uint64_t x0, std::uint64_t x1,
                              std::uint64_t y, std::uint32_t count, std::uint8_t* out) {
  const TexelRect& r = in.texels[piece];
  const std::uint64_t y0 = std::max(y, r.y0), y1 = std::min(y + count, r.y1);
  const std::uint64_t c0 = std::max(x0, r.x0), c1 = std::min(x1, r.x1);
  if (y0 >= y1 || c0 >= c1) return {};
  const std::uint64_t out_w = x1 - x0;
  GdalErrors errors;
  double lo[3] = {0, 0, 0}, scale[3] = {1, 1, 1};
  for (std::size_t k = 0; k < 3 && !ranges_.empty(); ++k) {
    const auto& range = ranges_[std::min(k, ranges_.size() - 1)];
    lo[k] = range.first;
    scale[k] = 255.0 / (range.second - range.first);
  }
  if (Status st = acquire(in); !st) return st;
  const std::uint64_t w = c1 - c0, h = y1 - y0;
  const int nb = in.bands;
  // GDAL's line spacing is an int: a window row of floats must fit in one.
  const std::uint64_t line_bytes = w * std::uint64_t(nb) * 4;
  if (line_bytes > std::uint64_t(std::numeric_limits<int>::max()))
    return make_error(ErrorCode::too_large, in.path.string() + ": a window row of " +
                                                std::to_string(w) + " texels is beyond GDAL's " +
                                                "int line spacing");
  scratch_.resize(std::size_t(w) * h * std::size_t(nb));
  CPLErrorReset();
  const CPLErr err = GDALDatasetRasterIO(in.warped_piece(piece), GF_Read, int(c0), int(y0), int(w),
                                         int(h), scratch_.data(), int(w), int(h), GDT_Float32, nb,
                                         nullptr, nb * 4, int(line_bytes), 4);
  if (err != CE_None || errors.failed())
    return make_error(ErrorCode::corrupt, in.path.string() + ": reading grid rows " +
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
        const int from = nb == 2 ? 0 : k;  // grey: its one band and its range
        const double v = (src[from] - lo[from]) * scale[from];
        c[k] = std::clamp(v, 0.0, 255.0);
      }
      if (a >= 1 || dst[3] == 0) {  // nothing under it shows: no blending (most texels)
        for (int k = 0; k < 3; ++k) dst[k] = std::uint8_t(c[k] + 0.5);
        dst[3] = std::uint8_t(a * 255 + 0.5);
        continue;
      }
      // Over: later inputs win where they are opaque.
      const double da = dst[3] / 255.0, oa = a + da * (1 - a);
      for (int k = 0; k < 3; ++k)
        dst[k] = std::uint8_t(std::lround((c[k] * a + dst[k] * da * (1 - a)) / oa));
      dst[3] = std::uint8_t(std::lround(oa * 255));
    }
  }
  return {};
}

}  // namespace detail

}  // namespace builder
}  // namespace vts
