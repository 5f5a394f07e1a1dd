// Image tilesets of third-party servers: an XYZ/TMS URL template or a TileJSON without our
// "vtstream" object (MapProxy, Martin, TileServer GL, titiler, nginx over a gdal2tiles folder, a
// CDN). Tiles are standard PNG/JPEG/WebP, one URL each, on the WebMercatorQuad grid; the tileset
// is described to the client as a borderless WebMercatorQuad pyramid georeferenced to the bounds,
// so the demand model, the warm walk and the viewer work on it as on ours.
//
// Callbacks run on the fetcher's thread, or on the source's callback thread for tiles outside the
// zoom range or bounds (absent without a request).
#include <algorithm>
#include <cctype>
#include <cmath>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "deliverer.hpp"
#include "fetching_source.hpp"
#include "image_layout.hpp"
#include "vts/base/file_io.hpp"
#include "vts/client/source.hpp"
#include "vts/protocol/json_input.hpp"
#include "vts/protocol/tilejson.hpp"

namespace vts::client {
namespace {

constexpr int kMaxImageZoom = 24;

Error bad(std::string m) {
  return make_error(ErrorCode::invalid_argument, std::move(m));
}

// A template's hosts: {s} as a, b, c (Leaflet's default subdomains), a range {a-c} or {1-4}
// (OpenLayers') as each character of it; else the template itself.
std::vector<std::string> expand_hosts(const std::string& t) {
  std::string_view from = "{s}";
  std::vector<std::string> hosts;
  if (t.find(from) != std::string::npos) {
    hosts = {"a", "b", "c"};
  } else {
    for (std::size_t p = t.find('{'); p != std::string::npos; p = t.find('{', p + 1)) {
      if (p + 4 >= t.size() || t[p + 2] != '-' || t[p + 4] != '}') continue;
      const char a = t[p + 1], b = t[p + 3];
      const bool letters = std::islower(static_cast<unsigned char>(a)) &&
                           std::islower(static_cast<unsigned char>(b));
      const bool digits = std::isdigit(static_cast<unsigned char>(a)) &&
                          std::isdigit(static_cast<unsigned char>(b));
      if (!(letters || digits) || a > b) continue;
      from = std::string_view(t).substr(p, 5);
      for (char c = a; c <= b; ++c) hosts.emplace_back(1, c);
      break;
    }
  }
  if (hosts.empty()) return {t};
  std::vector<std::string> out;
  for (const std::string& h : hosts) {
    std::string u = t;
    replace_all(u, from, h);
    out.push_back(std::move(u));
  }
  return out;
}

bool lower_ends_with(std::string s, std::string_view suffix) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s.ends_with(suffix);
}

struct ImagePending {
  SourceRequest request;
  SourceCallback callback;
  Fetcher::Handle fetch = 0;
  bool cancelled = false;
};

class ImageTemplateSource final : public FetchingSource<ImagePending> {
 public:
  ImageTemplateSource(std::unique_ptr<Fetcher> fetcher, SourceInfo info, ImageLayout layout,
                      std::unique_ptr<WorkerPool> callbacks)
      : FetchingSource(std::move(fetcher)),
        info_(std::move(info)),
        layout_(std::move(layout)),
        callbacks_(std::move(callbacks)) {
    for (const std::string& t : layout_.mirrors) {
      auto more = expand_hosts(t);
      urls_.insert(urls_.end(), more.begin(), more.end());
    }
    auto first = expand_hosts(layout_.tiles);
    urls_.insert(urls_.begin(), first.begin(), first.end());
  }
  ~ImageTemplateSource() override { close(); }

  const SourceInfo& info() const override { return info_; }
  bool local() const override { return false; }

