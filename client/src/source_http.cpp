// The TileJSON source: a tile server described by TileJSON 3.0 with our "vtstream" object
// (docs/PROTOCOL.md §5) — `vts serve`, or any server or CDN holding our tiles under a URL template.
//
// Tiles are fetched from "tiles"[0]. `vts serve` puts the archive version in that template
// (/{ts}@{version}/{z}/{x}/{y}), and answers 404 with `Vts-Error: version-not-current` once the
// archive has been rebuilt. Such a 404 makes the source fetch the TileJSON again (once per tile
// request; the fetcher merges concurrent refetches into one transfer), switch every later request
// to the new template, and retry the tile. The rebuilt tileset must keep its geometry and codec:
// SourceInfo is immutable for the source's life, so a tileset that changed those fails with an
// error that says to reopen it.
//
// Every callback runs on the fetcher's thread.
#include <algorithm>
#include <cctype>
#include <charconv>
#include <cstdint>
#include <future>
#include <limits>
#include <mutex>
#include <utility>

#include "fetching_source.hpp"
#include "image_layout.hpp"
#include "vts/base/file_io.hpp"
#include "vts/client/source.hpp"
#include "vts/protocol/tilejson.hpp"

namespace vts::client {
namespace {

constexpr std::size_t kMaxTileJsonBytes = 4u << 20;

FetchResult fetch_blocking(Fetcher& fetcher, FetchRequest request) {
  std::promise<FetchResult> promise;
  std::future<FetchResult> future = promise.get_future();
  fetcher.submit(std::move(request),
                 [&promise](FetchResult&& r) { promise.set_value(std::move(r)); });
  return future.get();
}

bool same_tileset_shape(const TilesetInfo& a, const TilesetInfo& b) {
  const Geometry &ga = a.geometry, &gb = b.geometry;
  return ga.width() == gb.width() && ga.height() == gb.height() &&
         ga.tile_size() == gb.tile_size() && ga.border() == gb.border() && a.codec == b.codec;
}

struct TileJsonPending {
  SourceRequest request;
  SourceCallback callback;
  Fetcher::Handle fetch = 0;
  std::uint64_t generation = 0;  // of the template the current attempt used
  bool refetched = false;        // TileJSON already refetched for this request
  bool cancelled = false;
};

class TileJsonSource final : public FetchingSource<TileJsonPending> {
 public:
  TileJsonSource(std::unique_ptr<Fetcher> fetcher, SourceInfo info, std::string json_url,
                 TileJson tilejson)
      : FetchingSource(std::move(fetcher)),
        info_(std::move(info)),
        json_url_(std::move(json_url)),
        template_(std::move(tilejson.tiles)),
        version_(std::move(tilejson.version)) {}

  ~TileJsonSource() override { close(); }

  const SourceInfo& info() const override { return info_; }
  bool local() const override { return false; }

  Handle fetch(const SourceRequest& request, SourceCallback callback) override {
    std::lock_guard lock(mutex_);
    auto [h, p] = add_locked(request, std::move(callback));
    submit_tile(h, *p);
    return h;
  }

 private:
  using Pending = TileJsonPending;

  // Caller holds mutex_. Starts the tile transfer with the current template.
  void submit_tile(Handle h, Pending& p) {
    std::string url = template_;
    replace_all(url, "{z}", std::to_string(p.request.id.z));
    replace_all(url, "{x}", std::to_string(p.request.id.x));
    replace_all(url, "{y}", std::to_string(p.request.id.y));
    p.generation = generation_;
    FetchRequest r;
    r.url = url;
    r.if_none_match = p.request.if_none_match;
    r.level = p.request.level;
    r.urgency = p.request.urgency;
    r.group = region_group(p.request.id);
    p.fetch = fetcher_->submit(
        std::move(r), [this, h, url](FetchResult&& res) { on_tile(h, url, std::move(res)); });
  }

  void on_tile(Handle h, const std::string& url, FetchResult&& r) {
    if (finish_fetched(h, r)) return;
    if (r.status == 404 && r.vts_error == kVersionNotCurrent)
      return on_not_current(h, url, first_line(r.body));
    if (r.status == 404) return finish_kind(h, SourceTile::Kind::absent, transfer_of(r));
    finish_error(h, make_error(ErrorCode::io, http_failure("GET", url, r)), transfer_of(r));
  }

  // The archive behind the template was rebuilt: move to the new template (refetching the
  // TileJSON unless another request already did) and retry, once.
  void on_not_current(Handle h, const std::string& url, const std::string& message) {
    std::unique_lock lock(mutex_);
    Pending* p = resume(h);
    if (p == nullptr) {
      lock.unlock();
      return finish_kind(h, SourceTile::Kind::cancelled);
    }
    if (p->refetched) {
      lock.unlock();
      return finish_error(h, make_error(ErrorCode::io, "GET " + url + ": HTTP 404 (" + message +
                                                           ") even after refetching " + json_url_));
    }
    p->refetched = true;
    if (generation_ != p->generation) return submit_tile(h, *p);
    FetchRequest r;
    r.url = json_url_;
    r.level = std::numeric_limits<int>::min();  // before any tile: every tile waits for it
    p->fetch = fetcher_->submit(std::move(r),
                                [this, h](FetchResult&& res) { on_tilejson(h, std::move(res)); });
  }

