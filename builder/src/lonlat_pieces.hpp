// An input's extent in degrees as the grid takes it: cut at the antimeridian into boxes that each
// lie within -180..180 (tiling.hpp's LonLatBounds never crosses it), clipped to the scheme's
// extent, and the point where the input's resolution is measured. Pure functions, thread-safe;
// no GDAL here (gdal_source.cpp measures and warps).
#pragma once

#include <vector>

#include "vts/protocol/tiling.hpp"

namespace vts {
inline namespace builder {
namespace detail {

// An extent as PROJ hands it back, in any of the forms a raster crossing 180 degrees takes:
// west > east (OCTTransformBounds' crossing form: 150 .. -150), longitudes beyond 180 (a file in
// EPSG:4326 from 150 to 210, or a 0..360 global grid), or a span of 360 degrees or more. Returns
// the boxes it covers within -180..180 in the order west piece, east piece: one box when it does
// not cross (shifted by a whole turn when it lies beyond 180, e.g. 190..200 -> -170..-160), two
// when it does (150 .. -150 -> [150, 180] and [-180, -150]); a whole turn from -180 is [-180, 180],
// from elsewhere two pieces (0..360 -> [0, 180] and [-180, 0]), more than a turn [-180, 180]. A
// piece thinner than 1e-9 degrees (an edge exactly on 180) is left out. Latitudes are kept as
// given. Empty for a non-finite or empty (south >= north) extent.
std::vector<LonLatBounds> split_at_antimeridian(const LonLatBounds& b);

// The pieces clipped to the scheme's extent (latitude; longitude is within it already), those left
// empty dropped.
std::vector<LonLatBounds> clip_pieces(std::vector<LonLatBounds> pieces, const LonLatBounds& extent);

// The one box that holds every piece, as the metadata records it (west < east always): the
// pieces' own box when there is one, the whole longitude range (-180 .. 180, their latitudes) when
// the input crosses the antimeridian. Zeroes for no piece.
LonLatBounds pieces_hull(const std::vector<LonLatBounds>& pieces);

// Where an input's resolution is measured: the middle of its (clipped) pieces in longitude, taken
// across 180 for two pieces (150..180 and -180..-150 -> 180), and in latitude the equator when
// the pieces span it, else their middle latitude. Pieces must not be empty.
LonLat resolution_point(const std::vector<LonLatBounds>& pieces);

}  // namespace detail
}  // namespace builder
}  // namespace vts
