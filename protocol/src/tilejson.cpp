#include "vts/protocol/tilejson.hpp"

#include <nlohmann/json.hpp>

#include "vts/base/file_io.hpp"
#include "vts/protocol/json_input.hpp"

namespace vts {
inline namespace protocol {
namespace {

using nlohmann::json;
using nlohmann::ordered_json;

// The "vtstream" object of `info`'s metadata: what this build knows of the tileset, never the
// archive's own metadata (whose other keys, of any size and nesting, are not ours to forward).
ordered_json vtstream_object(const TilesetInfo& info) {
  const std::string made = info.to_json();
  ordered_json meta = ordered_json::parse(made);  // ours: a few levels, valid
  return std::move(meta.at("vtstream"));
}

// The keys of the "vtstream" object TilesetInfo::to_json() writes (and from_json() reads).
constexpr const char* kVtstreamKeys[] = {
    "format_version", "width",   "height",       "tile_size",    "border",      "max_zoom",
    "stored_size",    "codec",   "pixel_format", "color_space",  "downsample",  "sparse",
    "checksum",       "payload", "generator",    "content_hash", "georeference"};

Error not_tilejson(const std::string& url, std::string_view why) {
  return make_error(ErrorCode::corrupt, url + " is not TileJSON (" + std::string(why) + ")");
}

// The "tiles" template, resolved; an error when absent or lacking a placeholder.
Result<std::string> tiles_template(const json& j, const std::string& url) {
  auto tiles = j.find("tiles");
  if (tiles == j.end() || !tiles->is_array() || tiles->empty() || !(*tiles)[0].is_string() ||
      (*tiles)[0].get_ref<const std::string&>().empty()) {
    return not_tilejson(url, "no \"tiles\" array of URL templates");
  }
  std::string t = resolve_url(url, (*tiles)[0].get<std::string>());
  for (const char* p : {"{z}", "{x}", "{y}"}) {
    if (t.find(p) == std::string::npos) {
      return make_error(ErrorCode::corrupt, url + ": tile URL template \"" + t + "\" lacks " + p);
    }
  }
  return t;
}

}  // namespace

std::string write_tilejson(const TileJsonFields& f) {
  const TilesetInfo& info = *f.info;
  ordered_json v = vtstream_object(info);
  if (!f.archive_url.empty()) v["archive"] = std::string(f.archive_url);
  ordered_json j = {
      {"tilejson", "3.0.0"},
      {"name", info.name.empty() ? std::string(f.tileset) : info.name},
      {"description", info.description},
      {"version", std::string(f.version)},
      {"scheme", "xyz"},
      {"tiles", {std::string(f.tiles_url)}},
      // The zooms of the tiles URL: our levels (docs/PROTOCOL.md: for WorldCRS84Quad, TMS + 1).
      {"minzoom", 0},
      {"maxzoom", info.geometry.max_zoom()},
      {"bounds", {-180, -90, 180, 90}},
  };
  if (info.georeference) {
    const Georeference& g = *info.georeference;
    j["bounds"] = {g.bounds.west, g.bounds.south, g.bounds.east, g.bounds.north};
    j["center"] = {g.center.lon, g.center.lat, g.center.level};
  }
  j["vtstream"] = std::move(v);
  return j.dump(2, ' ', false, ordered_json::error_handler_t::replace) + "\n";
}

Result<TileJson> read_tilejson(std::span<const std::uint8_t> body, const std::string& url) {
  // Depth-limited (any server may answer): the "vtstream" object is then safe to walk.
  const std::string_view text(reinterpret_cast<const char*>(body.data()), body.size());
  Result<json> parsed = parse_json(text, "its body");
  if (!parsed) return not_tilejson(url, parsed.error().message);
  const json& j = *parsed;
  if (!j.is_object()) return not_tilejson(url, "not a JSON object");
  TileJson t;
  auto tiles = tiles_template(j, url);
  if (!tiles) return std::move(tiles).error();
  t.tiles = std::move(*tiles);
  auto v = j.find("vtstream");
  if (v == j.end() || !v->is_object()) {
    return make_error(ErrorCode::unsupported,
                      url + " is TileJSON but not a vtstream tileset (no \"vtstream\" object)");
  }
  // The metadata TilesetInfo reads, of the keys it knows only: those of the "vtstream" object
  // (the archive metadata's; "archive" and anything else is left behind) and TileJSON's own name
  // and description.
  json meta = json::object();
  for (const char* k : {"name", "description"}) {
    if (auto it = j.find(k); it != j.end() && it->is_string()) meta[k] = *it;
  }
  json& known = meta["vtstream"] = json::object();
  for (const char* k : kVtstreamKeys) {
    if (auto it = v->find(k); it != v->end()) known[k] = *it;
  }
  Result<TilesetInfo> info =
      TilesetInfo::from_json(meta.dump(-1, ' ', false, json::error_handler_t::replace));
  if (!info) return make_error(info.error().code, url + ": " + info.error().message);
  t.info = std::move(*info);
  if (auto it = j.find("version"); it != j.end() && it->is_string()) t.version = *it;
  return t;
}

std::string resolve_url(const std::string& base, const std::string& ref) {
  if (istarts_with(ref, "http://") || istarts_with(ref, "https://")) return ref;
  const std::size_t scheme_end = base.find("://");
  if (scheme_end == std::string::npos) return ref;
  if (ref.substr(0, 2) == "//") return base.substr(0, scheme_end + 1) + ref;
  const std::size_t authority_end = base.find_first_of("/?#", scheme_end + 3);
  const std::string origin = base.substr(0, authority_end);
  if (!ref.empty() && ref.front() == '/') return origin + ref;
  if (authority_end == std::string::npos || base[authority_end] != '/') return origin + "/" + ref;
  const std::string path = base.substr(0, base.find_first_of("?#", authority_end));
  return path.substr(0, path.rfind('/') + 1) + ref;
}

}  // namespace protocol
}  // namespace vts