  Handle fetch(const SourceRequest& request, SourceCallback callback) override {
    std::lock_guard lock(mutex_);
    auto [h, p] = add_locked(request, std::move(callback));
    if (!image_tile_exists(info_, request.id)) {
      // Outside the zoom range or the bounds: a viewer of this server would not ask.
      callbacks_->submit([this, h = h] {
        SourceTile t;
        t.kind = SourceTile::Kind::absent;
        finish(h, std::move(t));
      });
      return h;
    }
    const std::string url = tile_url(request.id);
    FetchRequest r;
    r.url = url;
    r.if_none_match = request.if_none_match;
    r.level = request.level;
    r.urgency = request.urgency;
    r.group = region_group(request.id);
    p->fetch = fetcher_->submit(
        std::move(r), [this, h = h, url](FetchResult&& res) { on_tile(h, url, std::move(res)); });
    return h;
  }

 private:
  std::string tile_url(TileId id) const {
    const std::uint32_t flipped = ((std::uint32_t{1} << id.z) - 1) - id.y;
    std::string url = urls_[(std::uint64_t(id.x) + id.y) % urls_.size()];
    replace_all(url, "{z}", std::to_string(id.z));
    replace_all(url, "{x}", std::to_string(id.x));
    replace_all(url, "{-y}", std::to_string(flipped));
    replace_all(url, "{y}", std::to_string(layout_.tms ? flipped : id.y));
    return url;
  }

  void on_tile(Handle h, const std::string& url, FetchResult&& r) {
    if (finish_fetched(h, r)) return;
    // 404 too: the layout (bounds, zoom range) says the tile exists, so a 404 is a wrong
    // template or missing data, which a load test and a warm must show.
    finish_error(h, make_error(ErrorCode::io, http_failure("GET", url, r)), transfer_of(r));
  }

  const SourceInfo info_;
  const ImageLayout layout_;
  std::vector<std::string> urls_;  // the templates requests are spread over
  // Last: destroyed first, running what is queued (start_deliverer).
  std::unique_ptr<WorkerPool> callbacks_;
};

Result<double> number_at(const nlohmann::json& j, const char* key, const std::string& url) {
  const auto& v = j[key];
  if (!v.is_number()) return bad(url + ": \"" + key + "\" is not a number");
  return v.get<double>();
}

}  // namespace

std::string format_from_suffix(const std::string& url_template) {
  const std::string path = url_template.substr(0, url_template.find_first_of("?#"));
  if (lower_ends_with(path, ".png")) return "png";
  if (lower_ends_with(path, ".jpg") || lower_ends_with(path, ".jpeg")) return "jpeg";
  if (lower_ends_with(path, ".webp")) return "webp";
  return "image";
}

Result<SourceInfo> image_source_info(const ImageLayout& l, std::string key,
                                     std::string description_json) {
  if (l.max_zoom < 0) {
    return bad(l.tiles + " does not say its zoom levels: give the zoom range (--zoom 0-N)");
  }
  if (l.min_zoom < 0 || l.max_zoom > kMaxImageZoom || l.min_zoom > l.max_zoom) {
    return bad("zoom range " + std::to_string(l.min_zoom) + "-" + std::to_string(l.max_zoom) +
               " is not within 0-" + std::to_string(kMaxImageZoom) + " (min <= max)");
  }
  if (l.tile_size < 64 || l.tile_size > 1024 || (l.tile_size & (l.tile_size - 1)) != 0) {
    return bad("tile size " + std::to_string(l.tile_size) + " is not a power of two in 64-1024");
  }
  const LonLatBounds ext = scheme_extent(Tiling::web_mercator_quad);
  LonLatBounds b = l.bounds;
  if (!(std::isfinite(b.west) && std::isfinite(b.south) && std::isfinite(b.east) &&
        std::isfinite(b.north)) ||
      b.west >= b.east || b.south >= b.north) {
    return bad("bounds must be west,south,east,north with west < east and south < north");
  }
  b.west = std::max(b.west, ext.west);
  b.east = std::min(b.east, ext.east);
  b.south = std::max(b.south, ext.south);
  b.north = std::min(b.north, ext.north);
  if (b.west >= b.east || b.south >= b.north) {
    return bad("bounds lie outside the Web Mercator square (latitudes within +-85.0511)");
  }
  auto g = tiling_geometry(Tiling::web_mercator_quad, l.max_zoom, l.tile_size, 0);
  if (!g) return g.error();
  SourceInfo s;
  s.info.geometry = *g;
  s.info.sparse = true;
  s.info.name = key;
  s.info.generator = "third-party";
  Georeference geo;
  geo.tiling = Tiling::web_mercator_quad;
  geo.bounds = b;
  geo.center = default_center(geo.tiling, *g, b);
  geo.center.level = std::max(geo.center.level, l.min_zoom);
  s.info.georeference = geo;
  s.key = std::move(key);
  s.description_json = std::move(description_json);
  s.image_format = l.format.empty() ? "image" : l.format;
  s.image_tile_size = l.tile_size;
  s.min_zoom = l.min_zoom;
  return s;
}

