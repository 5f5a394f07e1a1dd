// Extents cut at the antimeridian (lonlat_pieces.hpp).
#include "lonlat_pieces.hpp"

#include <algorithm>
#include <cmath>

namespace vts {
inline namespace builder {
namespace detail {

namespace {

// Narrower pieces are rounding, not data: an extent ending on 180 computed as 180.0000000001.
constexpr double kMinPieceDegrees = 1e-9;

}  // namespace

std::vector<LonLatBounds> split_at_antimeridian(const LonLatBounds& b) {
  std::vector<LonLatBounds> out;
  if (!std::isfinite(b.west) || !std::isfinite(b.east) || !std::isfinite(b.south) ||
      !std::isfinite(b.north) || !(b.south < b.north))
    return out;
  double west = b.west, east = b.east;
  if (west > east) east += 360;  // PROJ's crossing form: the east edge is past 180
  if (east - west > 360 + kMinPieceDegrees) return {{-180, b.south, 180, b.north}};
  // The west edge into [-180, 180): a box beyond 180 is the same place a whole turn west.
  const double turns = std::floor((west + 180) / 360);
  west -= 360 * turns, east -= 360 * turns;
  // A whole turn from -180 is the world; from elsewhere (a 0..360 grid) it is two pieces, one
  // each side of 180, as the raster's own columns are.
  if (east - west >= 360 - kMinPieceDegrees) east = west + 360;
  if (west - -180 < kMinPieceDegrees && east - west >= 360 - kMinPieceDegrees)
    return {{-180, b.south, 180, b.north}};
  if (east - west < kMinPieceDegrees) return out;
  if (east <= 180 + kMinPieceDegrees) return {{west, b.south, std::min(east, 180.0), b.north}};
  if (180 - west >= kMinPieceDegrees) out.push_back({west, b.south, 180, b.north});
  out.push_back({-180, b.south, east - 360, b.north});
  return out;
}

std::vector<LonLatBounds> clip_pieces(std::vector<LonLatBounds> pieces,
                                      const LonLatBounds& extent) {
  std::vector<LonLatBounds> out;
  for (LonLatBounds p : pieces) {
    p = {std::max(p.west, extent.west), std::max(p.south, extent.south),
         std::min(p.east, extent.east), std::min(p.north, extent.north)};
    if (p.west < p.east && p.south < p.north) out.push_back(p);
  }
  return out;
}

LonLatBounds pieces_hull(const std::vector<LonLatBounds>& pieces) {
  if (pieces.empty()) return {};
  LonLatBounds h = pieces.front();
  for (const LonLatBounds& p : pieces)
    h = {std::min(h.west, p.west), std::min(h.south, p.south), std::max(h.east, p.east),
         std::max(h.north, p.north)};
  // Two pieces are the two sides of 180: what lies between them is not the input's, but a box
  // that never crosses can only hold both by taking every longitude.
  if (pieces.size() > 1) h.west = -180, h.east = 180;
  return h;
}

LonLat resolution_point(const std::vector<LonLatBounds>& pieces) {
  const LonLatBounds h = pieces_hull(pieces);
  double lon = (h.west + h.east) / 2;
  if (pieces.size() > 1) {  // the middle of west .. east + 360, back within -180..180
    lon = (pieces.front().west + pieces.back().east + 360) / 2;
    if (lon > 180) lon -= 360;
  }
  const double lat = h.south <= 0 && h.north >= 0 ? 0.0 : (h.south + h.north) / 2;
  return {lon, lat};
}

}  // namespace detail
}  // namespace builder
}  // namespace vts
