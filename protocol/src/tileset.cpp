// TilesetInfo <-> PMTiles JSON metadata. The metadata object carries the generic keys other
// PMTiles tools read ("name", "description", "type", "format", "version") and our own object under
// "vtstream". Every key of "vtstream" is written and required; unknown keys are ignored so that
// later minor additions stay readable by this version (a breaking change bumps format_version).
#include <nlohmann/json.hpp>

#include <cmath>
#include <exception>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "vts/protocol/tileset.hpp"

#include "vts/protocol/json_input.hpp"

namespace vts {
inline namespace protocol {
namespace {

using nlohmann::json;
using nlohmann::ordered_json;

constexpr const char* kChecksumName = "xxh3-64";
constexpr const char* kPayloadName = "zstd-skippable-header-v1";

const char* pixel_format_name(CodecId codec) {
  return codec == CodecId::bc1 ? "bc1" : "rgba8";
}

Error bad_key(const std::string& key, const std::string& what) {
  return make_error(ErrorCode::corrupt, "tileset metadata: \"" + key + "\" " + what);
}

// Typed accessors: each names the key in its error so a broken archive says what is wrong.
Result<const json*> member(const json& obj, const std::string& path, const char* key) {
  auto it = obj.find(key);
  if (it == obj.end()) return bad_key(path + key, "is missing");
  return &*it;
}

Result<std::uint64_t> get_uint(const json& obj, const std::string& path, const char* key,
                               std::uint64_t max = std::numeric_limits<std::uint64_t>::max()) {
  auto v = member(obj, path, key);
  if (!v) return std::move(v).error();
  const json& j = **v;
  if (!j.is_number_integer()) return bad_key(path + key, "must be an integer");
  if (j.is_number_unsigned()) {
    const auto u = j.get<std::uint64_t>();
    if (u > max) return bad_key(path + key, "is out of range (" + std::to_string(u) + ")");
    return u;
  }
  const auto s = j.get<std::int64_t>();
  if (s < 0) return bad_key(path + key, "must not be negative (" + std::to_string(s) + ")");
  if (std::uint64_t(s) > max)
    return bad_key(path + key, "is out of range (" + std::to_string(s) + ")");
  return std::uint64_t(s);
}

Result<std::string> get_string(const json& obj, const std::string& path, const char* key) {
  auto v = member(obj, path, key);
  if (!v) return std::move(v).error();
  if (!(*v)->is_string()) return bad_key(path + key, "must be a string");
  return (*v)->get<std::string>();
}

Result<bool> get_bool(const json& obj, const std::string& path, const char* key) {
  auto v = member(obj, path, key);
  if (!v) return std::move(v).error();
  if (!(*v)->is_boolean()) return bad_key(path + key, "must be true or false");
  return (*v)->get<bool>();
}

// Optional generic string key: absent -> empty; present but not a string -> error.
Result<std::string> get_optional_string(const json& obj, const char* key) {
  auto it = obj.find(key);
  if (it == obj.end() || it->is_null()) return std::string();
  if (!it->is_string()) return bad_key(key, "must be a string");
  return it->get<std::string>();
}

std::string num(double v) {
  std::ostringstream o;
  o.precision(17);
  o << v;
  return o.str();
}

std::string bounds_text(const LonLatBounds& b) {
  return num(b.west) + "," + num(b.south) + "," + num(b.east) + "," + num(b.north);
}

// An array of `n` numbers, or an error naming the key.
Result<std::vector<double>> get_numbers(const json& obj, const std::string& path, const char* key,
                                        std::size_t n, const char* what) {
  auto v = member(obj, path, key);
  if (!v) return std::move(v).error();
  const json& j = **v;
  if (!j.is_array() || j.size() != n) return bad_key(path + key, std::string("must be ") + what);
  std::vector<double> out;
  for (const json& e : j) {
    if (!e.is_number()) return bad_key(path + key, std::string("must be ") + what);
    out.push_back(e.get<double>());
  }
  return out;
}

// The optional "georeference" object of "vtstream": absent (older archives, plain images) ->
// nullopt.
Result<std::optional<Georeference>> parse_georeference(const json& v, const Geometry& g) {
  auto it = v.find("georeference");
  if (it == v.end() || it->is_null()) return std::optional<Georeference>();
  if (!it->is_object()) return bad_key("vtstream.georeference", "must be an object");
  const json& o = *it;
  const std::string p = "vtstream.georeference.";
  Georeference geo;
  auto tiling_text = get_string(o, p, "tiling");
  if (!tiling_text) return std::move(tiling_text).error();
  auto tiling = parse_tiling(*tiling_text);
  if (!tiling || *tiling == Tiling::none)
    return bad_key(p + "tiling",
                   "is \"" + *tiling_text + "\" (known: WorldCRS84Quad, WebMercatorQuad)");
  geo.tiling = *tiling;
  auto crs = get_string(o, p, "crs");
  if (!crs) return std::move(crs).error();
  if (*crs != geo.crs())
    return bad_key(p + "crs", "is \"" + *crs + "\" but " + std::string(tiling_name(geo.tiling)) +
                                  " is in " + geo.crs());
  auto b = get_numbers(o, p, "bounds", 4, "[west, south, east, north] in degrees");
  if (!b) return std::move(b).error();
  geo.bounds = {(*b)[0], (*b)[1], (*b)[2], (*b)[3]};
  auto c = get_numbers(o, p, "center", 3, "[lon, lat, level]");
  if (!c) return std::move(c).error();
  const double level = (*c)[2];
  if (!(level >= 0 && level <= 255 && level == std::floor(level)))
    return bad_key(p + "center", "level must be an integer 0..255");
  geo.center = {(*c)[0], (*c)[1], static_cast<int>(level)};
  if (Status s = check_georeference(geo, g); !s)
    return make_error(ErrorCode::corrupt, "tileset metadata: " + s.error().message);
  return std::optional<Georeference>(geo);
}

Result<TilesetInfo> parse(const json& root) {
  if (!root.is_object())
    return make_error(ErrorCode::corrupt, "tileset metadata is not a JSON object");
  auto vit = root.find("vtstream");
  if (vit == root.end())
    return make_error(ErrorCode::unsupported,
                      "not a vtstream archive (metadata has no \"vtstream\" object)");
  const json& v = *vit;
  if (!v.is_object()) return bad_key("vtstream", "must be an object");
  const std::string p = "vtstream.";

  TilesetInfo info;
  auto version = get_uint(v, p, "format_version", std::numeric_limits<int>::max());
  if (!version) return std::move(version).error();
  if (*version < 1) return bad_key(p + "format_version", "must be >= 1");
  if (*version > std::uint64_t(TilesetInfo::kFormatVersion))
    return make_error(ErrorCode::unsupported, "tileset format_version " + std::to_string(*version) +
                                                  " is newer than this build reads (" +
                                                  std::to_string(TilesetInfo::kFormatVersion) +
                                                  ")");
  info.format_version = static_cast<int>(*version);

  auto width = get_uint(v, p, "width");
  if (!width) return std::move(width).error();
  auto height = get_uint(v, p, "height");
  if (!height) return std::move(height).error();
  auto tile_size = get_uint(v, p, "tile_size", std::numeric_limits<std::uint32_t>::max());
  if (!tile_size) return std::move(tile_size).error();
  auto border = get_uint(v, p, "border", std::numeric_limits<std::uint32_t>::max());
  if (!border) return std::move(border).error();
  auto geometry = Geometry::create(*width, *height, static_cast<std::uint32_t>(*tile_size),
                                   static_cast<std::uint32_t>(*border));
  if (!geometry) {
    // Geometry::create() reports invalid arguments; coming from a file they are corrupt metadata.
    Error e = std::move(geometry).error();
    if (e.code == ErrorCode::invalid_argument) e.code = ErrorCode::corrupt;
    e.message = "tileset metadata geometry: " + e.message;
    return e;
  }
  info.geometry = *geometry;

  // Derived values are stored for readers that do not implement the geometry; they must agree.
  auto max_zoom = get_uint(v, p, "max_zoom", 255);
  if (!max_zoom) return std::move(max_zoom).error();
  if (*max_zoom != std::uint64_t(info.geometry.max_zoom()))
    return bad_key(p + "max_zoom", "is " + std::to_string(*max_zoom) + " but the geometry gives " +
                                       std::to_string(info.geometry.max_zoom()));
  auto stored = get_uint(v, p, "stored_size");
  if (!stored) return std::move(stored).error();
  if (*stored != info.geometry.stored_size())
    return bad_key(p + "stored_size", "is " + std::to_string(*stored) +
                                          " but tile_size + 2 * border is " +
                                          std::to_string(info.geometry.stored_size()));

  auto codec_text = get_string(v, p, "codec");
  if (!codec_text) return std::move(codec_text).error();
  auto codec = parse_codec_name(*codec_text);
  if (!codec) return make_error(ErrorCode::unsupported, "tileset " + codec.error().message);
  info.codec = *codec;
  auto pixel_format = get_string(v, p, "pixel_format");
  if (!pixel_format) return std::move(pixel_format).error();
  if (*pixel_format != pixel_format_name(info.codec))
    return bad_key(p + "pixel_format", "is \"" + *pixel_format + "\" but codec " +
                                           codec_name(info.codec) + " decodes to " +
                                           pixel_format_name(info.codec));

  auto checksum = get_string(v, p, "checksum");
  if (!checksum) return std::move(checksum).error();
  if (*checksum != kChecksumName)
    return make_error(ErrorCode::unsupported, "tileset checksum \"" + *checksum +
                                                  "\" (this build verifies " + kChecksumName + ")");
  auto payload = get_string(v, p, "payload");
  if (!payload) return std::move(payload).error();
  if (*payload != kPayloadName)
    return make_error(ErrorCode::unsupported, "tileset payload format \"" + *payload +
                                                  "\" (this build reads " + kPayloadName + ")");

  auto color_space = get_string(v, p, "color_space");
  if (!color_space) return std::move(color_space).error();
  if (*color_space != "srgb" && *color_space != "linear")
    return make_error(ErrorCode::unsupported,
                      "tileset color_space \"" + *color_space + "\" (known: srgb, linear)");
  info.color_space = *color_space;
  auto downsample = get_string(v, p, "downsample");
  if (!downsample) return std::move(downsample).error();
  info.downsample = *downsample;
  auto sparse = get_bool(v, p, "sparse");
  if (!sparse) return std::move(sparse).error();
  info.sparse = *sparse;
  auto generator = get_string(v, p, "generator");
  if (!generator) return std::move(generator).error();
  info.generator = *generator;
  // Optional: archives written before it existed simply have no content hash.
  auto content_hash = get_optional_string(v, "content_hash");
  if (!content_hash) return std::move(content_hash).error();
  info.content_hash = *content_hash;
  auto georeference = parse_georeference(v, info.geometry);
  if (!georeference) return std::move(georeference).error();
  info.georeference = *georeference;

  // Generic keys: optional (other tools may rewrite them), but typed when present.
  auto name = get_optional_string(root, "name");
  if (!name) return std::move(name).error();
  info.name = *name;
  auto description = get_optional_string(root, "description");
  if (!description) return std::move(description).error();
  info.description = *description;
  auto format = get_optional_string(root, "format");
  if (!format) return std::move(format).error();
  if (!format->empty() && *format != std::string("vts-") + codec_name(info.codec))
    return bad_key("format",
                   "is \"" + *format + "\" but vtstream.codec is " + codec_name(info.codec));
  return info;
}

}  // namespace

std::string TilesetInfo::to_json() const {
  // ordered_json keeps the keys in the documented order, so metadata diffs stay readable.
  ordered_json ours = {
      {"format_version", format_version},
      {"width", geometry.width()},
      {"height", geometry.height()},
      {"tile_size", geometry.tile_size()},
      {"border", geometry.border()},
      {"max_zoom", geometry.max_zoom()},
      {"stored_size", geometry.stored_size()},
      {"codec", codec_name(codec)},
      {"pixel_format", pixel_format_name(codec)},
      {"color_space", color_space},
      {"downsample", downsample},
      {"sparse", sparse},
      {"checksum", kChecksumName},
      {"payload", kPayloadName},
      {"generator", generator},
  };
  if (!content_hash.empty()) ours["content_hash"] = content_hash;
  if (georeference) {
    const Georeference& g = *georeference;
    ours["georeference"] = {
        {"tiling", tiling_name(g.tiling)},
        {"crs", g.crs()},
        {"bounds", {g.bounds.west, g.bounds.south, g.bounds.east, g.bounds.north}},
        {"center", {g.center.lon, g.center.lat, g.center.level}},
    };
  }
  ordered_json root = {
      {"name", name},        {"description", description},
      {"type", "baselayer"}, {"format", std::string("vts-") + codec_name(codec)},
      {"version", "1"},      {"vtstream", std::move(ours)},
  };
  // Strings are caller-supplied and may hold invalid UTF-8; replace rather than throw.
  return root.dump(-1, ' ', false, json::error_handler_t::replace);
}

Result<TilesetInfo> TilesetInfo::from_json(const std::string& metadata_json) {
  // Depth-limited: metadata comes from archives anyone may have written.
  Result<json> root = parse_json(metadata_json, "tileset metadata");
  if (!root) return std::move(root).error();
  try {
    return parse(*root);
  } catch (const std::exception& e) {
    // Nothing above should throw after parsing; never let it escape as an exception anyway.
    return make_error(ErrorCode::corrupt, std::string("tileset metadata: ") + e.what());
  }
}

Status check_georeference(const Georeference& geo, const Geometry& g) {
  if (geo.tiling == Tiling::none)
    return make_error(ErrorCode::invalid_argument, "georeference tiling must not be none");
  if (Status s = check_tiling_geometry(geo.tiling, g); !s)
    return make_error(ErrorCode::invalid_argument, "georeference: " + s.error().message);
  const LonLatBounds& b = geo.bounds;
  const LonLatBounds ext = scheme_extent(geo.tiling);
  const std::string scheme(tiling_name(geo.tiling));
  for (double v : {b.west, b.south, b.east, b.north}) {
    if (!std::isfinite(v))
      return make_error(ErrorCode::invalid_argument,
                        "georeference bounds " + bounds_text(b) + " are not all finite");
  }
  if (b.west > b.east)
    return make_error(ErrorCode::invalid_argument,
                      "georeference bounds " + bounds_text(b) +
                          ": west > east (a footprint crossing the antimeridian is not supported; "
                          "split it at 180 degrees)");
  if (!(b.west < b.east && b.south < b.north))
    return make_error(ErrorCode::invalid_argument, "georeference bounds " + bounds_text(b) +
                                                       " are empty (need west < east and south "
                                                       "< north)");
  if (b.west < ext.west || b.east > ext.east || b.south < ext.south || b.north > ext.north)
    return make_error(ErrorCode::invalid_argument, "georeference bounds " + bounds_text(b) +
                                                       " leave " + scheme + "'s extent " +
                                                       bounds_text(ext));
  const LonLatLevel& c = geo.center;
  if (!(c.lon >= b.west && c.lon <= b.east && c.lat >= b.south && c.lat <= b.north))
    return make_error(ErrorCode::invalid_argument, "georeference center " + num(c.lon) + "," +
                                                       num(c.lat) + " is outside the bounds " +
                                                       bounds_text(b));
  if (c.level < 0 || c.level > g.max_zoom())
    return make_error(ErrorCode::invalid_argument,
                      "georeference center level " + std::to_string(c.level) +
                          " is not within 0.." + std::to_string(g.max_zoom()));
  return {};
}

std::string tileset_name_problem(std::string_view name) {
  if (name.empty()) return "is empty";
  if (name.size() > 128) return "is longer than 128 characters";
  if (name.front() == '.') return "starts with a dot";
  for (char c : name) {
    const bool ok = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
                    c == '.' || c == '_' || c == '-';
    if (!ok) return "contains a character outside [A-Za-z0-9._-]";
  }
  return {};
}

}  // namespace protocol
}  // namespace vts
