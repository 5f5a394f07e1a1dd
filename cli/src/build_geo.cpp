// vts build's georeference options.
#include "build_geo.hpp"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <vector>

namespace vts::cli {

namespace {

// `n` comma-separated numbers, or nothing.
bool parse_numbers(const std::string& text, std::size_t n, std::vector<double>& out) {
  out.clear();
  std::size_t at = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t end = i + 1 < n ? text.find(',', at) : text.size();
    if (end == std::string::npos) return false;
    const std::string part = text.substr(at, end - at);
    char* stop = nullptr;
    const double v = std::strtod(part.c_str(), &stop);
    if (part.empty() || *stop != '\0') return false;
    out.push_back(v);
    at = end + 1;
  }
  return true;
}

// --bands B or R,G,B: 1-based band numbers.
Status apply_bands(const std::string& text, BuildOptions& o) {
  if (text.empty()) return {};
  std::vector<double> v;
  const std::size_t n = std::size_t(std::count(text.begin(), text.end(), ',')) + 1;
  if ((n != 1 && n != 3) || !parse_numbers(text, n, v) ||
      std::any_of(v.begin(), v.end(), [](double b) { return b < 1 || b > 65535 || b != int(b); }))
    return make_error(ErrorCode::invalid_argument,
                      "--bands '" + text + "' is not B (grey) or R,G,B: band numbers from 1");
  for (double b : v) o.bands.push_back(int(b));
  return {};
}

// --range MIN,MAX, MIN1,MAX1,MIN2,MAX2,MIN3,MAX3 or auto.
Status apply_range(const std::string& text, BuildOptions& o) {
  if (text.empty()) return {};
  if (text == "auto") {
    o.auto_range = true;
    return {};
  }
  std::vector<double> v;
  const std::size_t n = std::size_t(std::count(text.begin(), text.end(), ',')) + 1;
  bool ok = (n == 2 || n == 6) && parse_numbers(text, n, v);
  for (std::size_t i = 0; ok && i < v.size(); i += 2) ok = v[i] < v[i + 1];
  if (!ok)
    return make_error(
        ErrorCode::invalid_argument,
        "--range '" + text + "' is not MIN,MAX, MIN,MAX for each of 3 bands (MIN < MAX), or auto");
  if (n == 2)
    o.value_range = std::pair{v[0], v[1]};
  else
    for (std::size_t i = 0; i < n; i += 2) o.band_ranges.emplace_back(v[i], v[i + 1]);
  return {};
}

}  // namespace

void add_geo_options(CLI::App* c, GeoArgs& a) {
  c->add_option("--tiling", a.tiling,
                "Georeference on an OGC tile matrix set: WorldCRS84Quad or WebMercatorQuad. "
                "Georeferenced inputs (GDAL: a CRS and a geotransform) default to WorldCRS84Quad; "
                "--synthetic builds the scheme's grid");
  c->add_option("--bbox", a.bbox,
                "With --tiling: the data footprint W,S,E,N in degrees; only its tiles are built "
                "(default for georeferenced inputs: the union of their extents)");
  c->add_option("--resampling", a.resampling,
                "Georeferenced inputs: how they are warped onto the grid (gdalwarp -r)")
      ->check(CLI::IsMember({"near", "bilinear", "cubic", "lanczos"}))
      ->capture_default_str();
  c->add_option("--warp-error", a.warp_error,
                "Georeferenced inputs: the warp's transformer error in source pixels (gdalwarp "
                "-et; 0 = exact at every texel, ~3x the warp's time)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  c->add_option("--max-level", a.max_level,
                "Georeferenced inputs: our finest level (default: the first level whose texel is "
                "no larger than the finest input pixel)")
      ->check(CLI::Range(0, int(Geometry::kMaxZoom)));
  c->add_option("--bands", a.bands,
                "Georeferenced inputs: the bands B (grey) or R,G,B (1-based) of every input, e.g. "
                "4,3,2 for a multispectral file (an alpha band, nodata or mask still applies)");
  c->add_option("--range", a.range,
                "Georeferenced inputs: MIN,MAX mapped linearly to 0..255 (clamped) for every band, "
                "or MIN,MAX per band (R,G,B); or 'auto': per band, the 2%..98% percentiles of all "
                "inputs' values together (sampled: approximate), printed for reuse. Without it, "
                "values beyond 0..255 are refused");
}

std::string range_argument(const std::vector<std::pair<double, double>>& ranges) {
  std::string s;
  char buf[32];
  for (const auto& [lo, hi] : ranges) {
    std::snprintf(buf, sizeof buf, "%s%.6g,%.6g", s.empty() ? "" : ",", lo, hi);
    s += buf;
  }
  return s;
}

Status apply_geo_options(const GeoArgs& a, BuildOptions& o) {
  if (!a.tiling.empty()) {
    auto t = parse_tiling(a.tiling);
    if (!t) return make_error(ErrorCode::invalid_argument, "--tiling: " + t.error().message);
    o.tiling = *t;
  }
  auto r = parse_resampling(a.resampling);
  if (!r) return make_error(ErrorCode::invalid_argument, "--resampling: " + r.error().message);
  o.resampling = *r;
  o.warp_error = a.warp_error;
  if (a.max_level >= 0) o.max_level = a.max_level;
  std::vector<double> v;
  if (Status s = apply_bands(a.bands, o); !s) return s;
  if (Status s = apply_range(a.range, o); !s) return s;
  if (a.bbox.empty()) return {};
  if (o.tiling == Tiling::none)
    return make_error(ErrorCode::invalid_argument, "--bbox needs --tiling");
  if (!parse_numbers(a.bbox, 4, v))
    return make_error(ErrorCode::invalid_argument,
                      "--bbox '" + a.bbox + "' is not of the form W,S,E,N (degrees)");
  o.bounds = LonLatBounds{v[0], v[1], v[2], v[3]};
  return {};
}

}  // namespace vts::cli
