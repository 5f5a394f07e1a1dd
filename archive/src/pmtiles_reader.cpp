// PMTiles v3 reader over a file read with pread(2) (or over borrowed bytes).
//
// The file is never mapped: another process may truncate or overwrite it in place at any moment
// (cp over it, truncate, rsync --inplace), and touching a mapped page past the new end of a file
// raises SIGBUS, which would take a whole server down. Every read is a copy; after each read of a
// file the reader checks with fstat(2) on its kept descriptor that the file still has the size
// and modification time it had at open, so bytes of an archive that changed under it come back as
// ErrorCode::changed, never as a mix of two archives. Renaming another file into place does not
// touch ours: a reader keeps serving the inode it opened.
//
// Trust model: every byte of the archive is hostile. The header's sections are checked against
// the file size once, at open; every directory entry is checked when it is followed (leaf pointers
// against the leaf section, tile entries against the tile-data section); stored sizes are bounded
// before anything is allocated; directory chains are cut at kMaxDirectoryDepth, which also ends
// cycles; a directory holds at most kMaxDirectoryEntries entries. Decoded leaf directories are
// shared immutable vectors held by a DirectoryCache bounded in bytes, so concurrent lookups never
// see a directory change under them and a few KiB of leaf bombs cannot grow the process.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <xxhash.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <limits>
#include <list>
#include <mutex>
#include <new>
#include <set>
#include <system_error>
#include <unordered_map>
#include <utility>

#include "vts/archive/archive_set.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/base/file_io.hpp"

namespace vts::archive {
namespace {

class BorrowedBytes final : public ByteSource {
 public:
  explicit BorrowedBytes(std::span<const std::uint8_t> bytes) : bytes_(bytes) {}
  std::uint64_t size() const override { return bytes_.size(); }
  Status read(std::uint64_t offset, std::span<std::uint8_t> out) const override {
    if (!out.empty()) std::memcpy(out.data(), bytes_.data() + offset, out.size());
    return {};
  }

 private:
  std::span<const std::uint8_t> bytes_;
};

// A file kept open for the reader's life; closed on destruction.
class FileBytes final : public ByteSource {
 public:
  FileBytes(int fd, const struct stat& st, std::string path)
      : fd_(fd),
        size_(static_cast<std::uint64_t>(st.st_size)),
        mtime_(st.st_mtim),
        path_(std::move(path)) {}
  FileBytes(const FileBytes&) = delete;
  FileBytes& operator=(const FileBytes&) = delete;
  ~FileBytes() override { ::close(fd_); }

  std::uint64_t size() const override { return size_; }

  Status read(std::uint64_t offset, std::span<std::uint8_t> out) const override {
    std::size_t done = 0;
    while (done < out.size()) {
      const ssize_t n =
          ::pread(fd_, out.data() + done, out.size() - done, static_cast<off_t>(offset + done));
      if (n < 0 && errno == EINTR) continue;
      if (n < 0) {
        return make_error(ErrorCode::io,
                          "cannot read " + path_ + ": " + std::generic_category().message(errno));
      }
      if (n == 0) break;  // the file is shorter than when it was opened
      done += static_cast<std::size_t>(n);
    }
    if (Status s = check_unchanged(); !s) return s;
    if (done < out.size()) {  // shrunk and grown back within one clock tick: still a change
      changed_.store(true);
      return changed_error();
    }
    return {};
  }

  Status check_unchanged() const override {
    if (changed_.load()) return changed_error();
    struct stat st {};
    if (::fstat(fd_, &st) != 0) {
      return make_error(ErrorCode::io,
                        "cannot stat " + path_ + ": " + std::generic_category().message(errno));
    }
    if (static_cast<std::uint64_t>(st.st_size) != size_ || st.st_mtim.tv_sec != mtime_.tv_sec ||
        st.st_mtim.tv_nsec != mtime_.tv_nsec) {
      changed_.store(true);
      return changed_error();
    }
    return {};
  }

 private:
  Error changed_error() const {
    return make_error(ErrorCode::changed,
                      path_ +
                          " was modified in place after it was opened (size or modification "
                          "time differ); reopen it");
  }

