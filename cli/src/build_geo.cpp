// vts build's georeference options.
#include "build_geo.hpp"

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
  c->add_option("--max-level", a.max_level,
                "Georeferenced inputs: our finest level (default: the first level whose texel is "
                "no larger than the finest input pixel)")
      ->check(CLI::Range(0, int(Geometry::kMaxZoom)));
  c->add_option("--range", a.range,
                "Georeferenced inputs: MIN,MAX mapped linearly to 0..255 (clamped); needed for "
                "data that is not 8-bit");
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
  if (a.max_level >= 0) o.max_level = a.max_level;
  std::vector<double> v;
  if (!a.range.empty()) {
    if (!parse_numbers(a.range, 2, v) || !(v[0] < v[1]))
      return make_error(ErrorCode::invalid_argument,
                        "--range '" + a.range + "' is not of the form MIN,MAX with MIN < MAX");
    o.value_range = std::pair{v[0], v[1]};
  }
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
