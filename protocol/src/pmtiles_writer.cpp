// PMTiles v3 writer: spool payloads as they arrive, then lay out a clustered archive in finish().
//
// Memory is bounded by the index, not the payloads: per tile we keep 16 bytes (tile id, blob
// number) plus a slot of the duplicate-id set, per distinct payload 32 bytes plus a hash slot.
// Payload bytes live only in the spool file until finish() copies them into the archive.
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

#include "vts/protocol/pmtiles.hpp"

namespace vts::pmtiles {
namespace {

std::string tile_name(TileId id) {
  return std::to_string(id.z) + "/" + std::to_string(id.x) + "/" + std::to_string(id.y);
}

Error io_error(const std::string& what, const std::filesystem::path& path, int err) {
  // std::generic_category().message() is strerror's text without strerror's shared buffer.
  return make_error(ErrorCode::io,
                    what + " " + path.string() + ": " + std::generic_category().message(err));
}

// Owns a file descriptor.
class Fd {
 public:
  Fd() = default;
  explicit Fd(int fd) : fd_(fd) {}
  Fd(Fd&& o) noexcept : fd_(std::exchange(o.fd_, -1)) {}
  Fd& operator=(Fd&& o) noexcept {
    if (this != &o) {
      reset();
      fd_ = std::exchange(o.fd_, -1);
    }
    return *this;
  }
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  ~Fd() { reset(); }
  int get() const { return fd_; }
  void reset() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }
  // Closes and reports the error close() returns (write-back failures on some file systems).
  int close_checked() {
    const int fd = std::exchange(fd_, -1);
    return fd >= 0 && ::close(fd) != 0 ? errno : 0;
  }

 private:
  int fd_ = -1;
};

// Creates dir/".NAME.<kind>-XXXXXX" with O_EXCL. We do not use mkstemp so that the archive gets the
// usual umask-derived permissions (mkstemp forces 0600).
Result<std::pair<Fd, std::filesystem::path>> create_unique(const std::filesystem::path& dir,
                                                           const std::string& stem, mode_t mode) {
  static constexpr char kChars[] = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789";
  std::random_device rd;
  std::mt19937_64 rng((std::uint64_t{rd()} << 32) ^ rd());
  std::filesystem::path candidate;
  for (int attempt = 0; attempt < 100; ++attempt) {
    std::string name = stem;
    for (int i = 0; i < 6; ++i) name += kChars[rng() % (sizeof(kChars) - 1)];
    candidate = dir / name;
    const int fd = ::open(candidate.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, mode);
    if (fd >= 0) return std::pair<Fd, std::filesystem::path>{Fd(fd), candidate};
    if (errno != EEXIST) return io_error("cannot create", candidate, errno);
  }
  return io_error("cannot create a unique temporary file like", candidate, EEXIST);
}

Status pwrite_all(int fd, const std::uint8_t* data, std::size_t size, std::uint64_t offset,
                  const std::filesystem::path& path) {
  while (size > 0) {
    const ssize_t n = ::pwrite(fd, data, size, static_cast<off_t>(offset));
    if (n < 0) {
      if (errno == EINTR) continue;
      return io_error("cannot write", path, errno);
    }
    if (n == 0) return io_error("cannot write", path, EIO);
    data += n;
    size -= static_cast<std::size_t>(n);
    offset += static_cast<std::uint64_t>(n);
  }
  return {};
}

Status pread_all(int fd, std::uint8_t* data, std::size_t size, std::uint64_t offset,
                 const std::filesystem::path& path) {
  while (size > 0) {
    const ssize_t n = ::pread(fd, data, size, static_cast<off_t>(offset));
    if (n < 0) {
      if (errno == EINTR) continue;
      return io_error("cannot read", path, errno);
    }
    if (n == 0) return make_error(ErrorCode::io, "unexpected end of " + path.string());
    data += n;
    size -= static_cast<std::size_t>(n);
    offset += static_cast<std::uint64_t>(n);
  }
  return {};
}

// Sequential writer with a large buffer, so that copying millions of small tiles costs few
// syscalls.
class BufferedOut {
 public:
  BufferedOut(int fd, std::filesystem::path path) : fd_(fd), path_(std::move(path)) {
    buf_.resize(4u << 20);
  }
  std::uint64_t position() const { return flushed_ + used_; }