  const int fd_;
  const std::uint64_t size_;
  const timespec mtime_;
  const std::string path_;
  mutable std::atomic<bool> changed_{false};  // sticky: a file once changed stays changed
};

// Keeps the code of an error and puts context in front of its message.
Error with_context(const std::string& context, Error e) {
  e.message = context + ": " + e.message;
  return e;
}

// True when [offset, offset + length) lies within [0, size); no overflow for any inputs.
bool within(std::uint64_t offset, std::uint64_t length, std::uint64_t size) {
  return offset <= size && length <= size - offset;
}

struct LeafKey {
  std::uint64_t offset;
  std::uint32_t length;
  bool operator==(const LeafKey&) const = default;
  auto operator<=>(const LeafKey&) const = default;
};

class ReaderImpl final : public Reader {
 public:
  ReaderImpl(std::unique_ptr<ByteSource> source, ReaderOptions options)
      : source_(std::move(source)),
        options_(options),
        cache_(options.leaf_cache_bytes, options.leaf_cache_entries) {}

  // Validates the header against the archive size, reads and decodes the root directory and
  // metadata, and works out the version.
  Status init() {
    const std::uint64_t size = source_->size();
    std::vector<std::uint8_t> head(std::min<std::uint64_t>(size, kHeaderSize));
    if (Status s = source_->read(0, head); !s) return s;
    Result<Header> h = parse_header(head);
    if (!h) return std::move(h).error();
    header_ = *h;
    struct Section {
      const char* name;
      std::uint64_t offset, length;
    };
    for (const Section& s :
         {Section{"root directory", header_.root_dir_offset, header_.root_dir_length},
          Section{"metadata", header_.metadata_offset, header_.metadata_length},
          Section{"leaf directories", header_.leaf_dirs_offset, header_.leaf_dirs_length},
          Section{"tile data", header_.tile_data_offset, header_.tile_data_length}}) {
      if (!within(s.offset, s.length, size)) {
        return make_error(ErrorCode::truncated, std::string(s.name) + " section (offset " +
                                                    std::to_string(s.offset) + ", length " +
                                                    std::to_string(s.length) +
                                                    ") extends past the end of the archive (" +
                                                    std::to_string(size) + " bytes)");
      }
      if (s.length > 0 && s.offset < kHeaderSize) {
        return make_error(ErrorCode::corrupt, std::string(s.name) + " section (offset " +
                                                  std::to_string(s.offset) +
                                                  ") overlaps the 127-byte header");
      }
    }
    if (header_.root_dir_length == 0) {
      return make_error(ErrorCode::corrupt, "root directory has length 0");
    }
    Result<std::vector<std::uint8_t>> root_bytes =
        read_section("root directory", header_.root_dir_offset, header_.root_dir_length,
                     options_.max_directory_bytes);
    if (!root_bytes) return std::move(root_bytes).error();
    Result<Directory> root = decode_directory(*root_bytes);
    if (!root) return with_context("root directory", std::move(root).error());
    root_ = std::move(*root);

    Result<std::vector<std::uint8_t>> meta_bytes = read_section(
        "metadata", header_.metadata_offset, header_.metadata_length, options_.max_metadata_bytes);
    if (!meta_bytes) return std::move(meta_bytes).error();
    if (header_.metadata_length > 0) {
      Result<std::vector<std::uint8_t>> meta =
          decompress(*meta_bytes, header_.internal_compression, options_.max_metadata_bytes);
      if (!meta) return with_context("metadata", std::move(meta).error());
      metadata_.assign(meta->begin(), meta->end());
    }

    version_ = archive_version(head, *root_bytes, *meta_bytes);
    return {};
  }

  const Header& header() const override { return header_; }
  const std::string& metadata_json() const override { return metadata_; }
  const std::string& version() const override { return version_; }
  std::uint64_t size() const override { return source_->size(); }

  Status read(std::uint64_t offset, std::span<std::uint8_t> out) const override {
    if (!within(offset, out.size(), source_->size())) {
      return make_error(ErrorCode::invalid_argument,
                        "bytes " + std::to_string(offset) + "+" + std::to_string(out.size()) +
                            " lie beyond the archive's " + std::to_string(source_->size()));
    }
    return source_->read(offset, out);
  }

  Status check_unchanged() const override { return source_->check_unchanged(); }

