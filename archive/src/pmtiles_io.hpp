// Internals shared by the PMTiles writer and the merge of parts (pmtiles_writer.cpp,
// pmtiles_part.cpp): file helpers, the layout rule and the streaming directory builder of
// pmtiles_part.hpp, and the final assembly of an archive file.
#pragma once

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cassert>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <random>
#include <span>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "vts/archive/pmtiles.hpp"
#include "vts/archive/pmtiles_part.hpp"

namespace vts::archive::detail {

// ---- little-endian fields
// ------------------------------------------------------------------------

inline void put_u64(std::uint8_t* p, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
inline void put_u32(std::uint8_t* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
inline std::uint64_t get_u64(const std::uint8_t* p) {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}
inline std::uint32_t get_u32(const std::uint8_t* p) {
  std::uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}

inline std::string tile_name(TileId id) {
  return std::to_string(id.z) + "/" + std::to_string(id.x) + "/" + std::to_string(id.y);
}

inline Error io_error(const std::string& what, const std::filesystem::path& path, int err) {
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
inline Result<std::pair<Fd, std::filesystem::path>> create_unique(const std::filesystem::path& dir,
                                                                  const std::string& stem,
                                                                  mode_t mode) {
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

inline Status pwrite_all(int fd, const std::uint8_t* data, std::size_t size, std::uint64_t offset,
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

inline Status pread_all(int fd, std::uint8_t* data, std::size_t size, std::uint64_t offset,
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
  // Copies `size` bytes at `offset` of file `src` into the output in the kernel
  // (copy_file_range: no trip through user space, and shared extents on file systems with reflink
  // such as XFS and Btrfs), falling back to copy_from() where the kernel cannot.
  Status clone_from(int src, const std::filesystem::path& src_path, std::uint64_t offset,
                    std::uint64_t size) {
    if (Status s = flush(); !s) return s;
    auto in = static_cast<loff_t>(offset);
    auto out = static_cast<loff_t>(flushed_);
    while (size > 0) {
      const ssize_t n = ::copy_file_range(src, &in, fd_, &out, size, 0);
      if (n < 0 && errno == EINTR) continue;
      if (n < 0 && (errno == EXDEV || errno == EINVAL || errno == ENOSYS || errno == EOPNOTSUPP)) {
        flushed_ = static_cast<std::uint64_t>(out);
        return copy_from(src, src_path, static_cast<std::uint64_t>(in), size);
      }
      if (n < 0) return io_error("cannot copy from", src_path, errno);
      if (n == 0) return make_error(ErrorCode::io, "unexpected end of " + src_path.string());
      size -= static_cast<std::uint64_t>(n);
    }
    flushed_ = static_cast<std::uint64_t>(out);
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
inline std::uint64_t mix(std::uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ULL;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

// Payloads spooled to an unlinked file beside the destination as they arrive (any order, any
// thread), each distinct payload once (equal XXH3-128 and equal bytes). Memory: per tile 16 bytes
// plus a slot of the duplicate-id set, per distinct payload 32 bytes plus a hash slot.
class TileSpool {
 public:
  struct Blob {
    std::uint64_t spool_offset;
    std::uint64_t hash_low, hash_high;
    std::uint32_t length;
  };
  struct Record {
    std::uint64_t tile_id;
    std::uint64_t blob;
  };
  static Result<std::unique_ptr<TileSpool>> create(const std::filesystem::path& destination);
  // Thread-safe. Errors: a tile that does not exist, an empty payload, a payload over 4 GiB, the
  // same tile twice (invalid_argument / too_large), a spool write failure, add after close().
  Status add(TileId id, std::span<const std::uint8_t> payload);
  // Ends adding (false if it already had) and sorts the records by tile id.
  bool close();
  // Frees everything, the spool file included.
  void release() noexcept;
  const std::vector<Record>& records() const { return records_; }
  const Blob& blob(std::uint64_t i) const { return blobs_[i]; }
  int fd() const { return fd_.get(); }
  const std::filesystem::path& path() const { return path_; }

 private:
  TileSpool(Fd fd, std::filesystem::path path) : fd_(std::move(fd)), path_(std::move(path)) {}
  Result<bool> same_bytes(const Blob& b, std::span<const std::uint8_t> payload);

  std::mutex mutex_;
  bool closed_ = false;
  Fd fd_;
  std::filesystem::path path_;  // for messages only: unlinked right after creation
  std::uint64_t size_ = 0;
  std::vector<Blob> blobs_;
  std::vector<Record> records_;
  FlatIndex tile_ids_;    // tile_id + 1 of every added tile
  FlatIndex blob_index_;  // blob number + 1, by low 64 bits of the payload hash
  std::vector<std::uint8_t> scratch_;
};

// ---- The layout rule (pmtiles_part.hpp) ---------------------------------------------------------

// What identifies a payload before its bytes are compared: its XXH3-128 and length.
struct PayloadKey {
  std::uint64_t low = 0, high = 0;
  std::uint32_t length = 0;
  bool operator==(const PayloadKey&) const = default;
};

// Decides, tile by tile in tile-id order, where each payload goes in the data section. `Ref` names
// a payload's bytes for the caller's `same(a, b)` (called only for equal keys), which returns
// Result<bool>: whether they are equal.
template <typename Ref>
class DataLayout {
 public:
  struct Placement {
    std::uint64_t offset = 0;
    bool fresh = false;  // stored here for the first time: the caller copies its bytes
  };

  template <typename Same>
  Result<Placement> place(const PayloadKey& key, const Ref& ref, Same&& same) {
    if (has_previous_ && previous_key_ == key) {
      Result<bool> eq = same(previous_ref_, ref);
      if (!eq) return std::move(eq).error();
      if (*eq) return remember(key, ref, previous_offset_, false);
    }
    const bool small = key.length <= kSmallPayloadBytes;
    if (small) {
      Status failed;
      const std::uint64_t found = index_.find(key.low, [&](std::uint64_t v) {
        const Small& s = smalls_[v - 1];
        if (!(s.key == key)) return false;
        Result<bool> eq = same(s.ref, ref);
        if (!eq) {
          failed = std::move(eq).error();
          return true;
        }
        return *eq;
      });
      if (!failed) return failed.error();
      if (found != 0) return remember(key, ref, smalls_[found - 1].offset, false);
    }
    const std::uint64_t offset = size_;
    size_ += key.length;
    ++contents_;
    if (small && smalls_.size() < kSmallPayloadTable) {
      smalls_.push_back(Small{key, ref, offset});
      index_.insert(key.low, smalls_.size(),
                    [&](std::uint64_t v) { return smalls_[v - 1].key.low; });
    }
    return remember(key, ref, offset, true);
  }
  std::uint64_t data_size() const { return size_; }
  std::uint64_t contents() const { return contents_; }
  void release() {
    smalls_ = {};
    index_.release();
  }

 private:
  struct Small {
    PayloadKey key;
    Ref ref;
    std::uint64_t offset;
  };
  Placement remember(const PayloadKey& key, const Ref& ref, std::uint64_t offset, bool fresh) {
    has_previous_ = true;
    previous_key_ = key;
    previous_ref_ = ref;
    previous_offset_ = offset;
    return Placement{offset, fresh};
  }

  std::vector<Small> smalls_;
  FlatIndex index_;  // smalls_ position + 1, by the low 64 bits of the hash
  bool has_previous_ = false;
  PayloadKey previous_key_;
  Ref previous_ref_{};
  std::uint64_t previous_offset_ = 0;
  std::uint64_t size_ = 0, contents_ = 0;
};

// Lays out directories as entries stream in (pmtiles_part.hpp): leaves go to an unlinked
// temporary file beside the archive as soon as they are full, so memory holds at most
// kLeafEntries entries per directory level.
class DirectoryBuilder {
 public:
  static Result<DirectoryBuilder> create(const std::filesystem::path& archive, Compression c,
                                         std::size_t leaf_entries);
  // Tile entries in tile-id order; consecutive tiles with the same offset extend a run.
  Status add(std::uint64_t tile_id, std::uint64_t offset, std::uint32_t length);
  // Ends the stream: the compressed root directory (leaves_bytes() of leaves are in leaves_fd()).
  Result<std::vector<std::uint8_t>> finish();
  std::uint64_t entries() const { return entries_; }
  std::uint64_t leaves() const { return leaf_count_; }
  std::uint64_t leaves_bytes() const { return leaves_size_; }
  int leaves_fd() const { return file_.get(); }
  const std::filesystem::path& leaves_path() const { return path_; }

 private:
  DirectoryBuilder(Fd file, std::filesystem::path path, Compression c, std::size_t leaf_entries)
      : file_(std::move(file)),
        path_(std::move(path)),
        compression_(c),
        leaf_entries_(leaf_entries) {}
  Status push(std::size_t level, const Entry& e);
  Status flush(std::size_t level);

  Fd file_;
  std::filesystem::path path_;
  Compression compression_;
  std::size_t leaf_entries_;
  std::vector<std::vector<Entry>> levels_;  // [0]: tile entries; [k]: pointers to level k - 1
  std::vector<bool> flushed_;               // level k has written a leaf already
  bool has_entry_ = false;
  Entry pending_;  // the last tile entry, while its run may still grow
  std::uint64_t entries_ = 0, leaf_count_ = 0, leaves_size_ = 0;
};

// Writes `path` through `write`, buffered, by base's write_file_atomically (a temporary beside it,
// fsynced, renamed into place, the folder fsynced: on any failure `path` is untouched). Returns the
// file's size.
Result<std::uint64_t> write_archive_file(const std::filesystem::path& path,
                                         const std::function<Status(BufferedOut&)>& write);

// Writes an archive (write_archive_file): the header (from `options` and `stats`: tiles,
// entries, contents, tile_bytes), the root, the gzip/zstd metadata, the leaves from `dirs`, then
// `write_data`, which must write stats.tile_bytes bytes. Sets stats.file_bytes.
Status write_archive(const WriterOptions& options, const std::string& metadata_json,
                     std::span<const std::uint8_t> root, const DirectoryBuilder& dirs,
                     WriterStats& stats, const std::function<Status(BufferedOut&)>& write_data);

}  // namespace vts::archive::detail
