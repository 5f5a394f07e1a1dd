// PMTiles v3 reader over a read-only memory mapping (or borrowed bytes).
//
// Trust model: every byte of the archive is hostile. The header's sections are checked against
// the file size once, at open; every directory entry is checked when it is followed (leaf pointers
// against the leaf section, tile entries against the tile-data section); directory chains are cut
// at kMaxDirectoryDepth, which also ends cycles. Decoded leaf directories are shared immutable
// vectors held by a small LRU, so concurrent lookups never see a directory change under them.
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#include <xxhash.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <limits>
#include <list>
#include <mutex>
#include <new>
#include <set>
#include <system_error>
#include <unordered_map>
#include <utility>

#include "vts/protocol/pmtiles.hpp"

#include <xxhash.h>

#include <cstdio>

namespace vts::pmtiles {
namespace {

using Directory = std::shared_ptr<const std::vector<Entry>>;

// A read-only mapping of a file, and the file itself kept open (servers send from it with
// sendfile); unmapped and closed on destruction.
class Mapping {
 public:
  Mapping() = default;
  Mapping(void* addr, std::size_t size, int fd) : addr_(addr), size_(size), fd_(fd) {}
  Mapping(const Mapping&) = delete;
  Mapping& operator=(const Mapping&) = delete;
  ~Mapping() {
    if (addr_ != nullptr) ::munmap(addr_, size_);
    if (fd_ >= 0) ::close(fd_);
  }
  std::span<const std::uint8_t> bytes() const {
    return {static_cast<const std::uint8_t*>(addr_), size_};
  }
  int fd() const { return fd_; }

 private:
  void* addr_ = nullptr;
  std::size_t size_ = 0;
  int fd_ = -1;
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
struct LeafKeyHash {
  std::size_t operator()(const LeafKey& k) const noexcept {
    return std::hash<std::uint64_t>{}(k.offset * 0x9E3779B97F4A7C15ULL ^ k.length);
  }
};

class ReaderImpl final : public Reader {
 public:
  ReaderImpl(std::span<const std::uint8_t> bytes, std::unique_ptr<Mapping> mapping,
             ReaderOptions options)
      : bytes_(bytes), mapping_(std::move(mapping)), options_(options) {}

  // Validates the header against the archive size and decodes the root directory and metadata.
  Status init() {
    Result<Header> h = parse_header(bytes_);
    if (!h) return std::move(h).error();
    header_ = *h;
    const std::uint64_t size = bytes_.size();
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
    Result<Directory> root = decode_directory(header_.root_dir_offset, header_.root_dir_length);
    if (!root) return with_context("root directory", std::move(root).error());
    root_ = std::move(*root);

    if (header_.metadata_length > 0) {
      Result<std::vector<std::uint8_t>> meta =
          decompress(bytes_.subspan(header_.metadata_offset, header_.metadata_length),
                     header_.internal_compression, options_.max_metadata_bytes);
      if (!meta) return with_context("metadata", std::move(meta).error());
      metadata_.assign(meta->begin(), meta->end());
    }
    return {};
  }

  const Header& header() const override { return header_; }
  const std::string& metadata_json() const override { return metadata_; }
  std::span<const std::uint8_t> bytes() const override { return bytes_; }
  int file_descriptor() const override { return mapping_ ? mapping_->fd() : -1; }

  Result<std::span<const std::uint8_t>> get(TileId id) const override {
    if (id.z > 31 || std::uint64_t{id.x} >= (std::uint64_t{1} << id.z) ||
        std::uint64_t{id.y} >= (std::uint64_t{1} << id.z)) {
      return make_error(ErrorCode::invalid_argument, "tile " + name(id) + " does not exist");
    }
    Result<std::span<const std::uint8_t>> r = get_by_tile_id(zxy_to_tile_id(id.z, id.x, id.y));
    if (!r && r.error().code == ErrorCode::not_found) {
      return make_error(ErrorCode::not_found, "tile " + name(id) + " is not in the archive");
    }
    return r;
  }