  Result<std::vector<std::uint8_t>> get(TileId id) const override {
    if (id.z > 31 || std::uint64_t{id.x} >= (std::uint64_t{1} << id.z) ||
        std::uint64_t{id.y} >= (std::uint64_t{1} << id.z)) {
      return make_error(ErrorCode::invalid_argument, "tile " + name(id) + " does not exist");
    }
    Result<std::vector<std::uint8_t>> r = get_by_tile_id(zxy_to_tile_id(id.z, id.x, id.y));
    if (!r && r.error().code == ErrorCode::not_found) {
      return make_error(ErrorCode::not_found, "tile " + name(id) + " is not in the archive");
    }
    return r;
  }

  Result<std::vector<std::uint8_t>> get_by_tile_id(std::uint64_t tile_id) const override {
    Result<Entry> e = find_entry(tile_id);
    if (!e) return std::move(e).error();
    if (e->length > options_.max_tile_bytes) {
      return make_error(ErrorCode::too_large,
                        "tile id " + std::to_string(tile_id) + " is " + std::to_string(e->length) +
                            " bytes, over the limit of " + std::to_string(options_.max_tile_bytes));
    }
    std::vector<std::uint8_t> payload(e->length);
    if (Status s = source_->read(header_.tile_data_offset + e->offset, payload); !s) {
      return s.error();
    }
    return payload;
  }

  Status for_each_entry(const std::function<bool(const Entry&)>& visitor) const override {
    Walk walk;
    walk.visitor = &visitor;
    return walk_directory(*root_, 0, walk);
  }

  Result<std::uint64_t> leaf_directory_count() const override {
    Walk walk;
    if (Status s = walk_directory(*root_, 0, walk); !s) return s.error();
    return walk.leaf_count;
  }

 private:
  struct Walk {
    const std::function<bool(const Entry&)>* visitor = nullptr;  // null: count leaves only
    std::uint64_t next_tile_id = 0;  // entries must not start below the end of the previous run
    std::uint64_t leaf_count = 0;
    std::set<LeafKey> seen;  // a leaf referenced twice means a cycle or a hostile fan-out
    bool stopped = false;
  };

  static std::string name(TileId id) {
    return std::to_string(id.z) + "/" + std::to_string(id.x) + "/" + std::to_string(id.y);
  }

  Result<Entry> find_entry(std::uint64_t tile_id) const override {
    // The root is borrowed; only leaves (which the cache may evict) are held by shared_ptr.
    const std::vector<Entry>* dir = root_.get();
    Directory leaf_holder;
    for (int level = 0; level < kMaxDirectoryDepth; ++level) {
      // The last entry with tile_id <= the wanted id is the only one that can hold it.
      const auto it =
          std::upper_bound(dir->begin(), dir->end(), tile_id,
                           [](std::uint64_t id, const Entry& e) { return id < e.tile_id; });
      if (it == dir->begin()) break;
      const Entry e = *(it - 1);
      if (e.run_length > 0) {
        if (tile_id - e.tile_id >= e.run_length) break;
        if (Status s = check_tile_entry(e); !s) return s.error();
        return e;
      }
      if (level + 1 == kMaxDirectoryDepth) {
        return make_error(ErrorCode::corrupt, "directory cycle or too deep: tile id " +
                                                  std::to_string(tile_id) +
                                                  " still leads to a leaf directory after " +
                                                  std::to_string(kMaxDirectoryDepth) + " levels");
      }
      Result<Directory> leaf = load_leaf(e);
      if (!leaf) return std::move(leaf).error();
      leaf_holder = std::move(*leaf);
      dir = leaf_holder.get();
    }
    return make_error(ErrorCode::not_found,
                      "tile id " + std::to_string(tile_id) + " is not in the archive");
  }

  Status check_tile_entry(const Entry& e) const {
    if (!within(e.offset, e.length, header_.tile_data_length)) {
      return make_error(ErrorCode::corrupt, "tile entry for tile id " + std::to_string(e.tile_id) +
                                                " (offset " + std::to_string(e.offset) +
                                                ", length " + std::to_string(e.length) +
                                                ") extends past the tile data section (size " +
                                                std::to_string(header_.tile_data_length) + ")");
    }
    return {};
  }

