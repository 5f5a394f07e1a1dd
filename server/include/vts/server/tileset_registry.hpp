// The tilesets a server hosts, by name. A tileset is an opened archive plus what the HTTP layer
// needs precomputed (metadata, version). Lookups return a shared_ptr snapshot: a request holds it
// until its response is sent, so a hot reload can swap in a new archive while in-flight requests
// finish on the old archive. Names come from file stems and are looked up in a table — never
// joined into a filesystem path.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "vts/archive/pmtiles.hpp"
#include "vts/base/result.hpp"
#include "vts/protocol/tileset.hpp"
#include "vts/store/options.hpp"

namespace vts {
inline namespace server {

namespace http_detail {
class TileTagMemo;
}

struct Tileset {
  std::string name;
  // The archive file, or a set's manifest (…/NAME/tileset.json; archive/archive_set.hpp).
  std::filesystem::path path;
  bool is_set = false;  // a set of archives read as one: no /{name}.pmtiles to download
  // Read from an object store or web server (s3://, https://): each tile read is a request, made
  // on the answer pipeline's store-read pool, never on an I/O thread.
  bool remote = false;
  std::shared_ptr<archive::Reader> reader;
  TilesetInfo info;
  // 16 lowercase hex digits identifying the archive's content (XXH3-64 of its header, root
  // directory and metadata bytes). Versioned URLs carry it; a rebuilt archive gets a new one.
  std::string version;
  // Identity of the file that was opened (for change detection on reload).
  std::uint64_t file_size = 0;
  std::int64_t file_mtime_ns = 0;
  std::uint64_t file_inode = 0;
  // Tags of tiles already read from this file, so that a conditional request for one of them is
  // answered without reading the file (server/src/tile_tag_memo.hpp). Null: none kept.
  std::shared_ptr<http_detail::TileTagMemo> tags;
  // Which opening of an archive this is: unique in the process and never reused (open_tileset()
  // numbers them), so what a cache keeps under it is never answered for a re-opened archive.
  std::uint64_t generation = 0;
  // Set, for good, once this archive is known to have been modified in place since it was opened:
  // a read found it (ErrorCode::changed), a re-check did, or a reload saw its file change. From
  // then on nothing kept from it (tags, cached tiles) answers a request: the file is read, and
  // answers 503 until the reload replaces the tileset.
  mutable std::atomic<bool> modified{false};
  // When the archive was last verified unchanged (DeadlineClock, ns since its epoch): a read
  // (pread, then fstat) or a re-check. Tiles are answered from the RAM cache only while this is
  // recent (router.cpp: kRecheckInterval), so a change is noticed within that time even when
  // every request is a cache hit.
  mutable std::atomic<std::int64_t> verified_ns{0};
};

// Where a registry reads remote tilesets from, and how much of each archive it keeps.
struct RegistryOptions {
  store::StoreOptions store;  // s3:// and https:// (credentials, endpoint, timeouts)
  // Each archive's cache of decoded leaf directories, in bytes (`directory_cache_mb`): for a
  // remote archive, what makes a warm tile one ranged GET.
  std::size_t directory_cache_bytes = std::size_t{64} << 20;
};

// Opens one archive (a file, or an s3:// or http(s):// object) or one set (its tileset.json, or
// a local set's folder) as a tileset named after the archive's stem or the set's folder;
// validates metadata. Errors name the location ("<path>: <reason>").
Result<std::shared_ptr<const Tileset>> open_tileset(const std::filesystem::path& path,
                                                    const RegistryOptions& options = {});

// An archive file a registry does not serve as it is on disk: it does not open as a valid
// archive, its stem is not a valid tileset name, or its name is taken (a served tileset whose new
// file was refused keeps its previous archive; the reason says so). It is tried again once the
// file changes (or on a forced reload), and forgotten once served or gone from its folder.
struct SkippedArchive {
  std::filesystem::path file;
  Error error;  // its code, and the reason (which does not repeat the file)
};

// Thread-safe registry. Readers take snapshots; writers replace entries atomically.
class TilesetRegistry {
 public:
  explicit TilesetRegistry(RegistryOptions options = {}) : options_(std::move(options)) {}

  // Adds every archive named by `paths`: a *.pmtiles file, or a folder whose *.pmtiles files
  // (not recursive) are each a tileset. A file named in `paths` must open: load fails on the
  // first one that does not (or whose name is taken), changing nothing. An archive found in a
  // folder that does not open, or whose name is taken, is skipped as reload() skips it: it is
  // listed by skipped() and tried again once its file changes. Load fails (not_found) for a
  // folder without *.pmtiles files, and when every archive found was skipped (with the first
  // one's code and a message listing each file and its reason): it has nothing to serve.
  Status load(const std::vector<std::filesystem::path>& paths);

  // Re-opens every tileset whose file changed (size, mtime or inode) or, with force, all of them.
  // A new archive that fails to open is refused and the old one kept (its error is returned in
  // the list of failures). In loaded folders, archives that appeared are added and archives that
  // disappeared are removed. A refused archive, new or replacing a loaded one, is not tried again
  // until its file changes (or force), and listed by skipped() meanwhile. Files loaded by name
  // are never removed.
  //
  // Unless forced, a file modified less than `settle` ago is left for a later reload when it is
  // new in a folder or was modified in place (same inode): a writer copying over a served file may
  // pause with a valid header and directories over stale tile bytes, and nothing on the file
  // changes while it pauses. (A file renamed into place is complete: it is opened at once.)
  // `settling` counts the files so left.
  struct ReloadResult {
    int swapped = 0, added = 0, removed = 0, settling = 0;
    std::vector<Error> failures;
  };
  ReloadResult reload(bool force, std::chrono::nanoseconds settle = {});

  std::shared_ptr<const Tileset> find(std::string_view name) const;
  std::vector<std::shared_ptr<const Tileset>> all() const;  // sorted by name
  std::size_t size() const;
  // The archive files refused as they are now, at load or by a reload, sorted by file.
  std::vector<SkippedArchive> skipped() const;

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
                        std::chrono::nanoseconds settle, ReloadResult& result);
  void refresh_loaded(const std::vector<std::filesystem::path>& folders, bool force,
                      std::chrono::nanoseconds settle, ReloadResult& result);

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
  struct Refusal {
    FileIdentity identity;  // of the file as it was refused
    Error error;
  };
  // Under mutex_: records a refusal / forgets refusals of files that are neither in a folder's
  // listing `in_folders` nor the file of a served tileset.
  void refuse(const std::filesystem::path& file, const FileIdentity& id, Error error);
  void forget_gone_refusals(const std::set<std::filesystem::path>& in_folders);

  const RegistryOptions options_;
  std::vector<std::filesystem::path> folders_;        // loaded as folders
  std::map<std::filesystem::path, Refusal> refused_;  // archive files refused, as seen
};

}  // namespace server
}  // namespace vts
