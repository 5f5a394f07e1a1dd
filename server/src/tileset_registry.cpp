// Tileset registry: opens archives, computes their version, and swaps snapshots on reload.
#include "vts/server/tileset_registry.hpp"

#include "tile_tag_memo.hpp"
#include "vts/archive/archive_set.hpp"
#include "vts/archive/inspect.hpp"
#include "vts/base/file_io.hpp"
#include "vts/store/open.hpp"
#include "vts/store/store.hpp"

#include <xxhash.h>

#include <sys/stat.h>

#include <algorithm>
#include <cstdio>
#include <set>
#include <string_view>
#include <system_error>

namespace vts {
inline namespace server {
namespace {

namespace fs = std::filesystem;

// Tileset names travel in URLs and are looked up in a table: keep them to a conservative,
// unreserved-only alphabet so that no name needs escaping and none can mean a path.
// Names come from file stems; one that breaks the rule is refused with the file to rename.
Status validate_name(std::string_view name) {
  const std::string problem = tileset_name_problem(name);
  if (problem.empty()) return {};
  return make_error(ErrorCode::invalid_argument,
                    "tileset name \"" + std::string(name) + "\" " + problem + " (" +
                        std::string(kTilesetNameRule) + "; rename the file)");
}

using FileIdentity = TilesetRegistry::FileIdentity;

bool is_remote_path(const fs::path& p) {
  return store::is_remote(p.native());
}

// A remote object's identity is its ETag (one HEAD): hashed into `inode`, with no size or time
// (so it is never "recently modified": an object store replaces an object atomically).
Result<FileIdentity> identify_remote(const fs::path& url, const store::StoreOptions& o) {
  Result<std::string> etag = store::object_etag(url.native(), o);
  if (!etag) return std::move(etag).error();
  FileIdentity id;
  id.inode = XXH3_64bits(etag->data(), etag->size());
  return id;
}

Result<FileIdentity> identify(const fs::path& path, const store::StoreOptions& o) {
  if (is_remote_path(path)) return identify_remote(path, o);
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    return make_error(ErrorCode::not_found,
                      std::error_code(errno, std::generic_category()).message());
  }
  FileIdentity id;
  id.size = static_cast<std::uint64_t>(st.st_size);
  id.mtime_ns = static_cast<std::int64_t>(st.st_mtim.tv_sec) * 1'000'000'000 + st.st_mtim.tv_nsec;
  id.inode = static_cast<std::uint64_t>(st.st_ino);
  return id;
}

FileIdentity identity_of(const Tileset& t) {
  return {t.file_size, t.file_mtime_ns, t.file_inode};
}

// True when the file was modified less than `settle` ago (a modification time in the future, as
// from a skewed clock, is not waited for).
bool recently_modified(const FileIdentity& id, std::chrono::nanoseconds settle) {
  if (settle.count() <= 0) return false;
  const std::int64_t now = std::chrono::duration_cast<std::chrono::nanoseconds>(
                               std::chrono::system_clock::now().time_since_epoch())
                               .count();
  const std::int64_t age = now - id.mtime_ns;
  return age >= 0 && age < settle.count();
}

bool is_archive_name(const fs::path& p) {
  return p.extension() == ".pmtiles";
}

bool is_manifest(const fs::path& p) {
  return p.filename() == archive::kSetManifestName;
}

// The folder whose listing names `file`: a set is listed as its folder, and served by its
// manifest (…/planet/tileset.json is listed in …/).
fs::path listed_in(const fs::path& file) {
  return is_manifest(file) ? file.parent_path().parent_path() : file.parent_path();
}

// A tileset's name: an archive's file stem, a set's folder name.
std::string tileset_name_of(const fs::path& file) {
  return is_manifest(file) ? file.parent_path().filename().string() : file.stem().string();
}

// A folder or prefix as compared: canonical for a local one, without a trailing "/" for a URL.
fs::path comparable(const fs::path& folder) {
  if (!is_remote_path(folder)) {
    std::error_code ec;
    return fs::weakly_canonical(folder, ec);
  }
  std::string text = folder.native();
  while (text.ends_with('/')) text.pop_back();
  return text;
}

bool in_folder(const fs::path& file, const std::vector<fs::path>& folders) {
  const auto parent = comparable(listed_in(file));
  for (const auto& f : folders)
    if (comparable(f) == parent) return true;
  return false;
}

// open_tileset() without the file in its error messages (the callers name it).
Result<std::shared_ptr<const Tileset>> open_archive(const fs::path& path,
                                                    const RegistryOptions& ro) {
  const std::string name = tileset_name_of(path);
  if (Status s = validate_name(name); !s) return s.error();

  // Stat before opening: if the file is replaced in between, the recorded identity is the old
  // one, so the next reload sees a change and re-opens (never the reverse, which would pin a
  // stale archive forever).
  auto id = identify(path, ro.store);
  if (!id) return id.error();

  archive::ReaderOptions options;
  options.leaf_cache_entries = 4096;
  options.leaf_cache_bytes = ro.directory_cache_bytes;
  auto reader = store::open_reader(path.native(), ro.store, options);
  if (!reader) {  // the reader names the file first, "<file>: <reason>"
    Error e = reader.error();
    const std::string named = path.string() + ": ";
    if (e.message.starts_with(named)) e.message.erase(0, named.size());
    return e;
  }

  auto info = archive::archive_tileset((*reader)->header(), (*reader)->metadata_json());
  if (!info) return info.error();

  auto t = std::make_shared<Tileset>();
  t->name = name;
  t->path = path;
  t->is_set = is_manifest(path);
  t->remote = is_remote_path(path);
  t->reader = std::move(*reader);
  t->info = std::move(*info);
  t->version = t->reader->version();
  t->tags = std::make_shared<http_detail::TileTagMemo>();
  static std::atomic<std::uint64_t> openings{0};
  t->generation = openings.fetch_add(1, std::memory_order_relaxed) + 1;
  t->file_size = id->size;
  t->file_mtime_ns = id->mtime_ns;
  t->file_inode = id->inode;
  return std::shared_ptr<const Tileset>(std::move(t));
}

// False only when the file is certainly not there (an error to stat it keeps it served).
bool file_present(const fs::path& file) {
  std::error_code ec;
  return fs::exists(file, ec) || ec;
}

Error naming(const fs::path& file, const Error& e) {
  return make_error(e.code, file.string() + ": " + e.message);
}

}  // namespace

Result<std::shared_ptr<const Tileset>> open_tileset(const fs::path& path,
                                                    const RegistryOptions& options) {
  auto t = open_archive(path, options);
  if (!t) return naming(path, t.error());
  return t;
}

namespace {

// The archives directly inside a folder (not recursive), and the sets in its subfolders (their
// manifests, …/NAME/tileset.json), sorted.
// A prefix in an object store: its .pmtiles objects, and the sets in its sub-prefixes (those
// with a tileset.json object).
Result<std::vector<fs::path>> list_remote_archives(const fs::path& prefix,
                                                   const store::StoreOptions& o) {
  auto listing = store::list_folder(prefix.native(), o);
  if (!listing) return std::move(listing).error();
  std::vector<fs::path> found;
  for (const store::ObjectInfo& obj : listing->objects)
    if (obj.key.ends_with(".pmtiles")) found.emplace_back(obj.url);
  for (const std::string& folder : listing->folders) {
    const std::string manifest = folder + std::string(archive::kSetManifestName);
    auto etag = store::object_etag(manifest, o);
    if (etag)
      found.emplace_back(manifest);
    else if (etag.error().code != ErrorCode::not_found)
      return std::move(etag).error();
  }
  std::sort(found.begin(), found.end());
  return found;
}

Result<std::vector<fs::path>> list_archives(const fs::path& folder, const store::StoreOptions& o) {
  if (is_remote_path(folder)) return list_remote_archives(folder, o);
  std::vector<fs::path> found;
  std::error_code ec;
  for (fs::directory_iterator it(folder, ec), end; !ec && it != end; it.increment(ec)) {
    std::error_code type_ec;
    if (is_archive_name(it->path()) && it->is_regular_file(type_ec)) found.push_back(it->path());
    const fs::path manifest = it->path() / archive::kSetManifestName;
    if (it->is_directory(type_ec) && fs::is_regular_file(manifest, type_ec))
      found.push_back(manifest);
  }
  if (ec) return make_error(ErrorCode::io, folder.string() + ": " + ec.message());
  std::sort(found.begin(), found.end());
  return found;
}

}  // namespace

namespace {

// What load() found: files named, and archives listed in folders.
struct LoadPlan {
  std::vector<fs::path> named, listed, folders;
};

// A remote location: an object (archive or manifest) is named; a prefix ("…/") is a folder,
// or a set when it holds a tileset.json.
Status plan_remote(const fs::path& p, const store::StoreOptions& o, LoadPlan& plan) {
  const std::string& text = p.native();
  if (!text.ends_with('/')) {
    plan.named.push_back(p);
    return {};
  }
  const std::string manifest = text + std::string(archive::kSetManifestName);
  if (auto etag = store::object_etag(manifest, o)) {
    plan.named.emplace_back(manifest);
    return {};
  } else if (etag.error().code != ErrorCode::not_found) {
    return etag.error();
  }
  auto found = list_archives(p, o);
  if (!found) return found.error();
  if (found->empty())
    return make_error(ErrorCode::not_found,
                      text + ": prefix holds no *.pmtiles archives and no sets");
  plan.listed.insert(plan.listed.end(), found->begin(), found->end());
  plan.folders.push_back(p);
  return {};
}

Result<LoadPlan> plan_load(const std::vector<fs::path>& paths, const store::StoreOptions& o) {
  LoadPlan plan;
  for (const auto& p : paths) {
    if (is_remote_path(p)) {
      if (Status st = plan_remote(p, o, plan); !st) return st.error();
      continue;
    }
    std::error_code ec;
    const auto st = fs::status(p, ec);
    if (ec || !fs::exists(st)) {
      return make_error(ErrorCode::not_found, p.string() + ": no such file or folder");
    }
    if (!fs::is_directory(st)) {
      plan.named.push_back(p);
      continue;
    }
    if (archive::is_set_path(p)) {  // a set's folder: the set, not its archives one by one
      plan.named.push_back(archive::set_manifest_path(p));
      continue;
    }
    auto found = list_archives(p, o);
    if (!found) return found.error();
    if (found->empty()) {
      return make_error(ErrorCode::not_found,
                        p.string() + ": folder holds no *.pmtiles archives and no sets");
    }
    plan.listed.insert(plan.listed.end(), found->begin(), found->end());
    plan.folders.push_back(p);
  }
  return plan;
}

Error duplicate(const std::string& name, const fs::path& first, const fs::path& second) {
  return make_error(ErrorCode::invalid_argument, "duplicate tileset name \"" + name + "\": " +
                                                     first.string() + " and " + second.string());
}

// Every archive refused: load() has nothing to serve. One line per archive, whatever its file is
// named (the names come from a folder listing, not from the user).
Error nothing_to_serve(const std::vector<SkippedArchive>& skipped) {
  std::string m = "no archive can be served; every one found was refused:";
  for (const auto& s : skipped)
    m += "\n  " + escape_controls(s.file.string()) + ": " + escape_controls(s.error.message);
  return make_error(skipped.front().error.code, std::move(m));
}

}  // namespace

Status TilesetRegistry::load(const std::vector<fs::path>& paths) {
  auto plan = plan_load(paths, options_.store);
  if (!plan) return plan.error();
  // Open everything first, then commit: a failed load changes nothing. Named files first, so
  // that an archive of a folder never takes a name from a file the user named.
  Map opened;
  for (const auto& f : plan->named) {
    auto t = open_tileset(f, options_);
    if (!t) return t.error();
    const std::string& name = (*t)->name;
    if (auto dup = opened.find(name); dup != opened.end())
      return duplicate(name, dup->second->path, f);
    if (auto dup = find(name)) return duplicate(name, dup->path, f);
    opened.emplace(name, std::move(*t));
  }
  std::vector<std::pair<SkippedArchive, FileIdentity>> skipped;
  for (const auto& f : plan->listed) {
    auto id = identify(f, options_.store);
    if (!id) continue;  // gone since it was listed
    auto t = open_archive(f, options_);
    if (t) {
      const std::string& name = (*t)->name;
      auto dup = opened.find(name);
      auto served = find(name);
      if (dup == opened.end() && !served) {
        opened.emplace(name, std::move(*t));
        continue;
      }
      const fs::path& first = dup != opened.end() ? dup->second->path : served->path;
      t = make_error(ErrorCode::invalid_argument,
                     "tileset name \"" + name + "\" is taken by " + first.string());
    }
    skipped.push_back({{f, t.error()}, *id});
  }
  if (opened.empty() && !skipped.empty()) {
    std::vector<SkippedArchive> list;
    for (const auto& s : skipped) list.push_back(s.first);
    return nothing_to_serve(list);
  }
  std::lock_guard lock(mutex_);
  for (const auto& [name, t] : opened)
    if (auto dup = tilesets_.find(name); dup != tilesets_.end())
      return duplicate(name, dup->second->path, t->path);  // a concurrent load
  tilesets_.merge(opened);
  publish();
  folders_.insert(folders_.end(), plan->folders.begin(), plan->folders.end());
  for (auto& [s, id] : skipped) refuse(s.file, id, std::move(s.error));
  return {};
}

TilesetRegistry::ReloadResult TilesetRegistry::reload(bool force, std::chrono::nanoseconds settle) {
  if (force) settle = {};
  ReloadResult result;
  std::vector<fs::path> folders;
  {
    std::lock_guard lock(mutex_);
    folders = folders_;
  }
  // Archives that appeared in a served folder are added; those that left it are removed (requests
  // in flight finish on their open file). Files given by name are never removed.
  std::set<fs::path> in_folders;
  bool listed_all = true;
  for (const auto& folder : folders) {
    auto found = list_archives(folder, options_.store);
    if (!found) {
      result.failures.push_back(found.error());
      listed_all = false;
      continue;
    }
    in_folders.insert(found->begin(), found->end());
  }
  add_new_archives(in_folders, force, settle, result);
  refresh_loaded(folders, force, settle, result);
  if (listed_all) {
    std::lock_guard lock(mutex_);
    forget_gone_refusals(in_folders);
  }
  return result;
}

void TilesetRegistry::refuse(const fs::path& file, const FileIdentity& id, Error error) {
  refused_[file] = Refusal{id, std::move(error)};
}

void TilesetRegistry::forget_gone_refusals(const std::set<fs::path>& in_folders) {
  std::set<fs::path> served;
  for (const auto& [name, t] : tilesets_) served.insert(t->path);
  std::erase_if(refused_, [&](const auto& r) {
    return !in_folders.count(r.first) && !served.count(r.first);
  });
}

std::vector<SkippedArchive> TilesetRegistry::skipped() const {
  std::lock_guard lock(mutex_);
  std::vector<SkippedArchive> out;
  out.reserve(refused_.size());
  for (const auto& [file, r] : refused_) out.push_back({file, r.error});
  return out;
}

// Opens the archives of `in_folders` that are not served yet.
void TilesetRegistry::add_new_archives(const std::set<fs::path>& in_folders, bool force,
                                       std::chrono::nanoseconds settle, ReloadResult& result) {
  std::set<fs::path> known;
  for (const auto& t : all()) known.insert(t->path);
  for (const auto& path : in_folders) {
    if (known.count(path)) continue;
    auto id = identify(path, options_.store);
    if (!id) continue;  // gone again
    {
      std::lock_guard lock(mutex_);
      auto r = refused_.find(path);
      if (!force && r != refused_.end() && r->second.identity == *id) continue;  // as refused
    }
    if (recently_modified(*id, settle)) {  // perhaps still being written
      ++result.settling;
      continue;
    }
    auto fresh = open_archive(path, options_);
    std::lock_guard lock(mutex_);
    if (!fresh) {
      result.failures.push_back(naming(path, fresh.error()));
      result.failures.back().message += " (new archive not served)";
      refuse(path, *id, fresh.error());
      continue;
    }
    const std::string name = (*fresh)->name;
    if (auto dup = tilesets_.find(name); dup != tilesets_.end()) {
      result.failures.push_back(make_error(ErrorCode::invalid_argument,
                                           "duplicate tileset name \"" + name +
                                               "\": " + dup->second->path.string() + " and " +
                                               path.string() + " (the new one is not served)"));
      refuse(path, *id,
             make_error(ErrorCode::invalid_argument,
                        "tileset name \"" + name + "\" is taken by " + dup->second->path.string()));
      continue;
    }
    refused_.erase(path);
    tilesets_.emplace(name, std::move(*fresh));
    publish();
    ++result.added;
  }
}

// Removes tilesets whose archive left its folder; re-opens those whose file changed.
void TilesetRegistry::refresh_loaded(const std::vector<fs::path>& folders, bool force,
                                     std::chrono::nanoseconds settle, ReloadResult& result) {
  // Open outside the lock so lookups are never blocked by archive I/O.
  for (const auto& old : all()) {
    auto id = identify(old->path, options_.store);
    const bool gone = is_remote_path(old->path) ? !id && id.error().code == ErrorCode::not_found
                                                : !file_present(old->path);
    if (gone && in_folder(old->path, folders)) {
      std::lock_guard lock(mutex_);
      auto it = tilesets_.find(old->name);
      if (it != tilesets_.end() && it->second == old) {
        tilesets_.erase(it);
        publish();
        ++result.removed;
      }
      continue;
    }
    if (!id) {
      result.failures.push_back(naming(old->path, id.error()));
      result.failures.back().message += " (tileset \"" + old->name + "\" kept as loaded)";
      continue;
    }
    if (!force && *id == identity_of(*old)) continue;
    // Modified in place (same file): nothing kept from the old archive answers any more, even
    // while the new one settles or is refused. (A file renamed over it leaves the old one whole.)
    if (*id != identity_of(*old) && id->inode == old->file_inode && !is_remote_path(old->path))
      old->modified.store(true, std::memory_order_relaxed);
    {
      std::lock_guard lock(mutex_);
      auto r = refused_.find(old->path);
      if (!force && r != refused_.end() && r->second.identity == *id) continue;  // as refused
    }
    if (id->inode == old->file_inode && recently_modified(*id, settle)) {  // a copy in place
      ++result.settling;
      continue;
    }
    auto fresh = open_archive(old->path, options_);
    if (!fresh) {
      // The previous archive keeps answering: whole when its file was replaced by a rename, with
      // 503s (ErrorCode::changed) when it was modified in place, until a valid archive is there.
      const std::string kept =
          " (new archive refused; tileset \"" + old->name + "\" keeps the previous one)";
      std::lock_guard lock(mutex_);
      result.failures.push_back(naming(old->path, fresh.error()));
      result.failures.back().message += kept;
      Error reason = fresh.error();
      reason.message += kept;
      refuse(old->path, *id, std::move(reason));
      continue;
    }
    std::lock_guard lock(mutex_);
    refused_.erase(old->path);
    auto it = tilesets_.find(old->name);
    // Swap only if nobody replaced the entry meanwhile (a concurrent reload).
    if (it != tilesets_.end() && it->second == old) {
      it->second = std::move(*fresh);
      publish();
      ++result.swapped;
    }
  }
}

void TilesetRegistry::publish() {
  snapshot_ = std::make_shared<const Map>(tilesets_);
  generation_.fetch_add(1, std::memory_order_release);
}

// Every request looks its tileset up, on every I/O thread: with a mutex here, an I/O thread
// preempted while holding it stalls the others for a whole time slice (milliseconds of tail
// latency on a busy machine). Instead each thread keeps the last published snapshot and only takes
// the mutex when the generation moved.
std::shared_ptr<const Tileset> TilesetRegistry::find(std::string_view name) const {
  struct Cached {
    std::uint64_t registry = 0, generation = 0;
    std::shared_ptr<const Map> map;
  };
  thread_local Cached cached;
  const std::uint64_t generation = generation_.load(std::memory_order_acquire);
  if (cached.registry != id_ || cached.generation != generation || !cached.map) {
    std::lock_guard lock(mutex_);
    cached.registry = id_;
    cached.generation = generation_.load(std::memory_order_relaxed);
    cached.map = snapshot_;
  }
  if (!cached.map) return nullptr;
  auto it = cached.map->find(name);
  return it == cached.map->end() ? nullptr : it->second;
}

std::vector<std::shared_ptr<const Tileset>> TilesetRegistry::all() const {
  std::lock_guard lock(mutex_);
  std::vector<std::shared_ptr<const Tileset>> out;
  out.reserve(tilesets_.size());
  for (const auto& [name, t] : tilesets_) out.push_back(t);
  return out;
}

std::size_t TilesetRegistry::size() const {
  std::lock_guard lock(mutex_);
  return tilesets_.size();
}

}  // namespace server
}  // namespace vts
