// A set of archives read as one (archive_set.hpp).
#include "vts/archive/archive_set.hpp"

#include <xxhash.h>

#include <algorithm>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <set>
#include <unordered_map>
#include <utility>

#include "vts/base/file_io.hpp"
#include "vts/protocol/json_input.hpp"

namespace vts::archive {
namespace {

using nlohmann::json;

Error bad_manifest(std::string_view what, const std::string& why) {
  return make_error(ErrorCode::corrupt, std::string(what) + " is not a set manifest: " + why);
}

bool plain_file_name(const std::string& name) {
  return !name.empty() && name.size() <= 255 && name != "." && name != ".." &&
         name.find('/') == std::string::npos && name.find('\\') == std::string::npos &&
         name.find('\0') == std::string::npos;
}

std::string hex16(std::uint64_t v) {
  char text[17];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(v));
  return text;
}

Result<TileId> parse_root(const std::string& text) {
  unsigned z = 0, x = 0, y = 0;
  char tail = 0;
  if (std::sscanf(text.c_str(), "%u/%u/%u%c", &z, &x, &y, &tail) != 3 || z > 31 ||
      (z < 32 && (std::uint64_t{x} >> z != 0 || std::uint64_t{y} >> z != 0)))
    return make_error(ErrorCode::corrupt, "root \"" + text + "\" is not a tile z/x/y");
  return TileId{static_cast<std::uint8_t>(z), x, y};
}

// The archive holding (z, x, y) for z >= K: its root's (x, y) at level K.
std::uint64_t root_key(std::uint32_t x, std::uint32_t y) {
  return (std::uint64_t{x} << 32) | y;
}

class SetReader final : public Reader {
 public:
  Status init(const SetManifest& m, const SetArchiveOpener& open) {
    k_ = static_cast<std::uint8_t>(m.archive_level);
    version_ = m.version();
    std::uint64_t base = 0;
    for (std::size_t i = 0; i < m.archives.size(); ++i) {
      const SetArchive& a = m.archives[i];
      Result<std::shared_ptr<Reader>> r = open(a.name);
      if (!r) return r.error();
      const Reader& reader = **r;
      if (reader.size() != a.bytes || reader.version() != a.version)
        return make_error(ErrorCode::changed,
                          "archive " + a.name + " is not the one the set's manifest names (" +
                              std::to_string(reader.size()) + " bytes, version " +
                              reader.version() + "; the manifest says " + std::to_string(a.bytes) +
                              " bytes, version " + a.version +
                              "): the set is being replaced, or the archive was; reopen it");
      if (a.root)
        by_root_.emplace(root_key(a.root->x, a.root->y), archives_.size());
      else
        top_ = archives_.size();
      archives_.push_back({std::move(*r), base});
      base += a.bytes;
    }
    size_ = base;
    if (top_ == kNone) return make_error(ErrorCode::corrupt, "the set has no top archive");
    // The metadata as the archives store it, byte for byte (the manifest's copy is re-encoded
    // JSON): what a join writes, so it equals the one-file archive's.
    metadata_ = archives_[top_].reader->metadata_json();
    for (std::size_t i = 0; i < archives_.size(); ++i)
      if (archives_[i].reader->metadata_json() != metadata_)
        return make_error(ErrorCode::corrupt, "archive " + m.archives[i].name +
                                                  " belongs to another tileset than the set's top "
                                                  "archive (their metadata differ)");
    summarise_header();
    return {};
  }

  const Header& header() const override { return header_; }
  const std::string& metadata_json() const override { return metadata_; }
  const std::string& version() const override { return version_; }
  std::uint64_t size() const override { return size_; }

