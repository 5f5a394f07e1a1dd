// OGC API - Tiles 1.0 (OGC 20-057) over the georeferenced tilesets, docs/PROTOCOL.md §15: the
// landing page /ogcapi, conformance, collections (one a tileset), their map tilesets (one a tile
// matrix set they are offered in), the tile matrix sets (OGC 17-083r4 JSON) and tiles, whose
// bytes are the web image routes' (router_ogc.cpp offer_tile).
#include <algorithm>
#include <nlohmann/json.hpp>

#include "router_ogc.hpp"

namespace vts {
inline namespace server {
namespace router_detail {
namespace {

using nlohmann::ordered_json;

constexpr const char* kJson = "application/json";
constexpr std::uint32_t kMetadataMaxAge = 60;  // as TileJSON: it names the tilesets served
constexpr const char* kRel = "http://www.opengis.net/def/rel/ogc/1.0/";
constexpr const char* kCrs84Uri = "http://www.opengis.net/def/crs/OGC/1.3/CRS84";

std::string rel(std::string_view name) {
  return kRel + std::string(name);
}

ordered_json link(std::string rel_name, std::string href, std::string type = kJson,
                  std::string title = {}) {
  ordered_json l = {{"rel", std::move(rel_name)}, {"type", std::move(type)}};
  if (!title.empty()) l["title"] = std::move(title);
  l["href"] = std::move(href);
  return l;
}

HttpResponse json_document(const ordered_json& j) {
  HttpResponse r;
  r.route = Route::tilejson;  // a metadata document, counted with TileJSON
  set_owned(r, j.dump(2) + "\n", kJson);
  add(r, "Cache-Control", cache_control(false, kMetadataMaxAge, false));
  return r;
}

HttpResponse not_found(std::string why) {
  HttpResponse r = error(404, std::move(why));
  r.route = Route::tilejson;
  return r;
}

HttpResponse landing(const std::string& root) {
  return json_document(
      {{"title", "vtstream"},
       {"description", "Georeferenced tilesets of this vts serve as OGC API - Tiles"},
       {"links",
        {link("self", root), link("conformance", root + "/conformance"),
         link(rel("conformance"), root + "/conformance"), link("data", root + "/collections"),
         link(rel("data"), root + "/collections"),
         link(rel("tiling-schemes"), root + "/tileMatrixSets")}}});
}

HttpResponse conformance() {
  const std::string common = "http://www.opengis.net/spec/ogcapi-common-1/1.0/conf/";
  const std::string tiles = "http://www.opengis.net/spec/ogcapi-tiles-1/1.0/conf/";
  ordered_json list = {common + "core",
                       common + "landing-page",
                       common + "json",
                       "http://www.opengis.net/spec/ogcapi-common-2/1.0/conf/collections",
                       tiles + "core",
                       tiles + "tileset",
                       tiles + "tilesets-list",
                       tiles + "geodata-tilesets",
                       tiles + "png",
                       tiles + "jpeg",
                       "http://www.opengis.net/spec/tms/2.0/conf/tilematrixset",
                       "http://www.opengis.net/spec/tms/2.0/conf/json-tilematrixset"};
  return json_document({{"conformsTo", std::move(list)}});
}

std::string collection_url(const std::string& root, const Tileset& t) {
  return root + "/collections/" + url_segment(t.name);
}

ordered_json collection(const std::string& root, const Tileset& t) {
  const LonLatBounds& b = t.info.georeference->bounds;
  ordered_json c = {{"id", t.name}, {"title", t.name}};
  if (!t.info.description.empty()) c["description"] = t.info.description;
  c["extent"] = {{"spatial", {{"bbox", {{b.west, b.south, b.east, b.north}}}, {"crs", kCrs84Uri}}}};
  c["dataType"] = "map";
  const std::string self = collection_url(root, t);
  c["links"] = {link("self", self),
                link(rel("tilesets-map"), self + "/map/tiles", kJson, "map tilesets")};
  return c;
}

std::string tileset_url(const std::string& root, const Tileset& t, const Offer& o) {
  return collection_url(root, t) + "/map/tiles/" + o.set.id();
}

// What a tileset in the list and the tileset's own metadata share.
ordered_json tileset_summary(const std::string& root, const Tileset& t, const Offer& o) {
  ordered_json j = {{"title", t.name + " on " + o.set.id()},
                    {"dataType", "map"},
                    {"crs", std::string(tiling_crs_uri(o.set.tiling))}};
  if (o.set.tile_size == 256) {
    j["tileMatrixSetURI"] = "http://www.opengis.net/def/tilematrixset/OGC/1.0/" + o.set.id();
  }
  j["links"] = {link("self", tileset_url(root, t, o)),
                link(rel("tiling-scheme"), root + "/tileMatrixSets/" + o.set.id())};
  return j;
}

ordered_json tileset(const std::string& root, const Tileset& t, const Offer& o) {
  ordered_json j = tileset_summary(root, t, o);
  ordered_json limits = ordered_json::array();
  for (const TileLimits& l : offer_limits(t, o)) {
    limits.push_back({{"tileMatrix", std::to_string(l.tms)},
                      {"minTileRow", l.min_row},
                      {"maxTileRow", l.max_row},
                      {"minTileCol", l.min_col},
                      {"maxTileCol", l.max_col}});
  }
  j["tileMatrixSetLimits"] = std::move(limits);
  for (auto f : kOgcFormats) {
    ordered_json l = link("item",
                          tileset_url(root, t, o) + "/{tileMatrix}/{tileRow}/{tileCol}." +
                              std::string(imaging::web_format_extension(f)),
                          std::string(imaging::web_format_content_type(f)));
    l["templated"] = true;
    j["links"].push_back(std::move(l));
  }
  return j;
}

// The OGC 17-083r4 (TMS 2.0) JSON of a set. GDAL up to 3.6 reads the 2019 draft's member names
// instead (identifier, supportedCRS, topLeftCorner, and it recognises a definition by
// "identifier" with "boundingBox"): the definition carries those too, with the same values.
ordered_json matrix_set_json(MatrixSetKey key, int depth) {
  const bool crs84 = key.tiling == Tiling::world_crs84_quad;
  const double h = kWebMercatorHalfSide;
  const ordered_json origin =
      crs84 ? ordered_json::array({-180.0, 90.0}) : ordered_json::array({-h, h});
  const std::string crs(tiling_crs_uri(key.tiling));
  ordered_json j = {
      {"id", key.id()},
      {"identifier", key.id()},
      {"title", crs84 ? "CRS84 for the World" : "Google Maps Compatible for the World"}};
  if (key.tile_size == 256) {
    j["uri"] = "http://www.opengis.net/def/tilematrixset/OGC/1.0/" + key.id();
  }
  j["crs"] = crs;
  j["supportedCRS"] = crs;
  j["orderedAxes"] = crs84 ? ordered_json::array({"Lon", "Lat"}) : ordered_json::array({"X", "Y"});
  const ordered_json lower =
      crs84 ? ordered_json::array({-180.0, -90.0}) : ordered_json::array({-h, -h});
  const ordered_json upper =
      crs84 ? ordered_json::array({180.0, 90.0}) : ordered_json::array({h, h});
  j["boundingBox"] = {{"crs", crs},
                      {"lowerLeft", lower},
                      {"upperRight", upper},
                      {"lowerCorner", lower},
                      {"upperCorner", upper}};
  if (!crs84 && key.tile_size == 256) {
    j["wellKnownScaleSet"] = "http://www.opengis.net/def/wkss/OGC/1.0/GoogleMapsCompatible";
  }
  ordered_json matrices = ordered_json::array();
  for (const TileMatrix& m : tile_matrices(key, depth)) {
    matrices.push_back({{"id", std::to_string(m.tms)},
                        {"identifier", std::to_string(m.tms)},
                        {"scaleDenominator", m.scale_denominator},
                        {"cellSize", m.cell_size},
                        {"cornerOfOrigin", "topLeft"},
                        {"pointOfOrigin", origin},
                        {"topLeftCorner", origin},
                        {"tileWidth", key.tile_size},
                        {"tileHeight", key.tile_size},
                        {"matrixWidth", m.matrix_width},
                        {"matrixHeight", m.matrix_height}});
  }
  j["tileMatrices"] = std::move(matrices);
  return j;
}

// The matrix sets any offered tileset is offered in, sorted by id.
std::vector<MatrixSetKey> offered_sets(const std::vector<std::shared_ptr<const Tileset>>& offered) {
  std::vector<MatrixSetKey> sets;
  for (const auto& t : offered) {
    for (const Offer& o : ogc_offers(*t)) {
      if (std::find(sets.begin(), sets.end(), o.set) == sets.end()) sets.push_back(o.set);
    }
  }
  std::sort(sets.begin(), sets.end(),
            [](const MatrixSetKey& a, const MatrixSetKey& b) { return a.id() < b.id(); });
  return sets;
}

HttpResponse matrix_sets(const std::vector<std::string_view>& s, const TilesetRegistry& registry,
                         const RouterConfig& config, const std::string& root) {
  const auto offered = ogc_tilesets(registry, config);
  if (s.size() == 2) {
    ordered_json list = ordered_json::array();
    for (MatrixSetKey key : offered_sets(offered)) {
      ordered_json e = {{"id", key.id()}};
      if (key.tile_size == 256)
        e["uri"] = "http://www.opengis.net/def/tilematrixset/OGC/1.0/" + key.id();
      e["links"] = {link(rel("tiling-scheme"), root + "/tileMatrixSets/" + key.id())};
      list.push_back(std::move(e));
    }
    return json_document(
        {{"links", {link("self", root + "/tileMatrixSets")}}, {"tileMatrixSets", std::move(list)}});
  }
  const auto key = s.size() == 3 ? parse_matrix_set_id(s[2]) : std::nullopt;
  if (!key) {
    return not_found(
        "no such tile matrix set; the sets are WebMercatorQuad, WorldCRS84Quad and "
        "<set>-<T> for T x T tiles other than 256 (/ogcapi/tileMatrixSets lists them)");
  }
  return json_document(matrix_set_json(*key, matrix_set_depth(*key, offered)));
}

// /ogcapi/collections/{ts}/map/tiles/{set}/{tileMatrix}/{tileRow}/{tileCol}.{ext}
HttpResponse tile(const HttpRequest& request, std::shared_ptr<const Tileset> t, const Offer& o,
                  const std::vector<std::string_view>& s, const RouterConfig& config) {
  const std::string_view last = s[8];
  const std::size_t dot = last.find('.');
  const auto format =
      dot == std::string_view::npos ? std::nullopt : format_from_extension(last.substr(dot + 1));
  if (!format) return error(400, "a tile ends in .png, .webp or .jpg");
  const auto tms = parse_u32(s[6]), row = parse_u32(s[7]), col = parse_u32(last.substr(0, dot));
  if (!tms || !row || !col) {
    return error(400,
                 "tile address must be .../{tileMatrix}/{tileRow}/{tileCol}.{ext} with "
                 "decimal numbers (no signs or leading zeros)");
  }
  if (*tms > 64 || !offer_has_tile(o, int(*tms), *row, *col)) {
    return tile_error(404, "tile " + std::string(s[6]) + "/" + std::string(s[7]) + "/" +
                               std::string(last.substr(0, dot)) + " is outside the tile matrices " +
                               std::to_string(o.min_tms) + " to " + std::to_string(o.max_tms) +
                               " of " + t->name + " on " + o.set.id());
  }
  return offer_tile(request, std::move(t), o, int(*tms), *row, *col, *format, config);
}

// /ogcapi/collections[/{ts}[/map/tiles[/{set}[/{tileMatrix}/{tileRow}/{tileCol}.{ext}]]]]
HttpResponse collections(const HttpRequest& request, const std::vector<std::string_view>& s,
                         const TilesetRegistry& registry, const RouterConfig& config,
                         const std::string& root) {
  if (s.size() == 2) {
    ordered_json list = ordered_json::array();
    for (const auto& t : ogc_tilesets(registry, config)) list.push_back(collection(root, *t));
    return json_document(
        {{"links", {link("self", root + "/collections")}}, {"collections", std::move(list)}});
  }
  std::string why;
  auto t = ogc_tileset(registry, config, s[2], why);
  if (!t) return not_found(why);
  if (s.size() == 3) return json_document(collection(root, *t));
  if (s.size() < 5 || s[3] != "map" || s[4] != "tiles" || s.size() == 7 || s.size() == 8 ||
      s.size() > 9) {
    return not_found(
        "no such resource; a collection has /map/tiles, /map/tiles/{set} and "
        "/map/tiles/{set}/{tileMatrix}/{tileRow}/{tileCol}.png|.webp|.jpg");
  }
  if (s.size() == 5) {
    ordered_json list = ordered_json::array();
    for (const Offer& o : ogc_offers(*t)) list.push_back(tileset_summary(root, *t, o));
    return json_document({{"links", {link("self", collection_url(root, *t) + "/map/tiles")}},
                          {"tilesets", std::move(list)}});
  }
  const auto offer = find_offer(*t, s[5]);
  if (!offer) {
    return not_found("tileset \"" + t->name + "\" is not offered in tile matrix set \"" +
                     std::string(s[5]) + "\" (" + collection_url(root, *t) +
                     "/map/tiles lists "
                     "its sets)");
  }
  if (s.size() == 6) return json_document(tileset(root, *t, *offer));
  return tile(request, std::move(t), *offer, s, config);
}

}  // namespace

std::optional<HttpResponse> ogcapi_route(const HttpRequest& request, const Target& target,
                                         const TilesetRegistry& registry,
                                         const RouterConfig& config, const std::string& base) {
  const std::string root = base + "/ogcapi";
  if (target.path == "/ogcapi" || target.path == "/ogcapi/") return landing(root);
  if (!target.path.starts_with("/ogcapi/")) return std::nullopt;
  std::vector<std::string_view> s;
  std::string why;
  if (!split_segments(target.path, s, why)) return error(400, why);
  if (s[1] == "conformance" && s.size() == 2) return conformance();
  if (s[1] == "collections") return collections(request, s, registry, config, root);
  if (s[1] == "tileMatrixSets") return matrix_sets(s, registry, config, root);
  // Not an OGC API resource: the tile paths of a tileset named "ogcapi", when one is served.
  if (registry.find("ogcapi")) return std::nullopt;
  return not_found(
      "no such resource; try /ogcapi, /ogcapi/conformance, /ogcapi/collections or "
      "/ogcapi/tileMatrixSets");
}

}  // namespace router_detail
}  // namespace server
}  // namespace vts
