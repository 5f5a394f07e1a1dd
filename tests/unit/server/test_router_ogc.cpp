// The pure pieces of the OGC entry points (router_ogc.hpp, router_xml.hpp, router_target.cpp):
// the WMTS KVP parameters (names in any case, values percent-decoded), XML escaping, the XML
// writer, and the tile matrix set identifiers.
#include <gtest/gtest.h>

#include <optional>
#include <string>

#include "router_internal.hpp"
#include "router_ogc.hpp"
#include "router_xml.hpp"

namespace {

using namespace vts::router_detail;

std::optional<Target> target(std::string_view t) {
  std::optional<vts::HttpResponse> rejection;
  auto r = parse_target(t, 8192, rejection);
  if (!r && rejection) ADD_FAILURE() << t << ": " << rejection->status << " " << rejection->owned;
  return r;
}

TEST(RouterOgc, WmtsKvpNamesAreCaseInsensitiveAndValuesKeptAsSent) {
  auto t = target(
      "/wmts?SERVICE=WMTS&request=GetTile&Version=1.0.0&LAYER=earth&style=default&"
      "Format=image%2Fpng&TileMatrixSet=WorldCRS84Quad&TILEMATRIX=2&TileRow=1&tilecol=3&x=ignored");
  ASSERT_TRUE(t);
  const Query& q = t->query;
  EXPECT_EQ(q.service, "WMTS");
  EXPECT_EQ(q.request, "GetTile");
  EXPECT_EQ(q.version, "1.0.0");
  EXPECT_EQ(q.layer, "earth");
  EXPECT_EQ(q.style, "default");
  EXPECT_EQ(q.format, "image%2Fpng");  // as sent: decode_query_value() decodes it
  EXPECT_EQ(q.tile_matrix_set, "WorldCRS84Quad");
  EXPECT_EQ(q.tile_matrix, "2");
  EXPECT_EQ(q.tile_row, "1");
  EXPECT_EQ(q.tile_col, "3");
}

TEST(RouterOgc, AWmtsParameterGivenTwiceInAnyCaseIsRefused) {
  std::optional<vts::HttpResponse> rejection;
  EXPECT_FALSE(parse_target("/wmts?LAYER=a&layer=b", 8192, rejection));
  ASSERT_TRUE(rejection);
  EXPECT_EQ(rejection->status, 400);
}

TEST(RouterOgc, QueryValuesArePercentDecodedAndControlsRefused) {
  EXPECT_EQ(decode_query_value("image%2Fpng"), "image/png");
  EXPECT_EQ(decode_query_value("a+b%20c"), "a b c");
  EXPECT_EQ(decode_query_value("%e2%82%ac"), "\xE2\x82\xAC");
  EXPECT_EQ(decode_query_value(""), "");
  EXPECT_FALSE(decode_query_value("%2"));   // cut short
  EXPECT_FALSE(decode_query_value("%zz"));  // not hex
  EXPECT_FALSE(decode_query_value("a%0Ab"));
  EXPECT_FALSE(decode_query_value("%7F"));
}

TEST(RouterOgc, XmlEscapeWritesEntitiesAndReplacesWhatXmlCannotCarry) {
  EXPECT_EQ(xml_escape("a<b>&\"c'"), "a&lt;b&gt;&amp;&quot;c&#39;");
  EXPECT_EQ(xml_escape("tab\tnl\ncr\r"), "tab\tnl\ncr\r");
  EXPECT_EQ(xml_escape(std::string("x\x01y", 3)), "x\xEF\xBF\xBDy");
  EXPECT_EQ(xml_escape("\xC3\xA9t\xC3\xA9"), "\xC3\xA9t\xC3\xA9");  // UTF-8 kept
}

TEST(RouterOgc, XmlWriterNestsIndentsAndEscapes) {
  XmlWriter w;
  w.open("Capabilities", {{"xmlns", "http://www.opengis.net/wmts/1.0"}});
  w.leaf("Title", "a & b");
  w.empty("Link", {{"href", "/x?a=1&b=\"2\""}});
  w.close();
  const std::string doc = w.finish();
  EXPECT_EQ(doc.rfind("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n", 0), 0u) << doc;
  EXPECT_NE(doc.find("<Capabilities xmlns=\"http://www.opengis.net/wmts/1.0\">"), std::string::npos)
      << doc;
  EXPECT_NE(doc.find("  <Title>a &amp; b</Title>"), std::string::npos) << doc;
  EXPECT_NE(doc.find("  <Link href=\"/x?a=1&amp;b=&quot;2&quot;\"/>"), std::string::npos) << doc;
  EXPECT_NE(doc.find("</Capabilities>"), std::string::npos) << doc;
}

TEST(RouterOgc, MatrixSetIdsRoundTripAndOthersAreRefused) {
  using vts::Tiling;
  for (MatrixSetKey k :
       {MatrixSetKey{Tiling::web_mercator_quad, 256}, MatrixSetKey{Tiling::world_crs84_quad, 256},
        MatrixSetKey{Tiling::world_crs84_quad, 512}}) {
    auto back = parse_matrix_set_id(k.id());
    ASSERT_TRUE(back) << k.id();
    EXPECT_EQ(*back, k) << k.id();
  }
  EXPECT_EQ(MatrixSetKey{}.id(), "WebMercatorQuad");
  EXPECT_EQ((MatrixSetKey{Tiling::world_crs84_quad, 512}.id()), "WorldCRS84Quad-512");
  for (const char* bad : {"", "GoogleMapsCompatible-", "WebMercatorQuad-", "WebMercatorQuad-abc",
                          "Mars", "WorldCRS84Quad-256x", "none"}) {
    EXPECT_FALSE(parse_matrix_set_id(bad)) << bad;
  }
}

}  // namespace
