// The local-archive source: a archive::Reader over the file. Every fetch is answered
// synchronously, inside fetch(), with the reader's copy of the stored payload (an archive modified
// in place since it was opened answers with ErrorCode::changed, never with mixed bytes). The
// answers mirror what `vts serve` would send for the same archive (docs/PROTOCOL.md §3): the same
// bytes, the same ETag, absent where the server answers 204 or 404, an error where it answers 500.
// A stock raster archive (PNG/JPEG/WebP tiles, no "vtstream" metadata, e.g. `vts export`'s) opens
// as an image tileset, as the remote-archive source opens it: its tiles have no tile header, so
// their ETag is stock_tile_etag() of the archive version and the tile's place in the file.

#include <atomic>
#include <system_error>
#include <utility>

#include "image_layout.hpp"
#include "vts/archive/inspect.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/client/source.hpp"
#include "vts/store/open.hpp"

namespace vts::client {
namespace {

class LocalSource final : public TileSource {
 public:
  LocalSource(std::shared_ptr<archive::Reader> reader, SourceInfo info, std::string path,
              bool local)
      : reader_(std::move(reader)), info_(std::move(info)), path_(std::move(path)), local_(local) {}

  const SourceInfo& info() const override { return info_; }
  // A reader over an object store answers inside fetch() too, but each answer costs a request.
  bool local() const override { return local_; }

  // Thread-safe: the reader's lookups are, and nothing else here changes after construction.
  Handle fetch(const SourceRequest& request, SourceCallback callback) override {
    const Handle h = next_handle_.fetch_add(1, std::memory_order_relaxed) + 1;
    callback(read(request));
    return h;
  }

  // Every callback has run by the time fetch() returns: nothing to cancel.
  void cancel(Handle) override {}

 private:
  SourceTile read(const SourceRequest& request) const {
    SourceTile t;
    const TileId id = request.id;
    const Geometry& g = info_.info.geometry;
    // Outside the pyramid: `vts serve` answers 404 before looking at the archive.
    if (id.z > g.max_zoom() || id.x >= g.tiles_x(id.z) || id.y >= g.tiles_y(id.z)) {
      t.kind = SourceTile::Kind::absent;
      return t;
    }
    if (!info_.image_format.empty() && !image_tile_exists(info_, id)) {
      t.kind = SourceTile::Kind::absent;  // below min_zoom or outside the bounds
      return t;
    }
    Result<std::vector<std::uint8_t>> payload = reader_->get(id);
    if (!payload) {
      if (payload.error().code == ErrorCode::not_found) {
        t.kind = SourceTile::Kind::absent;
        return t;
      }
      t.error = make_error(payload.error().code,
                           path_ + ": tile " + id.to_string() + ": " + payload.error().message);
      return t;
    }
    Result<std::string> etag = info_.image_format.empty() ? tile_etag(*payload) : stock_etag(id);
    if (!etag) {
      t.error = make_error(etag.error().code, path_ + ": tile " + id.to_string() +
                                                  " is damaged: " + etag.error().message);
      return t;
    }
    t.etag = std::move(*etag);
    if (etag_matches(request.if_none_match, t.etag)) {
      t.kind = SourceTile::Kind::not_modified;
      return t;
    }
    t.kind = SourceTile::Kind::ok;
    t.payload = std::move(*payload);
    return t;
  }

  // A stock archive's tile: the validator the remote-archive source computes for the same tile.
  Result<std::string> stock_etag(TileId id) const {
    Result<archive::Entry> e = reader_->find_entry(archive::zxy_to_tile_id(id.z, id.x, id.y));
    if (!e) return std::move(e).error();
    return stock_tile_etag(info_.version, reader_->header().tile_data_offset + e->offset,
                           e->length);
  }

  std::shared_ptr<archive::Reader> reader_;
  SourceInfo info_;
  std::string path_;
  bool local_ = true;
  std::atomic<Handle> next_handle_{0};
};

// Our archive, or else a stock raster one (as open_remote_archive() decides).
Result<std::unique_ptr<TileSource>> reader_source(std::shared_ptr<archive::Reader> reader,
                                                  std::string key, const std::string& name,
                                                  bool local, const SourceOptions& options) {
  const archive::Header& h = reader->header();
  Result<TilesetInfo> info = archive::archive_tileset(h, reader->metadata_json());
  const bool stock =
      !info && info.error().code == ErrorCode::unsupported && is_stock_image_archive(h);
  if (!info && !stock) return make_error(info.error().code, name + ": " + info.error().message);
  SourceInfo si;
  if (stock) {
    auto image = stock_archive_info(h, reader->metadata_json(), key, options);
    if (!image) return std::move(image).error();
    si = std::move(*image);
  } else {
    si.info = std::move(*info);
    si.key = std::move(key);
    si.description_json = reader->metadata_json();
  }
  si.version = reader->version();  // as `vts serve` computes it
  return std::unique_ptr<TileSource>(
      std::make_unique<LocalSource>(std::move(reader), std::move(si), name, local));
}

}  // namespace

Result<std::unique_ptr<TileSource>> open_local_archive(const std::filesystem::path& path,
                                                       const SourceOptions& options) {
  if (path.empty()) return make_error(ErrorCode::invalid_argument, "empty archive path");
  std::error_code ec;
  std::filesystem::path absolute = std::filesystem::absolute(path, ec);
  if (ec) {
    return make_error(ErrorCode::io,
                      "cannot resolve archive path " + path.string() + ": " + ec.message());
  }
  absolute = absolute.lexically_normal();

  // Reader errors already name the path.
  Result<std::shared_ptr<archive::Reader>> reader = archive::Reader::open(absolute);
  if (!reader) return std::move(reader).error();
  return reader_source(std::move(*reader), "file:" + absolute.string(), absolute.string(), true,
                       options);
}

Result<std::unique_ptr<TileSource>> open_store_archive(const std::string& location) {
  auto options = store::StoreOptions::from_environment();
  if (!options) return std::move(options).error();
  Result<std::shared_ptr<archive::Reader>> reader = store::open_reader(location, *options);
  if (!reader) return std::move(reader).error();
  // The key names the object without its query (a pre-signed URL's signature expires).
  return reader_source(std::move(*reader), location.substr(0, location.find('?')), location, false,
                       {});
}

}  // namespace vts::client