  Result<std::span<const std::uint8_t>> get_by_tile_id(std::uint64_t tile_id) const override {
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
        return bytes_.subspan(header_.tile_data_offset + e.offset, e.length);
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

  // Decompresses and parses the directory at [offset, offset + length) of the archive, which the
  // caller has bounds-checked.
  Result<Directory> decode_directory(std::uint64_t offset, std::uint64_t length) const {
    Result<std::vector<std::uint8_t>> raw = decompress(
        bytes_.subspan(offset, length), header_.internal_compression, options_.max_directory_bytes);
    if (!raw) return std::move(raw).error();
    Result<std::vector<Entry>> entries = parse_directory(*raw);
    if (!entries) return std::move(entries).error();
    return std::make_shared<const std::vector<Entry>>(std::move(*entries));
  }

  // Bounds-checks a leaf pointer against the leaf section and decodes the leaf it points to.
  Result<Directory> decode_leaf(const Entry& pointer) const {
    const std::string where = "leaf directory at offset " + std::to_string(pointer.offset) +
                              " length " + std::to_string(pointer.length);
    if (!within(pointer.offset, pointer.length, header_.leaf_dirs_length)) {
      return make_error(ErrorCode::corrupt, where + " extends past the leaf section (size " +
                                                std::to_string(header_.leaf_dirs_length) + ")");
    }
    Result<Directory> d =
        decode_directory(header_.leaf_dirs_offset + pointer.offset, pointer.length);
    if (!d) return with_context(where, std::move(d).error());
    return d;
  }

  // decode_leaf() through the LRU cache. Decoding happens outside the lock, so one slow leaf
  // does not stall lookups in cached ones; two threads missing the same leaf both decode it and
  // the first to finish wins.
  Result<Directory> load_leaf(const Entry& pointer) const {
    const LeafKey key{pointer.offset, pointer.length};
    if (options_.leaf_cache_entries == 0) return decode_leaf(pointer);
    {
      std::lock_guard lock(cache_mutex_);
      if (auto it = cache_index_.find(key); it != cache_index_.end()) {
        lru_.splice(lru_.begin(), lru_, it->second);
        return it->second->second;
      }
    }
    Result<Directory> leaf = decode_leaf(pointer);
    if (!leaf) return leaf;
    std::lock_guard lock(cache_mutex_);
    if (auto it = cache_index_.find(key); it != cache_index_.end()) {
      lru_.splice(lru_.begin(), lru_, it->second);
      return it->second->second;
    }
    lru_.emplace_front(key, *leaf);
    cache_index_.emplace(key, lru_.begin());
    if (lru_.size() > options_.leaf_cache_entries) {
      cache_index_.erase(lru_.back().first);
      lru_.pop_back();
    }
    return leaf;
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

  std::span<const std::uint8_t> bytes_;
  std::unique_ptr<Mapping> mapping_;  // null when the bytes are borrowed
  ReaderOptions options_;
  Header header_;
  std::string metadata_;
  Directory root_;

  mutable std::mutex cache_mutex_;
  mutable std::list<std::pair<LeafKey, Directory>> lru_;  // most recently used first
  mutable std::unordered_map<LeafKey, std::list<std::pair<LeafKey, Directory>>::iterator,
                             LeafKeyHash>
      cache_index_;
};

Result<std::shared_ptr<Reader>> make_reader(std::span<const std::uint8_t> bytes,
                                            std::unique_ptr<Mapping> mapping,
                                            ReaderOptions options) {
  auto reader = std::make_shared<ReaderImpl>(bytes, std::move(mapping), options);
  if (Status s = reader->init(); !s) return s.error();
  return std::shared_ptr<Reader>(std::move(reader));
}

}  // namespace

Result<std::shared_ptr<Reader>> Reader::open(const std::filesystem::path& path,
                                             ReaderOptions options) {
  const auto sys_error = [&](const char* what, int err) {
    return make_error(
        err == ENOENT ? ErrorCode::not_found : ErrorCode::io,
        std::string(what) + " " + path.string() + ": " + std::generic_category().message(err));
  };
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return sys_error("cannot open", errno);
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const int err = errno;
    ::close(fd);
    return sys_error("cannot stat", err);
  }
  if (!S_ISREG(st.st_mode)) {
    ::close(fd);
    return make_error(ErrorCode::io, path.string() + " is not a regular file");
  }
  if (st.st_size == 0) {
    ::close(fd);
    return make_error(ErrorCode::truncated, path.string() + " is empty");
  }
  const std::size_t size = static_cast<std::size_t>(st.st_size);
  // MAP_PRIVATE + PROT_READ: we never write, and nobody else's writes through the mapping could
  // reach us. (Truncating the file under a live reader is outside the contract: SIGBUS.)
  void* addr = ::mmap(nullptr, size, PROT_READ, MAP_PRIVATE, fd, 0);
  const int map_err = errno;
  if (addr == MAP_FAILED) {
    ::close(fd);
    return sys_error("cannot map", map_err);
  }
  auto mapping = std::make_unique<Mapping>(addr, size, fd);
  const std::span<const std::uint8_t> bytes = mapping->bytes();
  Result<std::shared_ptr<Reader>> r = make_reader(bytes, std::move(mapping), options);
  if (!r) return with_context(path.string(), std::move(r).error());
  return r;
}

Result<std::shared_ptr<Reader>> Reader::open_bytes(std::span<const std::uint8_t> bytes,
                                                   ReaderOptions options) {
  return make_reader(bytes, nullptr, options);
}

std::string archive_version(const Reader& reader) {
  const auto bytes = reader.bytes();
  const Header& h = reader.header();
  // The reader has checked that these sections lie inside the archive.
  XXH3_state_t* state = XXH3_createState();
  if (state == nullptr) throw std::bad_alloc();
  XXH3_64bits_reset(state);
  XXH3_64bits_update(state, bytes.data(), kHeaderSize);
  XXH3_64bits_update(state, bytes.data() + h.root_dir_offset, h.root_dir_length);
  XXH3_64bits_update(state, bytes.data() + h.metadata_offset, h.metadata_length);
  const XXH64_hash_t hash = XXH3_64bits_digest(state);
  XXH3_freeState(state);
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(hash));
  return hex;
}

}  // namespace vts::pmtiles
