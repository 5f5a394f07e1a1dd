// PMTiles v3 archives (protomaps/PMTiles spec/v3/spec.md): reader and writer.
//
// Our archives are ordinary PMTiles v3 files: a 127-byte header, a root directory inside the first
// 16 KiB, JSON metadata, optional leaf directories, then tile data clustered in tile-id (Hilbert)
// order with identical payloads stored once. Directories and metadata are gzip-compressed (the
// most widely supported internal compression); tile payloads declare zstd (see codec.hpp).
// The generic layer here knows nothing of our pyramid: metadata is an opaque JSON string.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <list>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/protocol/tiling.hpp"

namespace vts::archive {

enum class Compression : std::uint8_t { unknown = 0, none = 1, gzip = 2, brotli = 3, zstd = 4 };
enum class TileType : std::uint8_t { unknown = 0, mvt = 1, png = 2, jpeg = 3, webp = 4, avif = 5 };

constexpr std::size_t kHeaderSize = 127;
constexpr std::size_t kRootDirectoryLimit = 16384 - kHeaderSize;  // root dir ends within 16 KiB
constexpr int kMaxDirectoryDepth = 4;  // root + up to 3 leaf levels; deeper means a cycle/hostile
// Entries one directory may hold (2^20, 24 MiB decoded). Our writer makes at most 4096 per
// directory; go-pmtiles grows its leaves until the root fits 16 KiB, some 10^5 entries for a
// planet. More is a directory bomb (a few KiB of gzip that decode to 10^7 entries): refused
// as too_large by parse_directory().
constexpr std::size_t kMaxDirectoryEntries = std::size_t{1} << 20;

// Hilbert tile id of (z, x, y): the count of tiles on all coarser levels plus the position of
// (x, y) along the level's Hilbert curve. Requires z <= 31 and x, y < 2^z.
std::uint64_t zxy_to_tile_id(std::uint8_t z, std::uint32_t x, std::uint32_t y);
Result<TileId> tile_id_to_zxy(std::uint64_t tile_id);

// The tile ids of the sub-pyramid under `root` at level z (root.z <= z <= 31): one contiguous
// range, because the Hilbert position of a tile's parent is its own divided by 4. So a
// sub-pyramid is one id range per level, and sub-pyramids sorted by their root's id are in
// archive order at every level (what a sharded build and its merge rely on).
struct TileIdRange {
  std::uint64_t first = 0, last = 0;  // inclusive
  bool operator==(const TileIdRange&) const = default;
};
TileIdRange subtree_tile_ids(TileId root, std::uint8_t z);
// The ids of root's sub-pyramid at every level root.z..max_z (max_z <= 31), one range per level,
// sorted and disjoint: the MergeOptions::ranges of one archive of a set split at level root.z.
std::vector<TileIdRange> subtree_ranges(TileId root, std::uint8_t max_z);
// The ids of every tile with z < k (1 <= k <= 31): {0, first id of level k - 1}, the ranges of
// the top archive of a set split at level k.
TileIdRange levels_above(std::uint8_t k);

struct Header {
  std::uint64_t root_dir_offset = 0, root_dir_length = 0;
  std::uint64_t metadata_offset = 0, metadata_length = 0;
  std::uint64_t leaf_dirs_offset = 0, leaf_dirs_length = 0;
  std::uint64_t tile_data_offset = 0, tile_data_length = 0;
  std::uint64_t addressed_tiles = 0, tile_entries = 0, tile_contents = 0;
  bool clustered = true;
  Compression internal_compression = Compression::gzip;
  Compression tile_compression = Compression::zstd;
  TileType tile_type = TileType::unknown;
  std::uint8_t min_zoom = 0, max_zoom = 0;
  std::int32_t min_lon_e7 = -1800000000, min_lat_e7 = -900000000;
  std::int32_t max_lon_e7 = 1800000000, max_lat_e7 = 900000000;
  std::uint8_t center_zoom = 0;
  std::int32_t center_lon_e7 = 0, center_lat_e7 = 0;
};

std::array<std::uint8_t, kHeaderSize> serialize_header(const Header& h);
// Checks magic "PMTiles" and version 3; does not check offsets against a file size.
Result<Header> parse_header(std::span<const std::uint8_t> bytes);

// One directory entry. run_length == 0 marks a leaf-directory pointer (offset relative to the
// leaf-directories section); otherwise `offset` is relative to the tile-data section and the
// entry addresses tile ids [tile_id, tile_id + run_length).
struct Entry {
  std::uint64_t tile_id = 0;
  std::uint64_t offset = 0;
  std::uint32_t length = 0;
  std::uint32_t run_length = 0;
  bool operator==(const Entry&) const = default;
};

// Uncompressed varint serialisation of a directory (entries sorted by tile_id).
std::vector<std::uint8_t> serialize_directory(std::span<const Entry> entries);
// Parses an uncompressed directory; rejects truncation, trailing bytes, non-increasing ids,
// zero-length entries and more than max_entries entries (too_large, before allocating).
Result<std::vector<Entry>> parse_directory(std::span<const std::uint8_t> bytes,
                                           std::size_t max_entries = kMaxDirectoryEntries);

// A decoded directory: shared and immutable, so a lookup holding one never sees it change.
using Directory = std::shared_ptr<const std::vector<Entry>>;
// Decompresses a directory as stored (at most max_decoded_bytes, else too_large) and parses it
// (at most kMaxDirectoryEntries entries). What every reader of directories calls.
Result<Directory> decode_directory(std::span<const std::uint8_t> stored, Compression c,
                                   std::size_t max_decoded_bytes);

// Compress / decompress with an internal-compression method (none, gzip, zstd). decompress()
// fails with too_large rather than produce more than max_output bytes (decompression bombs).
Result<std::vector<std::uint8_t>> compress(std::span<const std::uint8_t> bytes, Compression c);
Result<std::vector<std::uint8_t>> decompress(std::span<const std::uint8_t> bytes, Compression c,
                                             std::size_t max_output);

// Decoded directories by where they are stored (offset and length of the stored bytes), least
// recently used evicted first, bounded in bytes: the directories held cost at most max_bytes
// (cost(): their entries plus a fixed overhead each) and number at most max_directories. A
// directory that alone costs more than max_bytes is never kept. Directories handed out stay
// valid (shared) after eviction. Thread-safe: every call takes one mutex, and none decodes.
class DirectoryCache {
 public:
  explicit DirectoryCache(std::size_t max_bytes,
                          std::size_t max_directories = std::numeric_limits<std::size_t>::max())
      : max_bytes_(max_bytes), max_directories_(max_directories) {}
  DirectoryCache(const DirectoryCache&) = delete;
  DirectoryCache& operator=(const DirectoryCache&) = delete;

