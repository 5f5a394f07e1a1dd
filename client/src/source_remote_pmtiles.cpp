// The remote-archive source: a PMTiles v3 archive read with HTTP range requests from any server
// that honours Range (`vts serve`'s /{ts}.pmtiles, nginx, an object store), no tile server needed.
//
// Opening costs one range read of bytes 0..16383 (header, root directory and, for our archives,
// the metadata right after it), plus one more when the metadata lies beyond. A tile then costs
// one range read of its bytes, preceded by one per leaf directory on its path that is not in the
// source's cache of decoded leaves (a archive::DirectoryCache of kLeafCacheBytes). Concurrent
// requests for the same leaf (or the same tile bytes) send identical range requests, which the
// fetcher merges into one transfer; the first callback to arrive decodes the leaf and the others
// find it in the LRU.
//
// Trust model: the server is hostile. Every section, leaf pointer and tile entry is checked
// against the header before it is read; lengths are bounded before anything is requested;
// directories are decompressed under a size limit and parsed with the protocol's checked parser;
// directory chains are cut at archive::kMaxDirectoryDepth; a short body is an error. The archive's
// total size is not known (the fetcher does not report Content-Range totals), so a section that
// lies past the end of the file shows up as a short read (truncated) when it is read.
//
// ETags are computed from each payload's tile header, as `vts serve` and the local source do, so
// a cache revalidates the same way whichever source filled it. If-None-Match is therefore judged
// here, after the tile's bytes have been read: not_modified saves the caller a copy and a decode,
// not the range read. Should the archive be replaced on the server between two reads, offsets
// from the old directories point into the new file; such bytes fail the tile-header check (an
// error) or the client's checksum, and reopening the source picks up the new archive.
//
// A host that ignores Range answers the opening read with 200 and the whole file. That read
// keeps it (up to SourceOptions::max_download, else opening fails naming the host's behaviour)
// and every later read is served from the copy in memory, on the delivery thread: the file is
// downloaded once, never once per tile.
//
// Callbacks run on the fetcher's thread, or on the source's delivery thread for answers found
// without the network (a tile outside the pyramid or missing from a cached directory).
#include <xxhash.h>

#include <algorithm>
#include <cstdio>
#include <functional>
#include <future>
#include <limits>
#include <mutex>
#include <tuple>
#include <utility>

#include "deliverer.hpp"
#include "fetching_source.hpp"
#include "image_layout.hpp"
#include "vts/archive/inspect.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/client/source.hpp"