  Status read(std::uint64_t offset, std::span<std::uint8_t> out) const override {
    if (offset > size_ || out.size() > size_ - offset)
      return make_error(ErrorCode::invalid_argument,
                        "bytes " + std::to_string(offset) + "+" + std::to_string(out.size()) +
                            " lie beyond the set's " + std::to_string(size_));
    // The archive whose span holds `offset`, then on through the next ones.
    auto it = std::upper_bound(archives_.begin(), archives_.end(), offset,
                               [](std::uint64_t o, const Held& h) { return o < h.base; });
    std::size_t done = 0;
    for (--it; done < out.size(); ++it) {
      const std::uint64_t at = offset + done - it->base;
      const std::size_t n = static_cast<std::size_t>(
          std::min<std::uint64_t>(out.size() - done, it->reader->size() - at));
      if (Status s = it->reader->read(at, out.subspan(done, n)); !s) return s;
      done += n;
    }
    return {};
  }

  Status check_unchanged() const override {
    for (const Held& h : archives_)
      if (Status s = h.reader->check_unchanged(); !s) return s;
    return {};
  }

  Result<std::vector<std::uint8_t>> get(TileId id) const override {
    const Held* h = holder(id);
    if (h == nullptr)
      return make_error(ErrorCode::not_found, "tile " + id.to_string() + " is not in the set");
    return h->reader->get(id);
  }

  Result<std::vector<std::uint8_t>> get_by_tile_id(std::uint64_t tile_id) const override {
    Result<TileId> id = tile_id_to_zxy(tile_id);
    if (!id) return std::move(id).error();
    return get(*id);
  }

  Result<Entry> find_entry(std::uint64_t tile_id) const override {
    Result<TileId> id = tile_id_to_zxy(tile_id);
    if (!id) return std::move(id).error();
    const Held* h = holder(*id);
    if (h == nullptr)
      return make_error(ErrorCode::not_found, "tile " + id->to_string() + " is not in the set");
    Result<Entry> e = h->reader->find_entry(tile_id);
    if (e) e->offset += h->base + h->reader->header().tile_data_offset;
    return e;
  }

  Status for_each_entry(const std::function<bool(const Entry&)>& visitor) const override {
    bool go_on = true;
    for (const Held& h : archives_) {
      const std::uint64_t shift = h.base + h.reader->header().tile_data_offset;
      Status s = h.reader->for_each_entry([&](const Entry& e) {
        Entry moved = e;
        moved.offset += shift;
        return go_on = visitor(moved);
      });
      if (!s || !go_on) return s;
    }
    return {};
  }

  Result<std::uint64_t> leaf_directory_count() const override {
    std::uint64_t n = 0;
    for (const Held& h : archives_) {
      Result<std::uint64_t> c = h.reader->leaf_directory_count();
      if (!c) return c;
      n += *c;
    }
    return n;
  }

 private:
  struct Held {
    std::shared_ptr<Reader> reader;
    std::uint64_t base = 0;  // where its bytes start in the archives laid end to end
  };
  static constexpr std::size_t kNone = static_cast<std::size_t>(-1);

  const Held* holder(TileId id) const {
    if (id.z < k_) return &archives_[top_];
    const int shift = id.z - k_;
    if (shift > 31) return nullptr;
    auto it = by_root_.find(root_key(id.x >> shift, id.y >> shift));
    return it == by_root_.end() ? nullptr : &archives_[it->second];
  }

  // The one header a reader of the whole set sees: every archive's zooms, bounds and counts.
  void summarise_header() {
    header_ = archives_[top_].reader->header();
    header_.root_dir_offset = header_.root_dir_length = 0;
    header_.metadata_offset = header_.metadata_length = 0;
    header_.leaf_dirs_offset = header_.leaf_dirs_length = 0;
    header_.tile_data_offset = 0;
    header_.tile_data_length = size_;
    header_.addressed_tiles = header_.tile_entries = header_.tile_contents = 0;
    for (const Held& h : archives_) {
      const Header& a = h.reader->header();
      header_.min_zoom = std::min(header_.min_zoom, a.min_zoom);
      header_.max_zoom = std::max(header_.max_zoom, a.max_zoom);
      header_.min_lon_e7 = std::min(header_.min_lon_e7, a.min_lon_e7);
      header_.min_lat_e7 = std::min(header_.min_lat_e7, a.min_lat_e7);
      header_.max_lon_e7 = std::max(header_.max_lon_e7, a.max_lon_e7);
      header_.max_lat_e7 = std::max(header_.max_lat_e7, a.max_lat_e7);
      header_.addressed_tiles += a.addressed_tiles;
      header_.tile_entries += a.tile_entries;
      header_.tile_contents += a.tile_contents;
    }
  }

