// `vts info` and `vts verify` of a stock raster PMTiles (PNG/JPEG/WebP tiles without our
// metadata, such as `vts export` writes): described and checked as the client opens it
// (client/image_tiles.hpp).
#pragma once

#include <optional>
#include <string>

#include "vts/archive/inspect.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/base/result.hpp"
#include "vts/client/image_tiles.hpp"

namespace vts::cli {

// The stock raster archive `reader` holds, as the client opens it; nullopt for an archive that is
// not one (ours, or neither: summarize/verify then say why). The error names `path`.
std::optional<Result<client::SourceInfo>> stock_archive(const archive::Reader& reader,
                                                        const std::string& path);
// "stock raster PMTiles of png tiles (not a vtstream archive: ...)".
std::string stock_kind(const client::SourceInfo& s);
// `vts info [--json]` of it: kind, tile type and size, zooms, tiling, bounds, counts, levels.
void print_stock_info(const std::string& path, const client::SourceInfo& stock,
                      const archive::ArchiveSummary& summary, bool json);

}  // namespace vts::cli