namespace vts::client {
namespace {

constexpr std::uint64_t kFirstRead = 16384;              // header + root, per the spec
constexpr std::uint64_t kMaxMetadataBytes = 16u << 20;   // stored (compressed) metadata
constexpr std::size_t kMaxMetadataDecoded = 16u << 20;   // decompressed metadata
constexpr std::uint64_t kMaxLeafBytes = 16u << 20;       // one stored leaf directory
constexpr std::size_t kMaxDirectoryDecoded = 64u << 20;  // one decompressed directory
// Decoded leaves kept: a leaf of ours (4096 entries) costs 96 KiB, so this holds hundreds; a leaf
// as large as archive::kMaxDirectoryEntries allows (24 MiB), one.
constexpr std::size_t kLeafCacheBytes = 32u << 20;

using archive::Directory;

// True when [offset, offset + length) lies within [0, size); no overflow for any inputs.
bool within(std::uint64_t offset, std::uint64_t length, std::uint64_t size) {
  return offset <= size && length <= size - offset;
}

bool fits_u64(std::uint64_t offset, std::uint64_t length) {
  return length <= std::numeric_limits<std::uint64_t>::max() - offset;
}

std::string range_text(std::uint64_t offset, std::uint64_t length) {
  return "bytes " + std::to_string(offset) + "-" + std::to_string(offset + length - 1);
}

FetchResult fetch_blocking(Fetcher& fetcher, FetchRequest request) {
  std::promise<FetchResult> promise;
  std::future<FetchResult> future = promise.get_future();
  fetcher.submit(std::move(request),
                 [&promise](FetchResult&& r) { promise.set_value(std::move(r)); });
  return future.get();
}

// A range read's answer as a Status: the fetch went through, the server answered 200/206 and the
// body holds exactly `length` bytes. `what` names the section ("root directory", "tile 3/1/2").
Status check_range_result(const FetchResult& r, const std::string& url, const std::string& what,
                          std::uint64_t offset, std::uint64_t length) {
  if (r.error) {
    Error e = *r.error;
    e.message = what + ": " + e.message;
    return e;
  }
  if (r.status != 200 && r.status != 206) {
    return make_error(r.status == 404 ? ErrorCode::not_found : ErrorCode::io,
                      what + ": GET " + url + " (" + range_text(offset, length) + "): HTTP " +
                          std::to_string(r.status));
  }
  if (r.body.size() != length) {
    return make_error(ErrorCode::truncated,
                      what + ": GET " + url + " (" + range_text(offset, length) + ") returned " +
                          std::to_string(r.body.size()) + " bytes; the archive ends early");
  }
  return {};
}

Result<Directory> decode_directory(std::span<const std::uint8_t> stored,
                                   archive::Compression compression) {
  return archive::decode_directory(stored, compression, kMaxDirectoryDecoded);
}

struct Opened {
  archive::Header header;
  Directory root;
  SourceInfo info;
  // The whole archive, when the host ignored Range and sent it all; null otherwise. Then the
  // Cache-Control that came with it stands for every tile.
  std::shared_ptr<const std::vector<std::uint8_t>> whole;
  std::string whole_cache_control;
};

struct RemotePending {
  SourceRequest request;
  SourceCallback callback;
  std::uint64_t tile_id = 0;
  Fetcher::Handle fetch = 0;  // the transfer in progress; 0 when none
  bool cancelled = false;
};

class RemoteArchiveSource final : public FetchingSource<RemotePending> {
 public:
  RemoteArchiveSource(std::unique_ptr<Fetcher> fetcher, std::string url, Opened opened,
                      std::size_t max_tile_bytes, std::unique_ptr<WorkerPool> deliverer)
      : FetchingSource(std::move(fetcher)),
        url_(std::move(url)),
        header_(opened.header),
        root_(std::move(opened.root)),
        info_(std::move(opened.info)),
        whole_(std::move(opened.whole)),
        whole_cache_control_(std::move(opened.whole_cache_control)),
        max_tile_bytes_(max_tile_bytes),
        deliverer_(std::move(deliverer)) {}

  // Cancels every transfer: their callbacks finish their requests now. Then deliverer_'s
  // destructor (a member) runs the answers still queued.
  ~RemoteArchiveSource() override { close(); }

  const SourceInfo& info() const override { return info_; }
  bool local() const override { return false; }

  Handle fetch(const SourceRequest& request, SourceCallback callback) override {
    Handle h = 0;
    std::shared_ptr<Pending> p;
    {
      std::lock_guard lock(mutex_);
      std::tie(h, p) = add_locked(request, std::move(callback));
    }
    const TileId id = request.id;
    const Geometry& g = info_.info.geometry;
    if (id.z > g.max_zoom() || id.x >= g.tiles_x(id.z) || id.y >= g.tiles_y(id.z)) {
      // Outside the pyramid, as `vts serve` answers 404.
      post_kind(h, SourceTile::Kind::absent);
      return h;
    }
    p->tile_id = archive::zxy_to_tile_id(id.z, id.x, id.y);
    walk(h, root_, 0, /*on_fetcher_thread=*/false);
    return h;
  }

 private:
  using Pending = RemotePending;

  // ---- finishing a request (exactly once) ------------------------------------------------

  // finish() on the fetcher thread (we are in one of its callbacks) or the delivery thread.
  void deliver(Handle h, SourceTile&& tile, bool on_fetcher_thread) {
    if (on_fetcher_thread) return finish(h, std::move(tile));
    // std::function needs a copyable callable: hold the tile by shared_ptr.
    auto t = std::make_shared<SourceTile>(std::move(tile));
    deliverer_->submit([this, h, t] { finish(h, std::move(*t)); });
  }

  void post_kind(Handle h, SourceTile::Kind kind) {
    SourceTile t;
    t.kind = kind;
    deliver(h, std::move(t), false);
  }

  void fail(Handle h, Error e, bool on_fetcher_thread) {
    SourceTile t;
    t.kind = SourceTile::Kind::error;
    t.error = std::move(e);
    deliver(h, std::move(t), on_fetcher_thread);
  }

  // ---- directory walk --------------------------------------------------------------------