  // Reads a section (or a leaf) the caller has bounds-checked, refusing stored sizes over `limit`
  // before allocating.
  Result<std::vector<std::uint8_t>> read_section(const std::string& what, std::uint64_t offset,
                                                 std::uint64_t length, std::size_t limit) const {
    if (length > limit) {
      return make_error(ErrorCode::too_large, what + " of " + std::to_string(length) +
                                                  " bytes is over the limit of " +
                                                  std::to_string(limit));
    }
    std::vector<std::uint8_t> bytes(length);
    if (Status s = source_->read(offset, bytes); !s) return s.error();
    return bytes;
  }

  // Decompresses and parses a directory as stored.
  Result<Directory> decode_directory(std::span<const std::uint8_t> stored) const {
    return archive::decode_directory(stored, header_.internal_compression,
                                     options_.max_directory_bytes);
  }

  // Bounds-checks a leaf pointer against the leaf section, reads and decodes the leaf.
  Result<Directory> decode_leaf(const Entry& pointer) const {
    const std::string where = "leaf directory at offset " + std::to_string(pointer.offset) +
                              " length " + std::to_string(pointer.length);
    if (!within(pointer.offset, pointer.length, header_.leaf_dirs_length)) {
      return make_error(ErrorCode::corrupt, where + " extends past the leaf section (size " +
                                                std::to_string(header_.leaf_dirs_length) + ")");
    }
    Result<std::vector<std::uint8_t>> stored =
        read_section(where, header_.leaf_dirs_offset + pointer.offset, pointer.length,
                     options_.max_directory_bytes);
    if (!stored) return std::move(stored).error();
    Result<Directory> d = decode_directory(*stored);
    if (!d) return with_context(where, std::move(d).error());
    return d;
  }

  // decode_leaf() through the cache. Decoding happens outside the cache's lock, so one slow
  // leaf does not stall lookups in cached ones; two threads missing the same leaf both decode it
  // and the first to finish wins.
  Result<Directory> load_leaf(const Entry& pointer) const {
    if (Directory d = cache_.find(pointer.offset, pointer.length)) return d;
    Result<Directory> leaf = decode_leaf(pointer);
    if (!leaf) return leaf;
    return cache_.insert(pointer.offset, pointer.length, std::move(*leaf));
  }

  // Depth-first, in directory order, without the cache (a full walk would only flush it).
  Status walk_directory(const std::vector<Entry>& dir, int level, Walk& walk) const {
    for (const Entry& e : dir) {
      if (e.run_length > 0) {
        if (e.tile_id < walk.next_tile_id) {
          return make_error(ErrorCode::corrupt,
                            "tile id " + std::to_string(e.tile_id) +
                                " is out of order across directories (expected >= " +
                                std::to_string(walk.next_tile_id) + ")");
        }
        walk.next_tile_id = e.tile_id > std::numeric_limits<std::uint64_t>::max() - e.run_length
                                ? std::numeric_limits<std::uint64_t>::max()
                                : e.tile_id + e.run_length;
        if (walk.visitor == nullptr) continue;
        if (Status s = check_tile_entry(e); !s) return s;
        if (!(*walk.visitor)(e)) {
          walk.stopped = true;
          return {};
        }
        continue;
      }
      if (level + 1 >= kMaxDirectoryDepth) {
        return make_error(ErrorCode::corrupt,
                          "directory cycle or too deep: leaf directory at offset " +
                              std::to_string(e.offset) + " is nested deeper than " +
                              std::to_string(kMaxDirectoryDepth) + " levels");
      }
      if (!walk.seen.insert(LeafKey{e.offset, e.length}).second) {
        return make_error(ErrorCode::corrupt,
                          "leaf directory at offset " + std::to_string(e.offset) + " length " +
                              std::to_string(e.length) +
                              " is referenced more than once (a cycle or a shared leaf)");
      }
      ++walk.leaf_count;
      Result<Directory> leaf = decode_leaf(e);
      if (!leaf) return std::move(leaf).error();
      if (Status s = walk_directory(**leaf, level + 1, walk); !s) return s;
      if (walk.stopped) return {};
    }
    return {};
  }