  Status write(std::span<const std::uint8_t> bytes) {
    while (!bytes.empty()) {
      std::span<std::uint8_t> room = reserve();
      const std::size_t n = std::min(room.size(), bytes.size());
      std::memcpy(room.data(), bytes.data(), n);
      used_ += n;
      bytes = bytes.subspan(n);
      if (used_ == buf_.size()) {
        if (Status s = flush(); !s) return s;
      }
    }
    return {};
  }
  // Copies `size` bytes at `offset` of file `src` into the output.
  Status copy_from(int src, const std::filesystem::path& src_path, std::uint64_t offset,
                   std::uint64_t size) {
    while (size > 0) {
      std::span<std::uint8_t> room = reserve();
      const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(room.size(), size));
      if (Status s = pread_all(src, room.data(), n, offset, src_path); !s) return s;
      used_ += n;
      offset += n;
      size -= n;
      if (used_ == buf_.size()) {
        if (Status s = flush(); !s) return s;
      }
    }
    return {};
  }
  Status flush() {
    if (Status s = pwrite_all(fd_, buf_.data(), used_, flushed_, path_); !s) return s;
    flushed_ += used_;
    used_ = 0;
    return {};
  }

 private:
  std::span<std::uint8_t> reserve() { return std::span(buf_).subspan(used_); }

  int fd_;
  std::filesystem::path path_;
  std::vector<std::uint8_t> buf_;
  std::size_t used_ = 0;
  std::uint64_t flushed_ = 0;
};

// Open-addressing hash index of non-zero 64-bit values with linear probing. The caller supplies
// each value's hash (the table stores only values, 8 bytes a slot, at most 70% full) and, when it
// grows, a function recomputing a stored value's hash. Several values may share a hash.
class FlatIndex {
 public:
  // Calls match(value) for each stored value in the probe sequence of `hash` until it returns
  // true; returns that value, or 0.
  template <typename Match>
  std::uint64_t find(std::uint64_t hash, Match&& match) const {
    if (slots_.empty()) return 0;
    const std::size_t mask = slots_.size() - 1;
    for (std::size_t i = hash & mask;; i = (i + 1) & mask) {
      if (slots_[i] == 0) return 0;
      if (match(slots_[i])) return slots_[i];
    }
  }
  template <typename Rehash>
  void insert(std::uint64_t hash, std::uint64_t value, Rehash&& rehash) {
    assert(value != 0);
    if ((count_ + 1) * 10 > slots_.size() * 7) grow(rehash);
    place(hash, value);
    ++count_;
  }
  void release() {
    slots_.clear();
    slots_.shrink_to_fit();
    count_ = 0;
  }

 private:
  void place(std::uint64_t hash, std::uint64_t value) {
    const std::size_t mask = slots_.size() - 1;
    std::size_t i = hash & mask;
    while (slots_[i] != 0) i = (i + 1) & mask;
    slots_[i] = value;
  }
  template <typename Rehash>
  void grow(Rehash&& rehash) {
    std::vector<std::uint64_t> old = std::move(slots_);
    slots_.assign(old.empty() ? 1024 : old.size() * 2, 0);
    for (std::uint64_t v : old)
      if (v != 0) place(rehash(v), v);
  }

  std::vector<std::uint64_t> slots_;
  std::size_t count_ = 0;
};

