// A tileset stored as a set of PMTiles archives (docs/FORMAT.md §7, "Sets"): one archive per tile
// of an archive level K that has data, holding that tile's whole sub-pyramid (levels K..max), plus
// one "top" archive for the levels < K, named by a manifest, tileset.json, in the same folder or
// under the same URL prefix. A planet is 10^2..10^3 TiB; no object store holds one object that
// large (S3 and GCS stop at 5 TiB), so the set keeps each archive under the store's limit.
//
// Every archive is an ordinary PMTiles v3 file that stock readers open on its own (its header
// names its own zooms and bounds); every tile lives in exactly one archive, byte for byte as in
// the one-file archive of the same build. open_set() presents a set as one archive::Reader: a tile
// lookup routes by the tile's ancestor at level K (one hash lookup) to the archive that holds it,
// and costs what it costs in that archive.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "vts/archive/pmtiles.hpp"

namespace vts::archive {

inline constexpr std::string_view kSetManifestName = "tileset.json";
inline constexpr std::string_view kTopArchiveName = "top.pmtiles";
inline constexpr int kSetFormatVersion = 1;
// More archives than any sensible set has (a planet at K = 6 has at most 4096): a manifest
// listing more is refused before anything is opened.
inline constexpr std::size_t kMaxSetArchives = std::size_t{1} << 16;

struct SetArchive {
  std::string name;  // file name, relative to the manifest ("top.pmtiles", "3-5-2.pmtiles")
  std::optional<TileId> root;  // the level-K tile whose sub-pyramid it holds; none for the top
  std::uint64_t bytes = 0;     // the archive's size
  // archive_version() of the archive (its header, root directory and metadata, whose
  // content_hash covers every tile of the tileset): what open_set() checks each archive against,
  // so that a set whose archives are being replaced is never read as a mix.
  std::string version;
  bool operator==(const SetArchive&) const = default;
};

struct SetManifest {
  int archive_level = 1;  // K >= 1
  std::uint8_t max_zoom = 0;
  // The tileset's metadata as every archive of the set stores it (TilesetInfo::to_json(): its
  // geometry, codec, georeference and content hash).
  std::string metadata_json;
  std::vector<SetArchive> archives;  // the top first, then by the root's tile id

  // 16 lowercase hex digits: XXH3-64 of the archives' names and versions, in order. What `vts
  // serve` puts in versioned URLs of the set, as version() of one archive.
  std::string version() const;
  std::string to_json() const;
  // Refuses (corrupt, naming `what` and the field) anything but a manifest we write: a version
  // we do not know, K out of 1..max_zoom, names that are not plain file names ("a/b", ".."),
  // roots that are not at level K or repeat, archives out of order, more than kMaxSetArchives.
  static Result<SetManifest> from_json(std::string_view text, std::string_view what);
};

// "top.pmtiles" for the top archive, "K-x-y.pmtiles" for the archive of root (K, x, y).
std::string set_archive_name(const std::optional<TileId>& root);

// True for a path naming a set: a file named tileset.json, or a folder holding one.
bool is_set_path(const std::filesystem::path& path);
// The manifest of a set path (the folder's tileset.json, or the path itself).
std::filesystem::path set_manifest_path(const std::filesystem::path& path);

// Opens archive `name` of a set (a file beside the manifest, an object under the same prefix).
using SetArchiveOpener = std::function<Result<std::shared_ptr<Reader>>(const std::string& name)>;

// The set as one Reader: header() spans every archive (zooms 0..max, the union of the bounds,
// tile_data_offset 0), metadata_json() is the manifest's, version() the manifest's version(),
// size() the archives' sizes summed. Byte offsets (read(), find_entry(), for_each_entry()) are in
// the archives laid end to end in manifest order, so find_entry() then read() reads a tile's bytes
// as for one archive. for_each_entry() visits the archives in manifest order (tile-id order within
// each). Every archive is opened here: a missing one, or one whose size or version differs from
// the manifest's, is an error naming it (changed when it differs: a set being replaced).
Result<std::shared_ptr<Reader>> open_set(const SetManifest& manifest,
                                         const SetArchiveOpener& open_archive);
// A local set: the manifest at set_manifest_path(path), its archives beside it.
Result<std::shared_ptr<Reader>> open_set_path(const std::filesystem::path& path,
                                              ReaderOptions options = {});

}  // namespace vts::archive
