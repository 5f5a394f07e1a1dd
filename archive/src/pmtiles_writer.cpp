// PMTiles v3 writer: spool payloads as they arrive, then lay out a clustered archive in finish().
//
// Memory is bounded by the index, not the payloads (TileSpool, pmtiles_io.hpp). Payload bytes live
// only in the spool file until finish() copies them into the archive, laid out by the rule of
// pmtiles_part.hpp (DataLayout, DirectoryBuilder), as merge_parts() does.
//
// Files: the spool (".NAME.spool-XXXXXX") is created beside the destination and unlinked at once,
// so even a killed process leaks no spool; finish() writes ".NAME.tmp-XXXXXX", fsyncs it, renames
// it over NAME and fsyncs the directory. Any failure removes the temporary file, so NAME is either
// the previous file or the complete new archive.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <xxhash.h>

#include <algorithm>
#include <cassert>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <limits>
#include <mutex>
#include <random>
#include <system_error>

#include "pmtiles_io.hpp"
#include "vts/archive/pmtiles.hpp"

namespace vts::archive {
namespace {

using namespace detail;  // NOLINT(google-build-using-namespace): this file is their home too

class WriterImpl final : public Writer {
 public:
  WriterImpl(WriterOptions options, std::unique_ptr<TileSpool> spool)
      : options_(std::move(options)), spool_(std::move(spool)) {}
  ~WriterImpl() override { abort(); }

  Status add_tile(TileId id, std::span<const std::uint8_t> payload) override {
    return spool_->add(id, payload);
  }

  Result<WriterStats> finish(const std::string& metadata_json) override {
    if (!spool_->close())
      return make_error(ErrorCode::invalid_argument, "finish() after finish() or abort()");
    Result<WriterStats> result = write(metadata_json);
    spool_->release();
    return result;
  }

  void abort() noexcept override { spool_->release(); }

 private:
  Result<WriterStats> write(const std::string& metadata_json) {
    const std::vector<TileSpool::Record>& records = spool_->records();
    if (records.empty()) {
      // The spec requires a non-empty root directory, so an archive needs at least one tile.
      return make_error(ErrorCode::invalid_argument,
                        "no tiles were added to " + options_.path.string());
    }
    // The layout rule (pmtiles_part.hpp), which merge_parts() follows too. Blobs are distinct
    // payloads already (equal bytes were stored once), so two blobs are equal when they are one.
    Result<DirectoryBuilder> dirs = DirectoryBuilder::create(
        options_.path, options_.internal_compression, options_.leaf_entries);
    if (!dirs) return std::move(dirs).error();
    std::vector<std::uint64_t> order;  // blobs in data order (a blob may be stored twice)
    WriterStats stats;
    {
      DataLayout<std::uint64_t> layout;
      const auto same = [](std::uint64_t a, std::uint64_t b) -> Result<bool> { return a == b; };
      for (const TileSpool::Record& r : records) {
        const TileSpool::Blob& b = spool_->blob(r.blob);
        auto placed = layout.place(PayloadKey{b.hash_low, b.hash_high, b.length}, r.blob, same);
        if (!placed) return std::move(placed).error();
        if (placed->fresh) order.push_back(r.blob);
        if (Status s = dirs->add(r.tile_id, placed->offset, b.length); !s) return s.error();
      }
      stats.tile_bytes = layout.data_size();
    }
    Result<std::vector<std::uint8_t>> root = dirs->finish();
    if (!root) return std::move(root).error();
    stats.addressed_tiles = records.size();
    stats.tile_contents = order.size();
    stats.tile_entries = dirs->entries();

    Status written =
        write_archive(options_, metadata_json, *root, *dirs, stats, [&](BufferedOut& w) {
          for (std::uint64_t blob : order) {
            const TileSpool::Blob& b = spool_->blob(blob);
            if (Status s = w.copy_from(spool_->fd(), spool_->path(), b.spool_offset, b.length); !s)
              return s;
          }
          return Status{};
        });
    if (!written) return written.error();
    return stats;
  }

  WriterOptions options_;
  std::unique_ptr<TileSpool> spool_;
};

}  // namespace

Header georeferenced_bounds(const LonLatBounds& b, const LonLatLevel& center) {
  const auto e7 = [](double units) { return static_cast<std::int32_t>(units); };
  Header h;
  h.min_lon_e7 = e7(std::floor(b.west * 1e7));
  h.min_lat_e7 = e7(std::floor(b.south * 1e7));
  h.max_lon_e7 = e7(std::ceil(b.east * 1e7));
  h.max_lat_e7 = e7(std::ceil(b.north * 1e7));
  h.center_lon_e7 = e7(std::round(center.lon * 1e7));
  h.center_lat_e7 = e7(std::round(center.lat * 1e7));
  h.center_zoom = static_cast<std::uint8_t>(std::clamp(center.level, 0, 255));
  return h;
}

Result<std::unique_ptr<Writer>> Writer::create(WriterOptions options) {
  if (options.path.empty() || !options.path.has_filename()) {
    return make_error(ErrorCode::invalid_argument,
                      "archive path '" + options.path.string() + "' names no file");
  }
  switch (options.internal_compression) {
    case Compression::none:
    case Compression::gzip:
    case Compression::zstd:
      break;
    default:
      return make_error(ErrorCode::invalid_argument,
                        "internal compression must be none, gzip or zstd");
  }
  if (options.min_zoom > options.max_zoom || options.max_zoom > 31) {
    return make_error(ErrorCode::invalid_argument,
                      "zoom range " + std::to_string(options.min_zoom) + ".." +
                          std::to_string(options.max_zoom) + " is not within 0..31");
  }
  std::error_code ec;
  if (std::filesystem::is_directory(options.path, ec)) {
    return make_error(ErrorCode::invalid_argument,
                      "archive path " + options.path.string() + " is a directory");
  }
  Result<std::unique_ptr<TileSpool>> spool = TileSpool::create(options.path);
  if (!spool) return std::move(spool).error();
  return std::unique_ptr<Writer>(new WriterImpl(std::move(options), std::move(spool).value()));
}

}  // namespace vts::archive