  std::uint8_t k_ = 1;
  std::string metadata_, version_;
  Header header_;
  std::uint64_t size_ = 0;
  std::vector<Held> archives_;
  std::unordered_map<std::uint64_t, std::size_t> by_root_;
  std::size_t top_ = kNone;
};

Result<SetArchive> parse_archive(const json& a, std::string_view what, std::size_t i) {
  const std::string where = "archives[" + std::to_string(i) + "]";
  if (!a.is_object()) return bad_manifest(what, where + " is not an object");
  SetArchive out;
  const auto name = a.find("name");
  if (name == a.end() || !name->is_string() || !plain_file_name(name->get<std::string>()))
    return bad_manifest(what, where + ".name is not a plain file name");
  out.name = name->get<std::string>();
  const auto root = a.find("tile");
  if (root != a.end() && !root->is_null()) {
    if (!root->is_string()) return bad_manifest(what, where + ".tile is not \"z/x/y\"");
    Result<TileId> t = parse_root(root->get<std::string>());
    if (!t) return bad_manifest(what, where + ".tile: " + t.error().message);
    out.root = *t;
  }
  const auto bytes = a.find("bytes");
  if (bytes == a.end() || !bytes->is_number_unsigned() || bytes->get<std::uint64_t>() == 0)
    return bad_manifest(what, where + ".bytes is not a positive integer");
  out.bytes = bytes->get<std::uint64_t>();
  const auto version = a.find("version");
  if (version == a.end() || !version->is_string() || version->get<std::string>().size() != 16)
    return bad_manifest(what, where + ".version is not 16 hex digits");
  out.version = version->get<std::string>();
  return out;
}

}  // namespace

std::string SetManifest::version() const {
  XXH3_state_t* state = XXH3_createState();
  XXH3_64bits_reset(state);
  for (const SetArchive& a : archives) {
    XXH3_64bits_update(state, a.name.data(), a.name.size());
    XXH3_64bits_update(state, "\n", 1);
    XXH3_64bits_update(state, a.version.data(), a.version.size());
    XXH3_64bits_update(state, "\n", 1);
  }
  const std::uint64_t h = XXH3_64bits_digest(state);
  XXH3_freeState(state);
  return hex16(h);
}

std::string SetManifest::to_json() const {
  json j = json::object();
  j["vtstream_set"] = kSetFormatVersion;
  j["archive_level"] = archive_level;
  j["max_zoom"] = max_zoom;
  j["version"] = version();
  auto meta = parse_json(metadata_json, "the tileset's metadata");
  j["tileset"] = meta ? std::move(meta).value() : json(metadata_json);
  json list = json::array();
  for (const SetArchive& a : archives) {
    json e = json::object();
    e["name"] = a.name;
    e["tile"] = a.root ? json(a.root->to_string()) : json(nullptr);
    e["bytes"] = a.bytes;
    e["version"] = a.version;
    list.push_back(std::move(e));
  }
  j["archives"] = std::move(list);
  return j.dump(2) + "\n";
}

