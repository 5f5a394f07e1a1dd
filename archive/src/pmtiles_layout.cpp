// The directory layout and archive assembly shared by archive::Writer and merge_parts()
// (pmtiles_io.hpp, pmtiles_part.hpp), and the tile-id ranges of a set's archives (pmtiles.hpp).
#include <cassert>

#include "pmtiles_io.hpp"
#include "vts/base/file_io.hpp"

namespace vts::archive::detail {

Result<DirectoryBuilder> DirectoryBuilder::create(const std::filesystem::path& archive,
                                                  Compression c, std::size_t leaf_entries) {
  if (leaf_entries < 2 || leaf_entries > kLeafEntries)
    return make_error(ErrorCode::invalid_argument,
                      "leaf directories hold 2 to " + std::to_string(kLeafEntries) + " entries");
  const std::filesystem::path dir =
      archive.has_parent_path() ? archive.parent_path() : std::filesystem::path(".");
  Result<std::pair<Fd, std::filesystem::path>> tmp =
      create_unique(dir, "." + archive.filename().string() + ".leaves-", 0600);
  if (!tmp) return std::move(tmp).error();
  // Unlinked at once: no crash can leave it behind.
  if (::unlink(tmp->second.c_str()) != 0) return io_error("cannot unlink", tmp->second, errno);
  return DirectoryBuilder(std::move(tmp->first), std::move(tmp->second), c, leaf_entries);
}

Status DirectoryBuilder::add(std::uint64_t tile_id, std::uint64_t offset, std::uint32_t length) {
  if (has_entry_) {
    assert(pending_.tile_id + pending_.run_length <= tile_id);
    if (pending_.tile_id + pending_.run_length == tile_id && pending_.offset == offset &&
        pending_.run_length < std::numeric_limits<std::uint32_t>::max()) {
      ++pending_.run_length;  // same payload as the tile just before it: extend the run
      return {};
    }
    if (Status s = push(0, pending_); !s) return s;
  }
  pending_ = Entry{tile_id, offset, length, 1};
  has_entry_ = true;
  return {};
}

Status DirectoryBuilder::push(std::size_t level, const Entry& e) {
  if (levels_.size() <= level) {
    levels_.resize(level + 1);
    flushed_.resize(level + 1, false);
  }
  if (level == 0) ++entries_;
  if (levels_[level].size() == leaf_entries_) {
    if (Status s = flush(level); !s) return s;
  }
  levels_[level].push_back(e);
  return {};
}

// Writes level `level`'s entries as one leaf and points to it from the level above.
Status DirectoryBuilder::flush(std::size_t level) {
  std::vector<Entry> entries = std::move(levels_[level]);
  levels_[level].clear();
  if (entries.empty()) return {};
  Result<std::vector<std::uint8_t>> leaf = compress(serialize_directory(entries), compression_);
  if (!leaf) return std::move(leaf).error();
  if (Status s = pwrite_all(file_.get(), leaf->data(), leaf->size(), leaves_size_, path_); !s)
    return s;
  const Entry pointer{entries.front().tile_id, leaves_size_,
                      static_cast<std::uint32_t>(leaf->size()), 0};
  leaves_size_ += leaf->size();
  ++leaf_count_;
  flushed_[level] = true;
  return push(level + 1, pointer);
}

Result<std::vector<std::uint8_t>> DirectoryBuilder::finish() {
  if (has_entry_) {
    if (Status s = push(0, pending_); !s) return s.error();
    has_entry_ = false;
  }
  if (levels_.empty())
    return make_error(ErrorCode::invalid_argument, "an archive needs at least one tile");
  for (std::size_t level = 0;; ++level) {
    // A level that never wrote a leaf holds all of its entries: the root, if it fits.
    if (!flushed_[level]) {
      Result<std::vector<std::uint8_t>> root =
          compress(serialize_directory(levels_[level]), compression_);
      if (!root) return std::move(root).error();
      if (root->size() <= kRootDirectoryLimit) return root;
    }
    if (Status s = flush(level); !s) return s.error();
  }
}

Result<std::uint64_t> write_archive_file(const std::filesystem::path& path,
                                         const std::function<Status(BufferedOut&)>& write) {
  std::uint64_t size = 0;
  Status st = vts::write_file_atomically(
      path,
      [&](int fd, const std::filesystem::path& tmp) -> Status {
        BufferedOut w(fd, tmp);
        if (Status s = write(w); !s) return s;
        if (Status s = w.flush(); !s) return s;
        size = w.position();
        return {};
      },
      /*folder_sync_required=*/true);
  if (!st) return st.error();
  return size;
}

Status write_archive(const WriterOptions& options, const std::string& metadata_json,
                     std::span<const std::uint8_t> root, const DirectoryBuilder& dirs,
                     WriterStats& stats, const std::function<Status(BufferedOut&)>& write_data) {
  const std::span<const std::uint8_t> meta_raw(
      reinterpret_cast<const std::uint8_t*>(metadata_json.data()), metadata_json.size());
  Result<std::vector<std::uint8_t>> metadata = compress(meta_raw, options.internal_compression);
  if (!metadata) return std::move(metadata).error();
  Header h = options.bounds;
  h.clustered = true;
  h.internal_compression = options.internal_compression;
  h.tile_compression = options.tile_compression;
  h.tile_type = options.tile_type;
  h.min_zoom = options.min_zoom;
  h.max_zoom = options.max_zoom;
  h.addressed_tiles = stats.addressed_tiles;
  h.tile_entries = stats.tile_entries;
  h.tile_contents = stats.tile_contents;
  h.root_dir_offset = kHeaderSize;
  h.root_dir_length = root.size();
  h.metadata_offset = h.root_dir_offset + h.root_dir_length;
  h.metadata_length = metadata->size();
  h.leaf_dirs_offset = h.metadata_offset + h.metadata_length;
  h.leaf_dirs_length = dirs.leaves_bytes();
  h.tile_data_offset = h.leaf_dirs_offset + h.leaf_dirs_length;
  h.tile_data_length = stats.tile_bytes;
  stats.file_bytes = h.tile_data_offset + h.tile_data_length;
  Result<std::uint64_t> written = write_archive_file(options.path, [&](BufferedOut& w) -> Status {
    const auto header_bytes = serialize_header(h);
    for (std::span<const std::uint8_t> part : {std::span<const std::uint8_t>(header_bytes), root,
                                               std::span<const std::uint8_t>(*metadata)}) {
      if (Status s = w.write(part); !s) return s;
    }
    if (Status s = w.copy_from(dirs.leaves_fd(), dirs.leaves_path(), 0, dirs.leaves_bytes()); !s)
      return s;
    assert(w.position() == h.tile_data_offset);
    if (Status s = write_data(w); !s) return s;
    if (w.position() != stats.file_bytes)
      return make_error(ErrorCode::internal, "archive data section has the wrong size");
    return Status{};
  });
  if (!written) return written.error();
  return {};
}

}  // namespace vts::archive::detail

namespace vts::archive {

std::vector<TileIdRange> subtree_ranges(TileId root, std::uint8_t max_z) {
  assert(root.z <= max_z);
  std::vector<TileIdRange> ranges;
  for (unsigned z = root.z; z <= max_z; ++z)
    ranges.push_back(subtree_tile_ids(root, static_cast<std::uint8_t>(z)));
  return ranges;
}

TileIdRange levels_above(std::uint8_t k) {
  assert(k >= 1);
  // Level k starts where the whole pyramid's range at level k starts.
  return {0, subtree_tile_ids(TileId{0, 0, 0}, k).first - 1};
}

}  // namespace vts::archive