  std::string tile_name(Handle h) {
    std::lock_guard lock(mutex_);
    auto it = pending_.find(h);
    return it == pending_.end() ? std::string("?") : it->second->request.id.to_string();
  }

  // Looks the request's tile up in `dir` (at depth `depth`, 0 = root) and the directories below
  // it, reading leaves from the LRU while they are there; starts a transfer for the first leaf
  // that is not, or for the tile's bytes.
  void walk(Handle h, Directory dir, int depth, bool on_fetcher_thread) {
    std::uint64_t tile_id = 0;
    {
      std::lock_guard lock(mutex_);
      auto it = pending_.find(h);
      if (it == pending_.end()) return;
      tile_id = it->second->tile_id;
    }
    for (;;) {
      // The last entry with tile_id <= the wanted id is the only one that can hold it.
      const auto it = std::upper_bound(
          dir->begin(), dir->end(), tile_id,
          [](std::uint64_t id, const archive::Entry& e) { return id < e.tile_id; });
      if (it == dir->begin()) {
        SourceTile t;
        t.kind = SourceTile::Kind::absent;
        return deliver(h, std::move(t), on_fetcher_thread);
      }
      const archive::Entry e = *(it - 1);
      if (e.run_length > 0) {
        if (tile_id - e.tile_id >= e.run_length) {
          SourceTile t;
          t.kind = SourceTile::Kind::absent;
          return deliver(h, std::move(t), on_fetcher_thread);
        }
        return read_tile(h, e, on_fetcher_thread);
      }
      if (depth + 1 >= archive::kMaxDirectoryDepth) {
        return fail(h,
                    make_error(ErrorCode::corrupt,
                               url_ + ": directory cycle or too deep: tile " + tile_name(h) +
                                   " still leads to a leaf directory after " +
                                   std::to_string(archive::kMaxDirectoryDepth) + " levels"),
                    on_fetcher_thread);
      }
      const std::string where = url_ + ": leaf directory at offset " + std::to_string(e.offset) +
                                " length " + std::to_string(e.length);
      if (e.length == 0 || !within(e.offset, e.length, header_.leaf_dirs_length)) {
        return fail(h,
                    make_error(ErrorCode::corrupt,
                               where + " is empty or extends past the leaf section (size " +
                                   std::to_string(header_.leaf_dirs_length) + ")"),
                    on_fetcher_thread);
      }
      if (e.length > kMaxLeafBytes) {
        return fail(h,
                    make_error(ErrorCode::too_large, where + " is over the limit of " +
                                                         std::to_string(kMaxLeafBytes) + " bytes"),
                    on_fetcher_thread);
      }
      if (Directory leaf = cached_leaf(e)) {
        dir = std::move(leaf);
        ++depth;
        continue;
      }
      return read_leaf(h, e, depth + 1, on_fetcher_thread);
    }
  }

  Directory cached_leaf(const archive::Entry& pointer) {
    return leaves_.find(pointer.offset, pointer.length);
  }

  // Starts a range transfer for request h, unless it was cancelled meanwhile (then finishes it).
  void submit(Handle h, std::uint64_t offset, std::uint64_t length, bool on_fetcher_thread,
              FetchCallback callback) {
    std::unique_lock lock(mutex_);
    Pending* p = resume(h);
    if (p == nullptr) {
      lock.unlock();
      SourceTile t;
      t.kind = SourceTile::Kind::cancelled;
      return deliver(h, std::move(t), on_fetcher_thread);
    }
    if (whole_) {
      // The host ignores Range and we hold the whole file: answer as a 206 would, from the copy.
      lock.unlock();
      auto r = std::make_shared<FetchResult>();
      r->status = 206;
      if (offset < whole_->size()) {
        const auto first = whole_->begin() + std::ptrdiff_t(offset);
        r->body.assign(first, first + std::ptrdiff_t(std::min<std::uint64_t>(
                                          length, whole_->size() - offset)));
      }
      auto cb = std::make_shared<FetchCallback>(std::move(callback));
      deliverer_->submit([r, cb] { (*cb)(std::move(*r)); });
      return;
    }
    FetchRequest r;
    r.url = url_;
    r.range = std::make_pair(offset, offset + length - 1);
    r.level = p->request.level;
    r.urgency = p->request.urgency;
    r.group = region_group(p->request.id);
    // The default merge key (URL + range) merges identical reads of a leaf or a shared payload.
    p->fetch = fetcher_->submit(std::move(r), std::move(callback));
  }