Result<SetManifest> SetManifest::from_json(std::string_view text, std::string_view what) {
  auto parsed = parse_json(text, what, 8, kMaxSetArchives);
  if (!parsed) return std::move(parsed).error();
  const json& j = *parsed;
  if (!j.is_object()) return bad_manifest(what, "it is not a JSON object");
  const auto format = j.find("vtstream_set");
  if (format == j.end() || !format->is_number_integer())
    return bad_manifest(what, "it has no \"vtstream_set\" format version");
  if (format->get<std::int64_t>() != kSetFormatVersion)
    return make_error(ErrorCode::unsupported, std::string(what) + " is a set manifest of format " +
                                                  std::to_string(format->get<std::int64_t>()) +
                                                  "; this vts reads " +
                                                  std::to_string(kSetFormatVersion));
  SetManifest m;
  const auto max_zoom = j.find("max_zoom");
  if (max_zoom == j.end() || !max_zoom->is_number_unsigned() || max_zoom->get<std::uint64_t>() > 31)
    return bad_manifest(what, "max_zoom is not a level 0..31");
  m.max_zoom = static_cast<std::uint8_t>(max_zoom->get<std::uint64_t>());
  const auto level = j.find("archive_level");
  if (level == j.end() || !level->is_number_unsigned() || level->get<std::uint64_t>() < 1 ||
      level->get<std::uint64_t>() > m.max_zoom)
    return bad_manifest(what, "archive_level is not a level 1..max_zoom");
  m.archive_level = static_cast<int>(level->get<std::uint64_t>());
  const auto tileset = j.find("tileset");
  if (tileset == j.end() || !tileset->is_object())
    return bad_manifest(what, "it has no \"tileset\" metadata object");
  m.metadata_json = tileset->dump();
  const auto list = j.find("archives");
  if (list == j.end() || !list->is_array() || list->empty())
    return bad_manifest(what, "\"archives\" is not a list of archives");
  std::set<std::string> names;
  for (std::size_t i = 0; i < list->size(); ++i) {
    Result<SetArchive> a = parse_archive((*list)[i], what, i);
    if (!a) return std::move(a).error();
    if (!names.insert(a->name).second)
      return bad_manifest(what, "archive " + a->name + " is listed twice");
    if ((i == 0) != !a->root)
      return bad_manifest(what, i == 0 ? "the first archive is not the top (\"tile\": null)"
                                       : "archives[" + std::to_string(i) + "] has no tile");
    if (a->root) {
      if (a->root->z != m.archive_level)
        return bad_manifest(what, "archive " + a->name + "'s tile is not at archive_level");
      if (i > 1) {
        const TileId prev = *m.archives.back().root;
        if (zxy_to_tile_id(prev.z, prev.x, prev.y) >=
            zxy_to_tile_id(a->root->z, a->root->x, a->root->y))
          return bad_manifest(what, "archives are not in tile-id order at " + a->name);
      }
    }
    m.archives.push_back(std::move(*a));
  }
  const auto version = j.find("version");
  if (version != j.end() && (!version->is_string() || version->get<std::string>() != m.version()))
    return bad_manifest(what, "its version does not match its archives' (edited by hand?)");
  return m;
}

std::string set_archive_name(const std::optional<TileId>& root) {
  if (!root) return std::string(kTopArchiveName);
  return std::to_string(root->z) + "-" + std::to_string(root->x) + "-" + std::to_string(root->y) +
         ".pmtiles";
}

bool is_set_path(const std::filesystem::path& path) {
  std::error_code ec;
  if (path.filename() == kSetManifestName) return true;
  return std::filesystem::is_directory(path, ec) &&
         std::filesystem::is_regular_file(path / kSetManifestName, ec);
}

std::filesystem::path set_manifest_path(const std::filesystem::path& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) return path / kSetManifestName;
  return path;
}

Result<std::shared_ptr<Reader>> open_set(const SetManifest& manifest,
                                         const SetArchiveOpener& open_archive) {
  auto reader = std::make_shared<SetReader>();
  if (Status s = reader->init(manifest, open_archive); !s) return s.error();
  return std::shared_ptr<Reader>(std::move(reader));
}

Result<std::shared_ptr<Reader>> open_set_path(const std::filesystem::path& path,
                                              ReaderOptions options) {
  const std::filesystem::path manifest_path = set_manifest_path(path);
  Result<std::string> text = read_file(manifest_path);
  if (!text) return std::move(text).error();
  Result<SetManifest> m = SetManifest::from_json(*text, manifest_path.string());
  if (!m) return std::move(m).error();
  const std::filesystem::path folder = manifest_path.parent_path();
  return open_set(*m, [&](const std::string& name) -> Result<std::shared_ptr<Reader>> {
    return Reader::open(folder / name, options);
  });
}

}  // namespace vts::archive