  // The directory stored at (offset, length), now the most recently used; null when not held.
  Directory find(std::uint64_t offset, std::uint64_t length);
  // Keeps `d` as the directory at (offset, length) unless one is held already; returns the one
  // held (or `d` when it is not kept), so two threads that decoded the same leaf share one copy.
  Directory insert(std::uint64_t offset, std::uint64_t length, Directory d);
  // What the held directories cost in bytes (<= max_bytes), and how many there are.
  std::size_t bytes() const;
  std::size_t size() const;
  // What holding `d` costs, in bytes.
  static std::size_t cost(const std::vector<Entry>& d);

 private:
  struct Key {
    std::uint64_t offset, length;
    bool operator==(const Key&) const = default;
  };
  struct KeyHash {
    std::size_t operator()(const Key& k) const noexcept;
  };
  struct Held {
    Key key;
    Directory directory;
    std::size_t cost;
  };

  const std::size_t max_bytes_, max_directories_;
  mutable std::mutex mutex_;
  std::list<Held> lru_;  // most recently used first
  std::unordered_map<Key, std::list<Held>::iterator, KeyHash> index_;
  std::size_t bytes_ = 0;
};

struct WriterOptions {
  std::filesystem::path path;  // final name; nothing appears under it until finish() succeeds
  Compression internal_compression = Compression::gzip;
  Compression tile_compression = Compression::zstd;
  TileType tile_type = TileType::unknown;
  std::uint8_t min_zoom = 0, max_zoom = 0;
  Header bounds;  // only the lon/lat/center fields are used (georeferenced_bounds())
  // Entries per leaf directory (pmtiles_part.hpp's layout: 4096). Smaller values make nested
  // leaves from few tiles, for tests of readers; 2 to 4096.
  std::size_t leaf_entries = 4096;
};

// The header's lon/lat fields for a georeferenced tileset: min/max lon/lat rounded outwards to the
// header's 1e-7 degree units (so the box always contains the footprint and differs from it by
// less than 1e-7 degrees), the center rounded to the nearest unit, center_zoom = center.level.
// The other fields keep their defaults.
Header georeferenced_bounds(const LonLatBounds& b, const LonLatLevel& center);

struct WriterStats {
  std::uint64_t addressed_tiles = 0;  // add_tile() calls
  std::uint64_t tile_contents = 0;    // distinct payloads stored
  std::uint64_t tile_entries = 0;     // directory entries after run-length merging
  std::uint64_t tile_bytes = 0;       // bytes of distinct payloads
  std::uint64_t file_bytes = 0;       // size of the finished archive
};

// Builds an archive. Payloads are spooled to a temporary file beside the destination as they
// arrive (any order, any thread); finish() orders them by tile id, writes the final file under a
// temporary name, fsyncs it and renames it into place. Dropping an unfinished writer removes
// every temporary file. The layout (which equal payloads share bytes, the directories) is the
// rule of pmtiles_part.hpp, which merge_parts() follows too: the file depends only on the tiles.
// Where a build's encoded tiles go: an archive (Writer) or one shard's part (pmtiles_part.hpp).
class TileSink {
 public:
  virtual ~TileSink() = default;
  // Thread-safe. Adding the same tile twice is an invalid_argument error.
  virtual Status add_tile(TileId id, std::span<const std::uint8_t> payload) = 0;
};

class Writer : public TileSink {
 public:
  static Result<std::unique_ptr<Writer>> create(WriterOptions options);
  ~Writer() override = default;
  Status add_tile(TileId id, std::span<const std::uint8_t> payload) override = 0;
  // Not thread-safe with add_tile(). metadata_json is stored as given (gzip-compressed).
  virtual Result<WriterStats> finish(const std::string& metadata_json) = 0;
  // Removes temporary files; the destination is left untouched.
  virtual void abort() noexcept = 0;
};

struct ReaderOptions {
  // Decoded leaf directories kept (LRU): at most this many, costing at most leaf_cache_bytes
  // (DirectoryCache::cost()). 0 entries or 0 bytes: none kept.
  std::size_t leaf_cache_entries = 64;
  std::size_t leaf_cache_bytes = 64u << 20;
  std::size_t max_directory_bytes = 64u << 20;  // size limit of one directory, stored or decoded
  std::size_t max_metadata_bytes = 16u << 20;   // size limit of the metadata, stored or decoded
  std::size_t max_tile_bytes = 256u << 20;      // a larger tile entry is too_large
};

// Where a reader's bytes come from: a file, borrowed bytes, or an object in a remote store
// (store/: s3://, https://). Implementations are thread-safe.
class ByteSource {
 public:
  virtual ~ByteSource() = default;
  virtual std::uint64_t size() const = 0;
  // Reads exactly out.size() bytes at `offset`, which the caller has checked lie within size():
  // changed when the bytes are no longer those opened (a file modified in place, an object
  // replaced), unavailable when a remote store did not answer, io otherwise.
  virtual Status read(std::uint64_t offset, std::span<std::uint8_t> out) const = 0;
  virtual Status check_unchanged() const { return {}; }
  // What to call it in messages (a path or URL); may be empty.
  virtual std::string name() const { return {}; }
};

// Reads an archive from a file with pread(2), never through a mapping, so that another process
// truncating or overwriting the file in place cannot fault the reader's process (or from
// borrowed bytes). Construction validates the header against the file size, reads and decodes
// the root directory and the metadata; lookups validate every entry they follow. Every read of a
// file is followed by a check that the file still has the size and modification time it had at
// open: bytes of a file modified in place since are never returned, the read fails with
// ErrorCode::changed instead (and every later one: a changed reader stays changed). Replacing the
// file by renaming another over its path is not a change: the reader keeps reading the file it
// opened. All const member functions are thread-safe.
//
// open() of a set's manifest (tileset.json) or of its folder opens the set as one reader
// (archive_set.hpp).
class Reader {
 public:
  static Result<std::shared_ptr<Reader>> open(const std::filesystem::path& path,
                                              ReaderOptions options = {});
  // The bytes must outlive the reader (used by fuzzers and tests).
  static Result<std::shared_ptr<Reader>> open_bytes(std::span<const std::uint8_t> bytes,
                                                    ReaderOptions options = {});
  // Reads through any byte source (a remote object: store/); errors name source->name().
  static Result<std::shared_ptr<Reader>> open_source(std::unique_ptr<ByteSource> source,
                                                     ReaderOptions options = {});
  virtual ~Reader() = default;

