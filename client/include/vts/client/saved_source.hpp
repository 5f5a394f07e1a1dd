// What a cache folder remembers about each upstream it was filled from (the tileset's key, version,
// metadata and the source's own description), so that `vts cache serve` and `vts warm` can open
// the tileset with the network gone (client::offline_source). One small JSON file per upstream
// location in <cache dir>/sources/, written atomically.
#pragma once

#include <filesystem>
#include <string_view>

#include "vts/base/result.hpp"
#include "vts/client/source.hpp"

namespace vts::client {

// Writes `info` as the description of `location` (temporary file + rename: never half-written).
// An http(s) location is kept without its query (credentials), on writing and on reading.
Status save_source_info(const std::filesystem::path& cache_dir, std::string_view location,
                        const SourceInfo& info);
// The saved description of `location`; not_found when none was saved, corrupt when the file is
// not one of ours or describes another location.
Result<SourceInfo> load_source_info(const std::filesystem::path& cache_dir,
                                    std::string_view location);

}  // namespace vts::client
