// The tilesets a server hosts, by name. A tileset is an opened archive plus what the HTTP layer
// needs precomputed (metadata, version). Lookups return a shared_ptr snapshot: a request holds it
// until its response is sent, so a hot reload can swap in a new archive while in-flight requests
// finish on the old archive. Names come from file stems and are looked up in a table — never
// joined into a filesystem path.
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "vts/protocol/pmtiles.hpp"
#include "vts/protocol/result.hpp"
#include "vts/protocol/tileset.hpp"

namespace vts {

struct Tileset {
  std::string name;
  std::filesystem::path path;
  std::shared_ptr<pmtiles::Reader> reader;
  TilesetInfo info;
  // 16 lowercase hex digits identifying the archive's content (XXH3-64 of its header, root
  // directory and metadata bytes). Versioned URLs carry it; a rebuilt archive gets a new one.
  std::string version;
  // Identity of the file that was opened (for change detection on reload).
  std::uint64_t file_size = 0;
  std::int64_t file_mtime_ns = 0;
  std::uint64_t file_inode = 0;
};

// Opens one archive as a tileset named after its file stem; validates metadata.
Result<std::shared_ptr<const Tileset>> open_tileset(const std::filesystem::path& path);

// Thread-safe registry. Readers take snapshots; writers replace entries atomically.
class TilesetRegistry {
 public:
  // Adds every archive named by `paths`: a *.pmtiles file, or a folder whose *.pmtiles files
  // (not recursive) are each a tileset. Fails on the first unreadable archive or duplicate name.
  Status load(const std::vector<std::filesystem::path>& paths);

  // Re-opens every tileset whose file changed (size, mtime or inode) or, with force, all of them.
  // A new archive that fails to open is refused and the old one kept (its error is returned in
  // the list of failures). In loaded folders, archives that appeared are added and archives that
  // disappeared are removed. A refused archive, new or replacing a loaded one, is not tried again
  // until its file changes (or force). Files loaded by name are never removed.
  struct ReloadResult {
    int swapped = 0, added = 0, removed = 0;
    std::vector<Error> failures;
  };
  ReloadResult reload(bool force);

  std::shared_ptr<const Tileset> find(std::string_view name) const;
  std::vector<std::shared_ptr<const Tileset>> all() const;  // sorted by name
  std::size_t size() const;

  // What reload() compares to decide whether a file changed.
  struct FileIdentity {
    std::uint64_t size = 0;
    std::int64_t mtime_ns = 0;
    std::uint64_t inode = 0;
    bool operator==(const FileIdentity&) const = default;
  };

 private:
  using Map = std::map<std::string, std::shared_ptr<const Tileset>, std::less<>>;
  // Under mutex_: makes the current tilesets_ the snapshot find() reads.
  void publish();
  // reload()'s two halves.
  void add_new_archives(const std::set<std::filesystem::path>& in_folders, bool force,
                        ReloadResult& result);
  void refresh_loaded(const std::vector<std::filesystem::path>& folders, bool force,
                      ReloadResult& result);

  mutable std::mutex mutex_;
  Map tilesets_;
  // find()'s lock-free path: an immutable copy of tilesets_ and a counter bumped on each change.
  // (A thread's cached snapshot keeps a removed archive open until its next lookup.)
  std::shared_ptr<const Map> snapshot_;
  std::atomic<std::uint64_t> generation_{0};
  const std::uint64_t id_ = next_id();  // tells registries apart in the per-thread cache
  static std::uint64_t next_id() {
    static std::atomic<std::uint64_t> n{0};
    return ++n;
  }
  std::vector<std::filesystem::path> folders_;             // loaded as folders
  std::map<std::filesystem::path, FileIdentity> refused_;  // new archives refused, as seen
};

}  // namespace vts
