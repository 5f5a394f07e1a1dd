// An input's extent cut at the antimeridian: every form PROJ hands back for a raster crossing 180
// degrees becomes boxes within -180..180, and the one box the metadata records never crosses.
#include "lonlat_pieces.hpp"

#include <gtest/gtest.h>

#include <vector>

namespace vts {
namespace {

using detail::clip_pieces;
using detail::pieces_hull;
using detail::resolution_point;
using detail::split_at_antimeridian;
using Pieces = std::vector<LonLatBounds>;

TEST(LonLatPieces, AnExtentWithinTheWorldIsOnePieceAsItIs) {
  EXPECT_EQ(split_at_antimeridian({-20, -35, 50, 40}), (Pieces{{-20, -35, 50, 40}}));
  EXPECT_EQ(split_at_antimeridian({-180, -90, 180, 90}), (Pieces{{-180, -90, 180, 90}}));
}

TEST(LonLatPieces, WestBeyondEastIsCutIntoItsTwoSides) {
  EXPECT_EQ(split_at_antimeridian({150, -60, -150, 60}),
            (Pieces{{150, -60, 180, 60}, {-180, -60, -150, 60}}));
}

TEST(LonLatPieces, LongitudesPast180AreTheSamePlacesAWholeTurnWest) {
  // A file in EPSG:4326 from 150 to 210 degrees east.
  EXPECT_EQ(split_at_antimeridian({150, -60, 210, 60}),
            (Pieces{{150, -60, 180, 60}, {-180, -60, -150, 60}}));
  EXPECT_EQ(split_at_antimeridian({190, 0, 200, 10}), (Pieces{{-170, 0, -160, 10}}));
  EXPECT_EQ(split_at_antimeridian({-200, 0, -190, 10}), (Pieces{{160, 0, 170, 10}}));
}

TEST(LonLatPieces, AWholeTurnFromElsewhereIsTwoPiecesMeetingAt180) {
  // A 0..360 grid: its columns east of 180 are the world's west.
  EXPECT_EQ(split_at_antimeridian({0, -90, 360, 90}),
            (Pieces{{0, -90, 180, 90}, {-180, -90, 0, 90}}));
  // 0.25 degree pixels centred on whole degrees.
  EXPECT_EQ(split_at_antimeridian({-0.125, -90, 359.875, 90}),
            (Pieces{{-0.125, -90, 180, 90}, {-180, -90, -0.125, 90}}));
  EXPECT_EQ(split_at_antimeridian({180, 0, 540, 1}), (Pieces{{-180, 0, 180, 1}}));
  EXPECT_EQ(split_at_antimeridian({-190, 0, 200, 1}), (Pieces{{-180, 0, 180, 1}}));
}

TEST(LonLatPieces, AnEdgeOn180ByRoundingMakesNoSlivers) {
  EXPECT_EQ(split_at_antimeridian({150, 0, 180.0000000000001, 1}), (Pieces{{150, 0, 180, 1}}));
  EXPECT_EQ(split_at_antimeridian({180, 0, 200, 1}), (Pieces{{-180, 0, -160, 1}}));
}

TEST(LonLatPieces, EmptyOrNonFiniteExtentsHaveNoPiece) {
  EXPECT_TRUE(split_at_antimeridian({0, 10, 20, 10}).empty());
  EXPECT_TRUE(split_at_antimeridian({0, 10, 0, 20}).empty());
  EXPECT_TRUE(split_at_antimeridian({0, 0, INFINITY, 1}).empty());
  EXPECT_TRUE(split_at_antimeridian({NAN, 0, 1, 1}).empty());
}

TEST(LonLatPieces, ClippingToWebMercatorKeepsWhatIsWithin85Degrees) {
  const LonLatBounds wm = scheme_extent(Tiling::web_mercator_quad);
  EXPECT_EQ(clip_pieces({{-180, -90, 180, 90}}, wm),
            (Pieces{{-180, -kWebMercatorMaxLat, 180, kWebMercatorMaxLat}}));
  EXPECT_TRUE(clip_pieces({{0, 86, 10, 90}}, wm).empty());
  EXPECT_EQ(clip_pieces({{150, 80, 180, 89}, {-180, 80, -150, 89}}, wm).size(), 2u);
}

TEST(LonLatPieces, TheHullOfTwoSidesTakesEveryLongitude) {
  EXPECT_EQ(pieces_hull({{-20, -35, 50, 40}}), (LonLatBounds{-20, -35, 50, 40}));
  EXPECT_EQ(pieces_hull({{150, -60, 180, 60}, {-180, -60, -150, 60}}),
            (LonLatBounds{-180, -60, 180, 60}));
  EXPECT_EQ(pieces_hull({}), LonLatBounds{});
}

TEST(LonLatPieces, ResolutionIsMeasuredMidwayAndOnTheEquatorWhenSpanned) {
  const LonLat mid = resolution_point({{10, 40, 30, 60}});
  EXPECT_EQ(mid.lon, 20);
  EXPECT_EQ(mid.lat, 50);
  const LonLat world = resolution_point({{-180, -kWebMercatorMaxLat, 180, kWebMercatorMaxLat}});
  EXPECT_EQ(world.lon, 0);
  EXPECT_EQ(world.lat, 0);
  // Across 180: the middle of 150 .. 230, which is 190 = -170.
  const LonLat across = resolution_point({{150, -60, 180, -10}, {-180, -60, -130, -10}});
  EXPECT_EQ(across.lon, -170);
  EXPECT_EQ(across.lat, -35);
}

}  // namespace
}  // namespace vts