  void read_leaf(Handle h, const archive::Entry& pointer, int depth, bool on_fetcher_thread) {
    const std::uint64_t offset = header_.leaf_dirs_offset + pointer.offset;
    submit(h, offset, pointer.length, on_fetcher_thread,
           [this, h, pointer, offset, depth](FetchResult&& r) {
             if (r.cancelled) {
               SourceTile t;
               t.kind = SourceTile::Kind::cancelled;
               return finish(h, std::move(t));
             }
             const std::string what = "leaf directory at offset " + std::to_string(pointer.offset) +
                                      " length " + std::to_string(pointer.length);
             Directory leaf = cached_leaf(pointer);  // a merged twin may have decoded it already
             if (!leaf) {
               if (Status s = check_range_result(r, url_, what, offset, pointer.length); !s) {
                 return fail(h, s.error(), true);
               }
               Result<Directory> d = decode_directory(r.body, header_.internal_compression);
               if (!d) {
                 Error e = std::move(d).error();
                 e.message = url_ + ": " + what + ": " + e.message;
                 return fail(h, std::move(e), true);
               }
               leaf = leaves_.insert(pointer.offset, pointer.length, std::move(*d));
             }
             walk(h, std::move(leaf), depth, true);
           });
  }

  void read_tile(Handle h, const archive::Entry& e, bool on_fetcher_thread) {
    const std::string name = tile_name(h);
    if (e.length == 0 || !within(e.offset, e.length, header_.tile_data_length)) {
      return fail(h,
                  make_error(ErrorCode::corrupt,
                             url_ + ": tile " + name + " (offset " + std::to_string(e.offset) +
                                 ", length " + std::to_string(e.length) +
                                 ") is empty or extends past the tile data section (size " +
                                 std::to_string(header_.tile_data_length) + ")"),
                  on_fetcher_thread);
    }
    if (e.length > max_tile_bytes_) {
      return fail(h,
                  make_error(ErrorCode::too_large,
                             url_ + ": tile " + name + " of " + std::to_string(e.length) +
                                 " bytes is over the limit of " + std::to_string(max_tile_bytes_)),
                  on_fetcher_thread);
    }
    const std::uint64_t offset = header_.tile_data_offset + e.offset;
    const std::uint64_t length = e.length;
    submit(h, offset, length, on_fetcher_thread, [this, h, name, offset, length](FetchResult&& r) {
      SourceTile t;
      if (r.cancelled) {
        t.kind = SourceTile::Kind::cancelled;
        return finish(h, std::move(t));
      }
      if (Status s = check_range_result(r, url_, "tile " + name, offset, length); !s) {
        return fail(h, s.error(), true);
      }
      Result<std::string> etag = info_.image_format.empty()
                                     ? tile_etag(r.body)
                                     : stock_tile_etag(info_.version, offset, length);
      if (!etag) {
        return fail(h,
                    make_error(ErrorCode::corrupt,
                               url_ + ": tile " + name + " (" + range_text(offset, length) +
                                   ") has no valid tile header: " + etag.error().message),
                    true);
      }
      t.etag = std::move(*etag);
      t.fresh_for = cache_control_lifetime(whole_ ? whole_cache_control_ : r.cache_control);
      std::string if_none_match;
      {
        std::lock_guard lock(mutex_);
        if (auto it = pending_.find(h); it != pending_.end()) {
          if_none_match = it->second->request.if_none_match;
        }
      }
      if (etag_matches(if_none_match, t.etag)) {
        t.kind = SourceTile::Kind::not_modified;
      } else {
        t.kind = SourceTile::Kind::ok;
        t.payload = std::move(r.body);
      }
      finish(h, std::move(t));
    });
  }

  const std::string url_;
  const archive::Header header_;
  const Directory root_;
  const SourceInfo info_;
  const std::shared_ptr<const std::vector<std::uint8_t>> whole_;  // see Opened::whole
  const std::string whole_cache_control_;
  const std::size_t max_tile_bytes_;

  archive::DirectoryCache leaves_{kLeafCacheBytes};  // thread-safe on its own