bool image_tile_exists(const SourceInfo& info, TileId id) {
  const Geometry& g = info.info.geometry;
  if (id.z < info.min_zoom || !g.valid_level(id.z) || !g.exists(id)) return false;
  if (!info.info.georeference) return true;
  const Georeference& geo = *info.info.georeference;
  const TileRect r = footprint_tiles(geo.tiling, g, id.z, geo.bounds);
  return id.x >= r.x0 && id.x < r.x1 && id.y >= r.y0 && id.y < r.y1;
}

Result<ImageLayout> read_image_tilejson(std::span<const std::uint8_t> body, const std::string& url,
                                        const SourceOptions& options) {
  const auto corrupt = [&](const std::string& why) {
    return make_error(ErrorCode::corrupt, url + " is not TileJSON: " + why);
  };
  // Depth-limited: a third-party server's document; only the keys below are read from it.
  auto parsed =
      parse_json(std::string_view(reinterpret_cast<const char*>(body.data()), body.size()), url);
  if (!parsed) return std::move(parsed).error();
  const nlohmann::json& j = *parsed;
  if (!j.is_object()) return corrupt("not a JSON object");
  const auto tiles = j.find("tiles");
  if (tiles == j.end() || !tiles->is_array() || tiles->empty() || !(*tiles)[0].is_string())
    return corrupt("no \"tiles\" array of URL templates");
  ImageLayout l;
  for (const auto& t : *tiles) {
    if (!t.is_string()) return corrupt("a \"tiles\" entry is not a URL template");
    std::string u = resolve_url(url, t.get<std::string>());
    if (u.find("{z}") == std::string::npos || u.find("{x}") == std::string::npos ||
        (u.find("{y}") == std::string::npos && u.find("{-y}") == std::string::npos))
      return corrupt("tile template " + u + " lacks {z}, {x} or {y}");
    if (l.tiles.empty())
      l.tiles = std::move(u);
    else
      l.mirrors.push_back(std::move(u));
  }
  if (j.contains("scheme") && !j["scheme"].is_string())
    return bad(url + ": \"scheme\" is not \"xyz\" or \"tms\"");
  l.tms = j.value("scheme", std::string("xyz")) == "tms";
  l.min_zoom = 0;
  l.max_zoom = kMaxImageZoom;  // TileJSON's default is 30; finer levels are not addressed
  for (const char* key : {"minzoom", "maxzoom"}) {
    if (!j.contains(key)) continue;
    auto v = number_at(j, key, url);
    if (!v) return v.error();
    // Clamped before the conversion (a huge number would not fit an int); a negative one stays
    // negative, for image_source_info() to refuse naming the field.
    (key[1] == 'i' ? l.min_zoom : l.max_zoom) = int(std::clamp(*v, -1.0, double(kMaxImageZoom)));
  }
  if (j.contains("tileSize")) {
    auto v = number_at(j, "tileSize", url);
    if (!v) return v.error();
    l.tile_size = std::uint32_t(std::clamp(*v, 0.0, 65536.0));  // refused below unless 64..1024
  }
  if (j.contains("bounds")) {
    const auto& b = j["bounds"];
    if (!b.is_array() || b.size() != 4 || !b[0].is_number() || !b[1].is_number() ||
        !b[2].is_number() || !b[3].is_number())
      return bad(url + ": \"bounds\" is not [west, south, east, north]");
    l.bounds = {b[0].get<double>(), b[1].get<double>(), b[2].get<double>(), b[3].get<double>()};
  }
  l.format = j.contains("format") && j["format"].is_string() ? j["format"].get<std::string>()
                                                             : format_from_suffix(l.tiles);
  if (l.format == "jpg") l.format = "jpeg";
  if (l.format == "pbf" || l.format == "mvt" || j.contains("vector_layers"))
    return make_error(ErrorCode::unsupported, url + " describes vector tiles, not images");
  if (options.min_zoom >= 0) l.min_zoom = options.min_zoom;
  if (options.max_zoom >= 0) l.max_zoom = options.max_zoom;
  if (options.bounds) l.bounds = *options.bounds;
  return l;
}