  virtual const Header& header() const = 0;
  virtual const std::string& metadata_json() const = 0;
  // archive_version() of this archive: what `vts serve` puts in versioned URLs and what the
  // client sources report.
  virtual const std::string& version() const = 0;
  // The archive's size in bytes, as opened.
  virtual std::uint64_t size() const = 0;
  // Copies bytes [offset, offset + out.size()) of the archive into `out`: invalid_argument when
  // they lie beyond size(), changed when the file was modified since open, io on a read error.
  virtual Status read(std::uint64_t offset, std::span<std::uint8_t> out) const = 0;
  // ok while the file is the one opened (always for borrowed bytes), else changed.
  virtual Status check_unchanged() const = 0;

  // A copy of the stored payload of a tile. not_found when the archive has no such tile;
  // corrupt/truncated on a malformed directory; too_large for an entry over max_tile_bytes;
  // changed when the file was modified in place since open.
  virtual Result<std::vector<std::uint8_t>> get(TileId id) const = 0;
  virtual Result<std::vector<std::uint8_t>> get_by_tile_id(std::uint64_t tile_id) const = 0;
  // The directory entry holding tile_id (its offset relative to the tile-data section, checked
  // to lie within it), without reading the payload. Errors as get_by_tile_id().
  virtual Result<Entry> find_entry(std::uint64_t tile_id) const = 0;

  // Visits every tile entry (run_length >= 1) in tile-id order, descending into leaf directories.
  // Stops and returns the error when a directory is malformed or visitor returns false (then ok).
  virtual Status for_each_entry(const std::function<bool(const Entry&)>& visitor) const = 0;
  // Number of leaf directories (for info).
  virtual Result<std::uint64_t> leaf_directory_count() const = 0;
};

// The archive version of the header, root directory and metadata bytes as stored: 16 lowercase
// hex digits of XXH3-64 (seed 0) over them, in that order (docs/PROTOCOL.md §6). What
// Reader::version() reports and what a remote reader works out from its first read.
std::string archive_version(std::span<const std::uint8_t> header,
                            std::span<const std::uint8_t> root,
                            std::span<const std::uint8_t> metadata);

}  // namespace vts::archive