  void on_tilejson(Handle h, FetchResult&& r) {
    if (r.cancelled) return finish_kind(h, SourceTile::Kind::cancelled);
    if (r.error) {
      Error e = std::move(*r.error);
      e.message = "refetching TileJSON: " + e.message;
      return finish_error(h, std::move(e));
    }
    if (r.status != 200) {
      return finish_error(
          h, make_error(ErrorCode::io, http_failure("refetching TileJSON", json_url_, r)));
    }
    Result<TileJson> tj = read_tilejson(r.body, json_url_);
    if (!tj) return finish_error(h, std::move(tj).error());
    if (!same_tileset_shape(tj->info, info_.info)) {
      return finish_error(
          h, make_error(ErrorCode::unsupported,
                        json_url_ + ": the tileset was rebuilt with a different geometry "
                                    "or codec; open it again"));
    }
    std::unique_lock lock(mutex_);
    Pending* p = resume(h);
    if (p == nullptr) {
      lock.unlock();
      return finish_kind(h, SourceTile::Kind::cancelled);
    }
    // Several requests may bring the same new TileJSON; only a new version moves the template.
    if (tj->version != version_ || tj->tiles != template_) {
      template_ = std::move(tj->tiles);
      version_ = std::move(tj->version);
      ++generation_;
    }
    submit_tile(h, *p);
  }

  const SourceInfo info_;
  const std::string json_url_;

  // Guarded by mutex_.
  std::string template_;
  std::string version_;
  std::uint64_t generation_ = 0;
};

}  // namespace

Result<std::unique_ptr<TileSource>> open_tilejson(std::string_view url, SourceOptions options) {
  // Fragments are never sent; the key drops the query too (it may hold expiring credentials).
  std::string location(url.substr(0, url.find('#')));
  const std::size_t q = location.find('?');
  std::string path = location.substr(0, q);
  const std::string query = q == std::string::npos ? "" : location.substr(q);
  if (!istarts_with(path, "http://") && !istarts_with(path, "https://")) {
    return make_error(ErrorCode::invalid_argument,
                      "TileJSON location " + location + " is not an http(s) URL");
  }
  std::string key = path;
  if (path.ends_with(".json")) {
    key.resize(key.size() - 5);
  } else {
    path += ".json";
  }
  const std::string json_url = path + query;

  Result<std::unique_ptr<Fetcher>> fetcher = Fetcher::create(options.fetcher);
  if (!fetcher) return std::move(fetcher).error();
  FetchRequest request;
  request.url = json_url;
  FetchResult r = fetch_blocking(**fetcher, std::move(request));
  if (r.error) {
    Error e = std::move(*r.error);
    e.message = "cannot open tileset " + json_url + ": " + e.message;
    return e;
  }
  if (r.status == 404) {
    return make_error(ErrorCode::not_found, http_failure("no tileset at", json_url, r));
  }
  if (r.status != 200) {
    return make_error(ErrorCode::io, http_failure("cannot open tileset", json_url, r));
  }
  if (r.body.size() > kMaxTileJsonBytes) {
    return make_error(
        ErrorCode::too_large,
        json_url + ": TileJSON of " + std::to_string(r.body.size()) + " bytes is too large");
  }
  Result<TileJson> tj = read_tilejson(r.body, json_url);
  if (!tj && tj.error().code == ErrorCode::unsupported) {
    // No "vtstream" object: a third-party server's TileJSON of standard image tiles.
    auto layout = read_image_tilejson(r.body, json_url, options);
    if (!layout) return std::move(layout).error();
    return open_image_template(*layout, std::move(key), std::string(r.body.begin(), r.body.end()),
                               std::move(options));
  }
  if (!tj) return std::move(tj).error();

  SourceInfo info;
  info.info = tj->info;
  info.key = std::move(key);
  info.version = tj->version;
  info.description_json.assign(r.body.begin(), r.body.end());
  return std::unique_ptr<TileSource>(std::make_unique<TileJsonSource>(
      std::move(*fetcher), std::move(info), json_url, std::move(*tj)));
}

std::int64_t cache_control_lifetime(std::string_view value) {
  std::int64_t max_age = -1;
  bool immutable = false, no_cache = false;
  while (!value.empty()) {
    const std::size_t comma = value.find(',');
    std::string_view d = value.substr(0, comma);
    value = comma == std::string_view::npos ? std::string_view() : value.substr(comma + 1);
    while (!d.empty() && std::isspace(static_cast<unsigned char>(d.front()))) d.remove_prefix(1);
    while (!d.empty() && std::isspace(static_cast<unsigned char>(d.back()))) d.remove_suffix(1);
    std::string name(d.substr(0, d.find('=')));
    std::transform(name.begin(), name.end(), name.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    if (name == "no-store" || name == "no-cache") {
      no_cache = true;
    } else if (name == "immutable") {
      immutable = true;
    } else if (name == "max-age" && d.find('=') != std::string_view::npos) {
      std::string_view v = d.substr(d.find('=') + 1);
      if (v.size() >= 2 && v.front() == '"' && v.back() == '"') v = v.substr(1, v.size() - 2);
      std::int64_t n = 0;
      const auto [end, ec] = std::from_chars(v.data(), v.data() + v.size(), n);
      if (ec == std::errc::result_out_of_range) n = kFreshForever;
      if ((ec == std::errc() || ec == std::errc::result_out_of_range) &&
          end == v.data() + v.size() && n >= 0) {
        max_age = std::min(n, kFreshForever);
      }
    }
  }
  if (no_cache) return 0;
  if (immutable) return kFreshForever;
  return max_age;
}

}  // namespace vts::client