  std::unique_ptr<ByteSource> source_;
  ReaderOptions options_;
  Header header_;
  std::string metadata_;
  std::string version_;
  Directory root_;
  mutable DirectoryCache cache_;  // decoded leaves
};

Result<std::shared_ptr<Reader>> make_reader(std::unique_ptr<ByteSource> source,
                                            ReaderOptions options) {
  auto reader = std::make_shared<ReaderImpl>(std::move(source), options);
  if (Status s = reader->init(); !s) return s.error();
  return std::shared_ptr<Reader>(std::move(reader));
}

}  // namespace

// ---- DirectoryCache
// ------------------------------------------------------------------------------

std::size_t DirectoryCache::KeyHash::operator()(const Key& k) const noexcept {
  return std::hash<std::uint64_t>{}(k.offset * 0x9E3779B97F4A7C15ULL ^ k.length);
}

std::size_t DirectoryCache::cost(const std::vector<Entry>& d) {
  // The vector's storage, plus its control block, the list node and the index slot.
  return d.capacity() * sizeof(Entry) + 160;
}

Directory DirectoryCache::find(std::uint64_t offset, std::uint64_t length) {
  std::lock_guard lock(mutex_);
  auto it = index_.find(Key{offset, length});
  if (it == index_.end()) return nullptr;
  lru_.splice(lru_.begin(), lru_, it->second);
  return it->second->directory;
}

Directory DirectoryCache::insert(std::uint64_t offset, std::uint64_t length, Directory d) {
  if (d == nullptr) return d;
  const Key key{offset, length};
  const std::size_t c = cost(*d);
  std::lock_guard lock(mutex_);
  if (auto it = index_.find(key); it != index_.end()) {
    lru_.splice(lru_.begin(), lru_, it->second);
    return it->second->directory;
  }
  if (c > max_bytes_ || max_directories_ == 0) return d;
  while (!lru_.empty() && (bytes_ + c > max_bytes_ || lru_.size() >= max_directories_)) {
    bytes_ -= lru_.back().cost;
    index_.erase(lru_.back().key);
    lru_.pop_back();
  }
  lru_.push_front(Held{key, d, c});
  index_.emplace(key, lru_.begin());
  bytes_ += c;
  return d;
}

std::size_t DirectoryCache::bytes() const {
  std::lock_guard lock(mutex_);
  return bytes_;
}

std::size_t DirectoryCache::size() const {
  std::lock_guard lock(mutex_);
  return lru_.size();
}

Result<std::shared_ptr<Reader>> Reader::open(const std::filesystem::path& path,
                                             ReaderOptions options) {
  // A set's manifest, or its folder: the set as one reader (archive_set.hpp).
  if (is_set_path(path)) return open_set_path(path, options);
  // Not a FIFO (open_input_file opens with O_NONBLOCK, so one never blocks), device or folder.
  struct stat st {};
  auto opened = open_input_file(path, &st);
  if (!opened) return std::move(opened).error();
  const int fd = *opened;
  if (st.st_size == 0) {
    ::close(fd);
    return make_error(ErrorCode::truncated, path.string() + " is empty");
  }
  Result<std::shared_ptr<Reader>> r =
      make_reader(std::make_unique<FileBytes>(fd, st, path.string()), options);
  if (!r) return with_context(path.string(), std::move(r).error());
  return r;
}

Result<std::shared_ptr<Reader>> Reader::open_bytes(std::span<const std::uint8_t> bytes,
                                                   ReaderOptions options) {
  return make_reader(std::make_unique<BorrowedBytes>(bytes), options);
}

Result<std::shared_ptr<Reader>> Reader::open_source(std::unique_ptr<ByteSource> source,
                                                    ReaderOptions options) {
  if (source == nullptr) return make_error(ErrorCode::invalid_argument, "no byte source");
  const std::string name = source->name();
  Result<std::shared_ptr<Reader>> r = make_reader(std::move(source), options);
  if (!r && !name.empty()) return with_context(name, std::move(r).error());
  return r;
}

std::string archive_version(std::span<const std::uint8_t> header,
                            std::span<const std::uint8_t> root,
                            std::span<const std::uint8_t> metadata) {
  XXH3_state_t* state = XXH3_createState();
  if (state == nullptr) throw std::bad_alloc();
  XXH3_64bits_reset(state);
  XXH3_64bits_update(state, header.data(), header.size());
  XXH3_64bits_update(state, root.data(), root.size());
  XXH3_64bits_update(state, metadata.data(), metadata.size());
  const XXH64_hash_t hash = XXH3_64bits_digest(state);
  XXH3_freeState(state);
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(hash));
  return hex;
}

}  // namespace vts::archive