Result<SourceInfo> stock_archive_info(const archive::Header& h, const std::string& metadata_json,
                                      std::string key, const SourceOptions& options) {
  ImageLayout l;
  switch (h.tile_type) {
    case archive::TileType::png:
      l.format = "png";
      break;
    case archive::TileType::jpeg:
      l.format = "jpeg";
      break;
    case archive::TileType::webp:
      l.format = "webp";
      break;
    default:
      return make_error(ErrorCode::unsupported,
                        key +
                            " is neither a vtstream archive (no \"vtstream\" metadata) nor one "
                            "of png, jpeg or webp tiles (tile type " +
                            std::to_string(int(h.tile_type)) + ")");
  }
  if (h.tile_compression != archive::Compression::none &&
      h.tile_compression != archive::Compression::unknown)
    return make_error(ErrorCode::unsupported,
                      key + ": its image tiles are compressed again (tile compression " +
                          std::to_string(int(h.tile_compression)) +
                          "); a web map reads them only uncompressed (none)");
  // A stock archive's metadata is optional here: only its "tileSize" is read from it.
  if (auto meta = parse_json(metadata_json, "archive metadata"); meta && meta->is_object()) {
    const auto size = meta->find("tileSize");
    if (size != meta->end() && size->is_number_unsigned())  // refused below unless 64..1024
      l.tile_size = std::uint32_t(std::min<std::uint64_t>(
          size->get<std::uint64_t>(), std::numeric_limits<std::uint32_t>::max()));
  }
  l.tiles = key;
  l.min_zoom = options.min_zoom >= 0 ? options.min_zoom : h.min_zoom;
  l.max_zoom = options.max_zoom >= 0 ? options.max_zoom : h.max_zoom;
  l.bounds = options.bounds.value_or(LonLatBounds{h.min_lon_e7 * 1e-7, h.min_lat_e7 * 1e-7,
                                                  h.max_lon_e7 * 1e-7, h.max_lat_e7 * 1e-7});
  auto info = image_source_info(l, key, metadata_json);
  if (!info) {
    Error e = std::move(info).error();
    e.message = key + ": " + e.message;
    return e;
  }
  return info;
}

std::string stock_tile_etag(const std::string& version, std::uint64_t offset,
                            std::uint64_t length) {
  return '"' + version + '-' + std::to_string(offset) + '-' + std::to_string(length) + '"';
}

Result<std::unique_ptr<TileSource>> open_image_template(const ImageLayout& layout, std::string key,
                                                        std::string description_json,
                                                        SourceOptions options) {
  if (!istarts_with(layout.tiles, "http://") && !istarts_with(layout.tiles, "https://"))
    return bad("tile template " + layout.tiles + " is not an http(s) URL");
  auto info = image_source_info(layout, std::move(key), std::move(description_json));
  if (!info) return info.error();
  auto fetcher = Fetcher::create(options.fetcher);
  if (!fetcher) return std::move(fetcher).error();
  auto callbacks = start_deliverer();
  if (!callbacks) return std::move(callbacks).error();
  return std::unique_ptr<TileSource>(std::make_unique<ImageTemplateSource>(
      std::move(*fetcher), std::move(*info), layout, std::move(*callbacks)));
}

}  // namespace vts::client