  // Last: destroyed first, after the fetcher is gone, running what is queued (start_deliverer).
  std::unique_ptr<WorkerPool> deliverer_;
};

// Checks the header's sections are well-formed and lie where we can read them.
Status check_header(const archive::Header& h, std::uint64_t first_read_size) {
  switch (h.internal_compression) {
    case archive::Compression::none:
    case archive::Compression::gzip:
    case archive::Compression::zstd:
      break;
    default:
      return make_error(ErrorCode::unsupported,
                        "internal compression " +
                            std::to_string(static_cast<int>(h.internal_compression)) +
                            " (this build reads none, gzip and zstd)");
  }
  struct Section {
    const char* name;
    std::uint64_t offset, length;
  };
  for (const Section& s : {Section{"root directory", h.root_dir_offset, h.root_dir_length},
                           Section{"metadata", h.metadata_offset, h.metadata_length},
                           Section{"leaf directories", h.leaf_dirs_offset, h.leaf_dirs_length},
                           Section{"tile data", h.tile_data_offset, h.tile_data_length}}) {
    if (!fits_u64(s.offset, s.length)) {
      return make_error(ErrorCode::corrupt, std::string(s.name) + " section (offset " +
                                                std::to_string(s.offset) + ", length " +
                                                std::to_string(s.length) + ") overflows");
    }
    if (s.length > 0 && s.offset < archive::kHeaderSize) {
      return make_error(ErrorCode::corrupt, std::string(s.name) + " section (offset " +
                                                std::to_string(s.offset) +
                                                ") overlaps the 127-byte header");
    }
  }
  if (h.root_dir_length == 0) return make_error(ErrorCode::corrupt, "root directory has length 0");
  // The spec puts the root directory in the first 16 KiB, which is all we read for it.
  if (!within(h.root_dir_offset, h.root_dir_length, first_read_size)) {
    return make_error(first_read_size < kFirstRead ? ErrorCode::truncated : ErrorCode::corrupt,
                      "root directory (offset " + std::to_string(h.root_dir_offset) + ", length " +
                          std::to_string(h.root_dir_length) + ") is not within the first " +
                          std::to_string(first_read_size) + " bytes of the archive");
  }
  if (h.metadata_length > kMaxMetadataBytes) {
    return make_error(ErrorCode::too_large, "metadata of " + std::to_string(h.metadata_length) +
                                                " bytes is over the limit of " +
                                                std::to_string(kMaxMetadataBytes));
  }
  return {};
}

// "http://host:port" of a URL, for messages about the host.
std::string host_of(const std::string& url) {
  const std::size_t scheme = url.find("://");
  const std::size_t start = scheme == std::string::npos ? 0 : scheme + 3;
  const std::size_t end = url.find_first_of("/?#", start);
  return url.substr(0, end);
}

Error ignores_range(const std::string& url, std::int64_t size, std::uint64_t max_download) {
  const std::string whole = size >= 0 ? "the whole " + std::to_string(size) + "-byte file"
                                      : "the whole file, of unknown length";
  return make_error(
      ErrorCode::unsupported,
      "host " + host_of(url) + " ignores HTTP Range requests (answered 200 with " + whole +
          " when asked for bytes 0-" + std::to_string(kFirstRead - 1) + " of " + url +
          "); reading tiles from it would download the file once per tile, and it is over the " +
          "download limit of " + std::to_string(max_download) +
          " bytes (--max-download) for one full download; serve it with Range support (nginx, " +
          "`vts serve`, an object store) or raise --max-download");
}

Error in_archive(const std::string& url, Error e) {
  e.message = url + ": " + e.message;
  return e;
}

}  // namespace

Result<std::unique_ptr<TileSource>> open_remote_archive(std::string_view url_view,
                                                        SourceOptions options) {
  const std::string url(url_view.substr(0, url_view.find('#')));
  Result<std::unique_ptr<Fetcher>> fetcher = Fetcher::create(options.fetcher);
  if (!fetcher) return std::move(fetcher).error();

  FetchRequest first;
  first.url = url;
  first.range = std::make_pair(std::uint64_t{0}, kFirstRead - 1);
  // A host that ignores Range sends the whole file here: keep it when it is small enough, and
  // stop at once (CURLOPT_MAXFILESIZE, or the body limit) when it is not.
  first.whole_if_range_ignored = true;
  first.max_body_bytes = std::max(options.max_download, kFirstRead);
  FetchResult head = fetch_blocking(**fetcher, std::move(first));
  if (head.error && head.error->code == ErrorCode::too_large && head.status == 200) {
    return ignores_range(url, head.content_length, options.max_download);
  }
  if (head.error) {
    Error e = *head.error;
    e.message = "cannot open remote archive " + url + ": " + e.message;
    return e;
  }
  if (head.status == 404) {
    return make_error(ErrorCode::not_found, "no archive at " + url + " (HTTP 404)");
  }
  if (head.status != 200 && head.status != 206) {
    return make_error(ErrorCode::io, "cannot open remote archive " + url + ": HTTP " +
                                         std::to_string(head.status));
  }
  std::shared_ptr<const std::vector<std::uint8_t>> whole;
  if (head.range_ignored) {
    if (head.body.size() > options.max_download) {
      return ignores_range(url, std::int64_t(head.body.size()), options.max_download);
    }
    whole = std::make_shared<const std::vector<std::uint8_t>>(std::move(head.body));
  }
  const std::span<const std::uint8_t> bytes(whole ? *whole : head.body);
  Result<archive::Header> header = archive::parse_header(bytes);
  if (!header) {
    return make_error(ErrorCode::corrupt,
                      url + " is not a PMTiles v3 archive (" + header.error().message + ")");
  }
  const archive::Header& h = *header;
  if (Status s = check_header(h, std::min<std::uint64_t>(bytes.size(), kFirstRead)); !s) {
    return in_archive(url, s.error());
  }

  const auto root_bytes = bytes.subspan(h.root_dir_offset, h.root_dir_length);
  Result<Directory> root = decode_directory(root_bytes, h.internal_compression);
  if (!root) {
    Error e = std::move(root).error();
    e.message = url + ": root directory: " + e.message;
    return e;
  }

  // Metadata: usually right after the root, inside the first read; otherwise one more read.
  if (h.metadata_length == 0) {
    return make_error(ErrorCode::unsupported,
                      url + " is a PMTiles archive without metadata, not a vtstream tileset");
  }
  std::vector<std::uint8_t> stored_metadata;
  if (within(h.metadata_offset, h.metadata_length, bytes.size())) {
    const auto m = bytes.subspan(h.metadata_offset, h.metadata_length);
    stored_metadata.assign(m.begin(), m.end());
  } else {
    FetchRequest r;
    r.url = url;
    r.range = std::make_pair(h.metadata_offset, h.metadata_offset + h.metadata_length - 1);
    FetchResult m = fetch_blocking(**fetcher, std::move(r));
    if (Status s = check_range_result(m, url, "metadata", h.metadata_offset, h.metadata_length);
        !s) {
      return in_archive(url, s.error());
    }
    stored_metadata = std::move(m.body);
  }
  Result<std::vector<std::uint8_t>> decoded_metadata =
      archive::decompress(stored_metadata, h.internal_compression, kMaxMetadataDecoded);
  if (!decoded_metadata) {
    return in_archive(url, make_error(decoded_metadata.error().code,
                                      "metadata: " + decoded_metadata.error().message));
  }
  std::string metadata_json(decoded_metadata->begin(), decoded_metadata->end());
  Result<TilesetInfo> info = archive::archive_tileset(h, metadata_json);
  // A stock archive of standard images (no "vtstream" metadata): an image tileset.
  const bool stock =
      !info && info.error().code == ErrorCode::unsupported && is_stock_image_archive(h);
  if (!info && !stock) return in_archive(url, std::move(info).error());

  Opened opened;
  opened.header = h;
  opened.root = std::move(*root);
  if (stock) {
    auto image = stock_archive_info(h, metadata_json, url, options);
    if (!image) return std::move(image).error();
    opened.info = std::move(*image);
  } else {
    opened.info.info = std::move(*info);
    opened.info.key = url;
    opened.info.description_json = std::move(metadata_json);
  }
  opened.info.version =
      archive::archive_version(bytes.first(archive::kHeaderSize), root_bytes, stored_metadata);
  opened.whole = std::move(whole);
  if (opened.whole) opened.whole_cache_control = head.cache_control;
  auto deliverer = start_deliverer();
  if (!deliverer) return std::move(deliverer).error();
  return std::unique_ptr<TileSource>(
      std::make_unique<RemoteArchiveSource>(std::move(*fetcher), url, std::move(opened),
                                            options.fetcher.max_body_bytes, std::move(*deliverer)));
}

}  // namespace vts::client