// splitmix64 finaliser: tile ids are dense and sequential, which linear probing hates unmixed.
std::uint64_t mix(std::uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ULL;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

struct Directories {
  std::vector<std::uint8_t> root;    // compressed
  std::vector<std::uint8_t> leaves;  // compressed leaf directories, back to back
  std::uint64_t leaf_count = 0;
};

// Lays out the directories: everything in the root when it fits in the first 16 KiB, else one
// level of leaves of `leaf_size` entries, growing the leaf size until the root of leaf pointers
// fits. Leaves stay within the Reader's default limits (1 << 22 entries).
Result<Directories> build_directories(std::span<const Entry> entries, Compression c) {
  constexpr std::size_t kMaxEntriesPerDirectory = std::size_t{1} << 22;
  Directories d;
  if (entries.size() <= kMaxEntriesPerDirectory) {
    Result<std::vector<std::uint8_t>> root = compress(serialize_directory(entries), c);
    if (!root) return std::move(root).error();
    if (root->size() <= kRootDirectoryLimit) {
      d.root = std::move(*root);
      return d;
    }
  }
  for (std::size_t leaf_size = 4096;;
       leaf_size = std::min(leaf_size + leaf_size / 2, kMaxEntriesPerDirectory)) {
    d.leaves.clear();
    std::vector<Entry> pointers;
    for (std::size_t i = 0; i < entries.size(); i += leaf_size) {
      const std::span<const Entry> chunk =
          entries.subspan(i, std::min(leaf_size, entries.size() - i));
      Result<std::vector<std::uint8_t>> leaf = compress(serialize_directory(chunk), c);
      if (!leaf) return std::move(leaf).error();
      if (leaf->size() > std::numeric_limits<std::uint32_t>::max()) {
        return make_error(ErrorCode::too_large, "a leaf directory exceeds 4 GiB");
      }
      pointers.push_back(Entry{chunk.front().tile_id, d.leaves.size(),
                               static_cast<std::uint32_t>(leaf->size()), 0});
      d.leaves.insert(d.leaves.end(), leaf->begin(), leaf->end());
    }
    Result<std::vector<std::uint8_t>> root = compress(serialize_directory(pointers), c);
    if (!root) return std::move(root).error();
    if (root->size() <= kRootDirectoryLimit) {
      d.root = std::move(*root);
      d.leaf_count = pointers.size();
      return d;
    }
    if (leaf_size == kMaxEntriesPerDirectory) {
      return make_error(ErrorCode::too_large,
                        std::to_string(entries.size()) +
                            " directory entries do not fit a root directory of 16 KiB with one "
                            "level of leaf directories");
    }
  }
}

class WriterImpl final : public Writer {
 public:
  WriterImpl(WriterOptions options, Fd spool, std::filesystem::path spool_path)
      : options_(std::move(options)),
        spool_(std::move(spool)),
        spool_path_(std::move(spool_path)) {}
  ~WriterImpl() override { abort(); }

  Status add_tile(TileId id, std::span<const std::uint8_t> payload) override {
    if (id.z > 31 || std::uint64_t{id.x} >= (std::uint64_t{1} << id.z) ||
        std::uint64_t{id.y} >= (std::uint64_t{1} << id.z)) {
      return make_error(ErrorCode::invalid_argument, "tile " + tile_name(id) + " does not exist");
    }
    if (payload.empty()) {
      // PMTiles entries must have a length > 0; an absent tile is expressed by not adding it.
      return make_error(ErrorCode::invalid_argument,
                        "tile " + tile_name(id) + " has an empty payload");
    }
    if (payload.size() > std::numeric_limits<std::uint32_t>::max()) {
      return make_error(ErrorCode::too_large,
                        "tile " + tile_name(id) + " payload exceeds 4 GiB (the PMTiles limit)");
    }
    const std::uint64_t tile_id = zxy_to_tile_id(id.z, id.x, id.y);
    const XXH128_hash_t hash = XXH3_128bits(payload.data(), payload.size());  // outside the lock

    std::lock_guard lock(mutex_);
    if (state_ != State::open) {
      return make_error(ErrorCode::invalid_argument, "add_tile after finish() or abort()");
    }
    const std::uint64_t key = tile_id + 1;  // ids are < 2^63, so + 1 never wraps to the empty 0
    if (tile_ids_.find(mix(key), [&](std::uint64_t v) { return v == key; }) != 0) {
      return make_error(ErrorCode::invalid_argument, "tile " + tile_name(id) + " added twice");
    }

    std::uint64_t blob = 0;
    Status compare_status;
    const std::uint64_t found = blob_index_.find(hash.low64, [&](std::uint64_t v) {
      const Blob& b = blobs_[v - 1];
      if (b.hash_high != hash.high64 || b.hash_low != hash.low64 || b.length != payload.size()) {
        return false;
      }
      // Equal 128-bit hashes: confirm with the bytes, so a collision can never swap tiles.
      Result<bool> same = same_bytes(b, payload);
      if (!same) {
        compare_status = std::move(same).error();
        return true;
      }
      return *same;
    });
    if (!compare_status) return compare_status;
    if (found != 0) {
      blob = found - 1;
    } else {
      if (Status s =
              pwrite_all(spool_.get(), payload.data(), payload.size(), spool_size_, spool_path_);
          !s) {
        return s;
      }
      blob = blobs_.size();
      blobs_.push_back(
          Blob{spool_size_, hash.low64, hash.high64, static_cast<std::uint32_t>(payload.size())});
      spool_size_ += payload.size();
      blob_index_.insert(hash.low64, blob + 1,
                         [&](std::uint64_t v) { return blobs_[v - 1].hash_low; });
    }
    records_.push_back(Record{tile_id, blob});
    tile_ids_.insert(mix(key), key, [](std::uint64_t v) { return mix(v); });
    return {};
  }

  Result<WriterStats> finish(const std::string& metadata_json) override {
    std::lock_guard lock(mutex_);
    if (state_ != State::open) {
      return make_error(ErrorCode::invalid_argument, "finish() after finish() or abort()");
    }
    state_ = State::done;
    Result<WriterStats> result = finish_locked(metadata_json);
    if (!result && !tmp_path_.empty()) {
      std::error_code ignored;
      std::filesystem::remove(tmp_path_, ignored);
    }
    tmp_path_.clear();
    spool_.reset();  // already unlinked: closing frees its space
    release_index();
    return result;
  }

  void abort() noexcept override {
    std::lock_guard lock(mutex_);
    if (state_ != State::open) return;
    state_ = State::done;
    spool_.reset();
    release_index();
  }

 private:
  struct Blob {
    std::uint64_t spool_offset;
    std::uint64_t hash_low, hash_high;
    std::uint32_t length;
  };
  struct Record {
    std::uint64_t tile_id;
    std::uint64_t blob;
  };
  enum class State { open, done };

  Result<bool> same_bytes(const Blob& b, std::span<const std::uint8_t> payload) {
    constexpr std::size_t kChunk = 1u << 16;
    scratch_.resize(std::min<std::size_t>(kChunk, payload.size()));
    for (std::size_t done = 0; done < payload.size();) {
      const std::size_t n = std::min(kChunk, payload.size() - done);
      if (Status s =
              pread_all(spool_.get(), scratch_.data(), n, b.spool_offset + done, spool_path_);
          !s) {
        return s.error();
      }
      if (std::memcmp(scratch_.data(), payload.data() + done, n) != 0) return false;
      done += n;
    }
    return true;
  }

  void release_index() {
    records_ = {};
    blobs_ = {};
    tile_ids_.release();
    blob_index_.release();
    scratch_ = {};
  }

  Result<WriterStats> finish_locked(const std::string& metadata_json) {
    if (records_.empty()) {
      // The spec requires a non-empty root directory, so an archive needs at least one tile.
      return make_error(ErrorCode::invalid_argument,
                        "no tiles were added to " + options_.path.string());
    }
    std::sort(records_.begin(), records_.end(),
              [](const Record& a, const Record& b) { return a.tile_id < b.tile_id; });

    // Data offsets in order of first appearance along the Hilbert curve: that is "clustered".
    constexpr std::uint64_t kUnset = std::numeric_limits<std::uint64_t>::max();
    std::vector<std::uint64_t> data_offset(blobs_.size(), kUnset);
    std::vector<std::uint64_t> order;
    order.reserve(blobs_.size());
    std::uint64_t data_size = 0;
    std::vector<Entry> entries;
    for (const Record& r : records_) {
      const Blob& b = blobs_[r.blob];
      if (data_offset[r.blob] == kUnset) {
        data_offset[r.blob] = data_size;
        data_size += b.length;
        order.push_back(r.blob);
      }
      const std::uint64_t offset = data_offset[r.blob];
      if (!entries.empty()) {
        Entry& last = entries.back();
        assert(last.tile_id + last.run_length <= r.tile_id);
        if (last.tile_id + last.run_length == r.tile_id && last.offset == offset &&
            last.run_length < std::numeric_limits<std::uint32_t>::max()) {
          ++last.run_length;  // same payload as the tile just before it: extend the run
          continue;
        }
      }
      entries.push_back(Entry{r.tile_id, offset, b.length, 1});
    }
    data_offset = {};

    WriterStats stats;
    stats.addressed_tiles = records_.size();
    stats.tile_contents = order.size();
    stats.tile_entries = entries.size();
    stats.tile_bytes = data_size;
    records_ = {};
    tile_ids_.release();
    blob_index_.release();

    Result<Directories> dirs = build_directories(entries, options_.internal_compression);
    if (!dirs) return std::move(dirs).error();
    entries = {};
    const std::span<const std::uint8_t> meta_raw(
        reinterpret_cast<const std::uint8_t*>(metadata_json.data()), metadata_json.size());
    Result<std::vector<std::uint8_t>> meta = compress(meta_raw, options_.internal_compression);
    if (!meta) return std::move(meta).error();

    Header h = options_.bounds;
    h.root_dir_offset = kHeaderSize;
    h.root_dir_length = dirs->root.size();
    h.metadata_offset = h.root_dir_offset + h.root_dir_length;
    h.metadata_length = meta->size();
    h.leaf_dirs_offset = h.metadata_offset + h.metadata_length;
    h.leaf_dirs_length = dirs->leaves.size();
    h.tile_data_offset = h.leaf_dirs_offset + h.leaf_dirs_length;
    h.tile_data_length = data_size;
    h.addressed_tiles = stats.addressed_tiles;
    h.tile_entries = stats.tile_entries;
    h.tile_contents = stats.tile_contents;
    h.clustered = true;
    h.internal_compression = options_.internal_compression;
    h.tile_compression = options_.tile_compression;
    h.tile_type = options_.tile_type;
    h.min_zoom = options_.min_zoom;
    h.max_zoom = options_.max_zoom;
    stats.file_bytes = h.tile_data_offset + h.tile_data_length;

    const std::filesystem::path dir = parent_dir(options_.path);
    Result<std::pair<Fd, std::filesystem::path>> tmp =
        create_unique(dir, "." + options_.path.filename().string() + ".tmp-", 0666);
    if (!tmp) return std::move(tmp).error();
    Fd out = std::move(tmp->first);
    tmp_path_ = tmp->second;

    BufferedOut w(out.get(), tmp_path_);
    const auto header_bytes = serialize_header(h);
    for (std::span<const std::uint8_t> part :
         {std::span<const std::uint8_t>(header_bytes), std::span<const std::uint8_t>(dirs->root),
          std::span<const std::uint8_t>(*meta), std::span<const std::uint8_t>(dirs->leaves)}) {
      if (Status s = w.write(part); !s) return s.error();
    }
    dirs = Directories{};
    assert(w.position() == h.tile_data_offset);
    for (std::uint64_t blob : order) {
      const Blob& b = blobs_[blob];
      if (Status s = w.copy_from(spool_.get(), spool_path_, b.spool_offset, b.length); !s) {
        return s.error();
      }
    }
    if (Status s = w.flush(); !s) return s.error();
    assert(w.position() == stats.file_bytes);
    if (::fsync(out.get()) != 0) return io_error("cannot fsync", tmp_path_, errno);
    if (const int err = out.close_checked(); err != 0)
      return io_error("cannot close", tmp_path_, err);
    if (::rename(tmp_path_.c_str(), options_.path.c_str()) != 0) {
      return io_error("cannot rename " + tmp_path_.string() + " to", options_.path, errno);
    }
    tmp_path_.clear();  // renamed: nothing temporary is left to remove
    // Make the rename itself durable. The archive is complete either way, so a failure here is
    // still reported: the caller asked for a durable file.
    Fd dfd(::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
    if (dfd.get() < 0 || ::fsync(dfd.get()) != 0)
      return io_error("cannot fsync directory", dir, errno);
    return stats;
  }

 public:
  static std::filesystem::path parent_dir(const std::filesystem::path& p) {
    return p.has_parent_path() ? p.parent_path() : std::filesystem::path(".");
  }

 private:
  WriterOptions options_;
  std::mutex mutex_;
  State state_ = State::open;
  Fd spool_;
  std::filesystem::path spool_path_;  // for messages only: unlinked right after creation
  std::uint64_t spool_size_ = 0;
  std::vector<Blob> blobs_;
  std::vector<Record> records_;
  FlatIndex tile_ids_;    // tile_id + 1 of every added tile
  FlatIndex blob_index_;  // blob number + 1, by low 64 bits of the payload hash
  std::vector<std::uint8_t> scratch_;
  std::filesystem::path tmp_path_;  // the archive being written in finish(), until renamed
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
  Result<std::pair<Fd, std::filesystem::path>> spool =
      create_unique(WriterImpl::parent_dir(options.path),
                    "." + options.path.filename().string() + ".spool-", 0600);
  if (!spool) return std::move(spool).error();
  // Unlinked at once: the descriptor keeps the data, and no crash can leave the spool behind.
  if (::unlink(spool->second.c_str()) != 0) {
    return io_error("cannot unlink", spool->second, errno);
  }
  return std::unique_ptr<Writer>(
      new WriterImpl(std::move(options), std::move(spool->first), std::move(spool->second)));
}

}  // namespace vts::pmtiles
