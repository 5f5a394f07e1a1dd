// WMTS 1.0.0 (OGC 07-057r7), docs/PROTOCOL.md §15: the capabilities document (KVP GetCapabilities
// at /wmts, RESTful at /wmts/1.0.0/WMTSCapabilities.xml) and tiles (KVP GetTile at /wmts, RESTful
// at /wmts/1.0.0/{layer}/{style}/{TileMatrixSet}/{TileMatrix}/{TileRow}/{TileCol}.{ext}), whose
// bytes are the web image routes' (router_ogc.cpp offer_tile). Errors are OWS 1.1 exception
// reports.
#include <algorithm>

#include "router_ogc.hpp"
#include "router_xml.hpp"

namespace vts {
inline namespace server {
namespace router_detail {
namespace {

constexpr std::uint32_t kCapabilitiesMaxAge = 60;  // as TileJSON: it names the tilesets served

// An OWS 1.1 ExceptionReport (OGC 06-121r3 §8) with one exception.
HttpResponse ows_exception(int status, std::string_view code, std::string_view locator,
                           const std::string& text) {
  XmlWriter x;
  x.open("ExceptionReport", {{"xmlns", "http://www.opengis.net/ows/1.1"},
                             {"xmlns:xsi", "http://www.w3.org/2001/XMLSchema-instance"},
                             {"xsi:schemaLocation",
                              "http://www.opengis.net/ows/1.1 "
                              "http://schemas.opengis.net/ows/1.1.0/owsExceptionReport.xsd"},
                             {"version", "1.1.0"},
                             {"xml:lang", "en"}});
  std::vector<XmlWriter::Attr> attrs = {{"exceptionCode", code}};
  if (!locator.empty()) attrs.push_back({"locator", locator});
  x.open("Exception", attrs);
  x.leaf("ExceptionText", text);
  x.close();
  x.close();
  HttpResponse r;
  r.status = status;
  r.route = Route::error;
  set_owned(r, x.finish(), "application/xml");
  add(r, "Cache-Control", "no-store");
  return r;
}

HttpResponse missing(std::string_view name) {
  return ows_exception(400, "MissingParameterValue", name,
                       "parameter " + std::string(name) + " is required");
}

HttpResponse invalid(std::string_view name, const std::string& why) {
  return ows_exception(400, "InvalidParameterValue", name, why);
}

void operation(XmlWriter& x, std::string_view name, const std::string& href) {
  x.open("ows:Operation", {{"name", name}});
  x.open("ows:DCP");
  x.open("ows:HTTP");
  x.open("ows:Get", {{"xlink:href", href}});
  x.open("ows:Constraint", {{"name", "GetEncoding"}});
  x.open("ows:AllowedValues");
  x.leaf("ows:Value", "KVP");
  x.close();
  x.close();
  x.close();
  x.close();
  x.close();
  x.close();
}

void layer(XmlWriter& x, const Tileset& t, const std::string& base) {
  const auto offers = ogc_offers(t);
  x.open("Layer");
  x.leaf("ows:Title", t.name);
  if (!t.info.description.empty()) x.leaf("ows:Abstract", t.info.description);
  const LonLatBounds b = offer_bounds(t, offers.front());
  x.open("ows:WGS84BoundingBox");
  x.leaf("ows:LowerCorner", number_text(b.west) + " " + number_text(b.south));
  x.leaf("ows:UpperCorner", number_text(b.east) + " " + number_text(b.north));
  x.close();
  x.leaf("ows:Identifier", t.name);
  x.open("Style", {{"isDefault", "true"}});
  x.leaf("ows:Identifier", "default");
  x.close();
  for (auto f : kOgcFormats) x.leaf("Format", imaging::web_format_content_type(f));
  for (const Offer& o : offers) {
    x.open("TileMatrixSetLink");
    x.leaf("TileMatrixSet", o.set.id());
    x.open("TileMatrixSetLimits");
    for (const TileLimits& l : offer_limits(t, o)) {
      x.open("TileMatrixLimits");
      x.leaf("TileMatrix", std::to_string(l.tms));
      x.leaf("MinTileRow", std::to_string(l.min_row));
      x.leaf("MaxTileRow", std::to_string(l.max_row));
      x.leaf("MinTileCol", std::to_string(l.min_col));
      x.leaf("MaxTileCol", std::to_string(l.max_col));
      x.close();
    }
    x.close();
    x.close();
  }
  for (auto f : kOgcFormats) {
    x.empty("ResourceURL",
            {{"format", imaging::web_format_content_type(f)},
             {"resourceType", "tile"},
             {"template", base + "/wmts/1.0.0/" + url_segment(t.name) +
                              "/{Style}/{TileMatrixSet}/{TileMatrix}/{TileRow}/{TileCol}." +
                              std::string(imaging::web_format_extension(f))}});
  }
  x.close();
}

void matrix_set(XmlWriter& x, MatrixSetKey key, int depth) {
  const bool crs84 = key.tiling == Tiling::world_crs84_quad;
  x.open("TileMatrixSet");
  x.leaf("ows:Identifier", key.id());
  x.leaf("ows:SupportedCRS",
         crs84 ? "urn:ogc:def:crs:OGC:1.3:CRS84" : "urn:ogc:def:crs:EPSG::3857");
  // Web Mercator's well-known scale set (WMTS 1.0.0 Annex E.4) is ours at 256-texel tiles.
  if (!crs84 && key.tile_size == 256) {
    x.leaf("WellKnownScaleSet", "urn:ogc:def:wkss:OGC:1.0:GoogleMapsCompatible");
  }
  const std::string corner =
      crs84 ? "-180 90"
            : number_text(-kWebMercatorHalfSide) + " " + number_text(kWebMercatorHalfSide);
  for (const TileMatrix& m : tile_matrices(key, depth)) {
    x.open("TileMatrix");
    x.leaf("ows:Identifier", std::to_string(m.tms));
    x.leaf("ScaleDenominator", number_text(m.scale_denominator));
    x.leaf("TopLeftCorner", corner);
    x.leaf("TileWidth", std::to_string(key.tile_size));
    x.leaf("TileHeight", std::to_string(key.tile_size));
    x.leaf("MatrixWidth", std::to_string(m.matrix_width));
    x.leaf("MatrixHeight", std::to_string(m.matrix_height));
    x.close();
  }
  x.close();
}

HttpResponse capabilities(const TilesetRegistry& registry, const RouterConfig& config,
                          const std::string& base) {
  const auto offered = ogc_tilesets(registry, config);
  XmlWriter x;
  x.open("Capabilities", {{"xmlns", "http://www.opengis.net/wmts/1.0"},
                          {"xmlns:ows", "http://www.opengis.net/ows/1.1"},
                          {"xmlns:xlink", "http://www.w3.org/1999/xlink"},
                          {"xmlns:xsi", "http://www.w3.org/2001/XMLSchema-instance"},
                          {"xsi:schemaLocation",
                           "http://www.opengis.net/wmts/1.0 "
                           "http://schemas.opengis.net/wmts/1.0/wmtsGetCapabilities_response.xsd"},
                          {"version", "1.0.0"}});
  x.open("ows:ServiceIdentification");
  x.leaf("ows:Title", "vtstream");
  x.leaf("ows:ServiceType", "OGC WMTS");
  x.leaf("ows:ServiceTypeVersion", "1.0.0");
  x.close();
  x.open("ows:OperationsMetadata");
  operation(x, "GetCapabilities", base + "/wmts?");
  operation(x, "GetTile", base + "/wmts?");
  x.close();
  x.open("Contents");
  std::vector<MatrixSetKey> sets;
  for (const auto& t : offered) {
    layer(x, *t, base);
    for (const Offer& o : ogc_offers(*t)) {
      if (std::find(sets.begin(), sets.end(), o.set) == sets.end()) sets.push_back(o.set);
    }
  }
  std::sort(sets.begin(), sets.end(),
            [](const MatrixSetKey& a, const MatrixSetKey& b) { return a.id() < b.id(); });
  for (MatrixSetKey key : sets) matrix_set(x, key, matrix_set_depth(key, offered));
  x.close();
  x.empty("ServiceMetadataURL", {{"xlink:href", base + "/wmts/1.0.0/WMTSCapabilities.xml"}});
  x.close();
  HttpResponse r;
  r.route = Route::tilejson;  // a metadata document, counted with TileJSON
  set_owned(r, x.finish(), "application/xml");
  add(r, "Cache-Control", cache_control(false, kCapabilitiesMaxAge, false));
  return r;
}

// A GetTile request's parameters, decoded; `format` is already a web format.
struct TileRequest {
  std::string layer, style, matrix_set, matrix, row, col;
  imaging::WebFormat format = imaging::WebFormat::png;
};

HttpResponse get_tile(const HttpRequest& request, const TileRequest& q,
                      const TilesetRegistry& registry, const RouterConfig& config) {
  std::string why;
  auto t = ogc_tileset(registry, config, q.layer, why);
  if (!t) return invalid("LAYER", why);
  if (q.style != "default") {
    return invalid("STYLE", "layer " + t->name + " has one style, \"default\"");
  }
  const auto offer = find_offer(*t, q.matrix_set);
  if (!offer) {
    std::string sets;
    for (const Offer& o : ogc_offers(*t)) sets += (sets.empty() ? "" : ", ") + o.set.id();
    return invalid("TILEMATRIXSET", "layer " + t->name + " is offered in " + sets);
  }
  const auto tms = parse_u32(q.matrix);
  if (!tms) return invalid("TILEMATRIX", "TILEMATRIX must be a decimal number");
  const auto row = parse_u32(q.row), col = parse_u32(q.col);
  if (!row) return invalid("TILEROW", "TILEROW must be a decimal number");
  if (!col) return invalid("TILECOL", "TILECOL must be a decimal number");
  // Beyond the layer's levels or its matrix: 404, which GDAL's WMTS driver (and a web map) reads
  // as an empty tile, as it must for a layer shallower than the set other layers share.
  if (*tms < std::uint32_t(offer->min_tms) || *tms > std::uint32_t(offer->max_tms)) {
    return ows_exception(404, "TileOutOfRange", "TILEMATRIX",
                         "layer " + t->name + " has tile matrices " +
                             std::to_string(offer->min_tms) + " to " +
                             std::to_string(offer->max_tms) + " of " + q.matrix_set);
  }
  if (!offer_has_tile(*offer, int(*tms), *row, *col)) {
    const TileMatrix m = tile_matrices(offer->set, int(*tms)).back();
    const bool row_out = *row >= m.matrix_height;
    return ows_exception(404, "TileOutOfRange", row_out ? "TILEROW" : "TILECOL",
                         "tile matrix " + q.matrix + " of " + q.matrix_set + " has " +
                             std::to_string(m.matrix_height) + " rows and " +
                             std::to_string(m.matrix_width) + " columns");
  }
  return offer_tile(request, std::move(t), *offer, int(*tms), *row, *col, q.format, config);
}

// GET /wmts?SERVICE=WMTS&REQUEST=...
HttpResponse kvp(const HttpRequest& request, const Query& query, const TilesetRegistry& registry,
                 const RouterConfig& config, const std::string& base) {
  // Every value decoded once; a malformed one is refused by name.
  struct Param {
    const char* name;
    const std::optional<std::string_view>& raw;
    std::optional<std::string> value;
  };
  Param p[] = {{"SERVICE", query.service, {}},
               {"REQUEST", query.request, {}},
               {"VERSION", query.version, {}},
               {"LAYER", query.layer, {}},
               {"STYLE", query.style, {}},
               {"FORMAT", query.format, {}},
               {"TILEMATRIXSET", query.tile_matrix_set, {}},
               {"TILEMATRIX", query.tile_matrix, {}},
               {"TILEROW", query.tile_row, {}},
               {"TILECOL", query.tile_col, {}}};
  for (Param& each : p) {
    if (!each.raw) continue;
    each.value = decode_query_value(*each.raw);
    if (!each.value) return invalid(each.name, "malformed percent-escape");
  }
  auto& [service, req, version, layer_name, style, format, matrix_set, matrix, row, col] = p;
  if (!service.value) return missing("SERVICE");
  if (*service.value != "WMTS") return invalid("SERVICE", "SERVICE must be WMTS");
  if (!req.value) return missing("REQUEST");
  if (*req.value == "GetCapabilities") return capabilities(registry, config, base);
  if (*req.value != "GetTile") {
    return ows_exception(501, "OperationNotSupported", "REQUEST",
                         "REQUEST " + *req.value +
                             " is not supported; use GetCapabilities or "
                             "GetTile");
  }
  for (Param* each : {&version, &layer_name, &style, &format, &matrix_set, &matrix, &row, &col}) {
    if (!each->value) return missing(each->name);
  }
  if (*version.value != "1.0.0") return invalid("VERSION", "VERSION must be 1.0.0");
  const auto web = format_from_media_type(*format.value);
  if (!web) {
    return invalid("FORMAT", "FORMAT " + *format.value +
                                 " is not offered; use image/png, image/webp or image/jpeg");
  }
  return get_tile(request,
                  {*layer_name.value, *style.value, *matrix_set.value, *matrix.value, *row.value,
                   *col.value, *web},
                  registry, config);
}

// GET /wmts/1.0.0/...: the capabilities document or a tile.
HttpResponse rest(const HttpRequest& request, const std::vector<std::string_view>& s,
                  const TilesetRegistry& registry, const RouterConfig& config,
                  const std::string& base) {
  if (s.size() == 3 && s[2] == "WMTSCapabilities.xml") {
    return capabilities(registry, config, base);
  }
  if (s.size() != 8) {
    return ows_exception(404, "InvalidParameterValue", "",
                         "no such WMTS resource; try /wmts/1.0.0/WMTSCapabilities.xml or "
                         "/wmts/1.0.0/{layer}/{style}/{TileMatrixSet}/{TileMatrix}/{TileRow}/"
                         "{TileCol}.png|.webp|.jpg");
  }
  const std::string_view last = s[7];
  const std::size_t dot = last.find('.');
  const auto web =
      dot == std::string_view::npos ? std::nullopt : format_from_extension(last.substr(dot + 1));
  if (!web) {
    return invalid("FORMAT", "a WMTS tile ends in .png, .webp or .jpg");
  }
  return get_tile(request,
                  {std::string(s[2]), std::string(s[3]), std::string(s[4]), std::string(s[5]),
                   std::string(s[6]), std::string(last.substr(0, dot)), *web},
                  registry, config);
}

}  // namespace

std::optional<HttpResponse> wmts_route(const HttpRequest& request, const Target& target,
                                       const TilesetRegistry& registry, const RouterConfig& config,
                                       const std::string& base) {
  if (target.path == "/wmts") return kvp(request, target.query, registry, config, base);
  if (!target.path.starts_with("/wmts/")) return std::nullopt;
  std::vector<std::string_view> s;
  std::string why;
  if (!split_segments(target.path, s, why)) return error(400, why);
  if (s[1] != "1.0.0") {
    // Not a WMTS resource: the tile paths of a tileset named "wmts", when one is served.
    if (registry.find("wmts")) return std::nullopt;
    return ows_exception(404, "VersionNegotiationFailed", "",
                         "the one WMTS version served is 1.0.0: /wmts/1.0.0/...");
  }
  return rest(request, s, registry, config, base);
}

}  // namespace router_detail
}  // namespace server
}  // namespace vts
