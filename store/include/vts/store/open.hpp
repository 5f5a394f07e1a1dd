// One way to open whatever names a tileset's archive: a local file, a set (its folder or its
// tileset.json), or either in an object store (s3://bucket/key) or on a web server (https://).
// What `vts serve` and every client call instead of archive::Reader::open.
#pragma once

#include <memory>
#include <string>
#include <string_view>

#include "vts/archive/archive_set.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/store/options.hpp"

namespace vts::store {

// Opens the archive or set at `location`:
//   - a local path: archive::Reader::open (an archive, a set's folder or its manifest);
//   - s3://… or http(s)://… naming a .pmtiles object: one GET of its first block
//     (open_object), the header, root directory and metadata then read from it;
//   - s3://… or http(s)://… naming a tileset.json: the manifest (one GET, at most 16 MiB), then
//     every archive it names, beside it under the same prefix (open_set: each must have the size
//     and version the manifest gives).
// `reader` bounds each archive's cache of decoded leaf directories (leaf_cache_bytes): for a
// remote archive that is what makes a warm tile cost one GET. Errors name the location.
Result<std::shared_ptr<archive::Reader>> open_reader(const std::string& location,
                                                     const StoreOptions& options,
                                                     const archive::ReaderOptions& reader = {});

// The most bytes a set's manifest may have (65 536 archives at ~130 bytes each, with room).
inline constexpr std::size_t kMaxManifestBytes = std::size_t{16} << 20;

}  // namespace vts::store
