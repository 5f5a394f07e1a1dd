// `vts extract`: one tile, or a whole level stitched back together, written as an image file
// through OpenImageIO (format chosen by the file extension). From a georeferenced archive the
// file keeps its georeference (the CRS and geotransform export_geotiff gives the same texels): a
// TIFF as GeoTIFF tags, any other format GDAL reads (PNG, JPEG, ...) in a PAM side file
// OUTPUT.aux.xml, which GDAL and QGIS read.
#pragma once

#include <atomic>
#include <filesystem>

#include "vts/archive/pmtiles.hpp"
#include "vts/protocol/tileset.hpp"

namespace vts {
inline namespace builder {

struct ExtractOptions {
  std::filesystem::path output;
  bool with_border = false;  // tile only: write the stored (T+2B)^2 texels, not just the content
  int channels = 4;          // 4 = RGBA, 3 = drop alpha
  // Checked between rows of tiles: once set, the extraction stops with cancelled.
  const std::atomic<bool>* cancel = nullptr;
};

// Both write OUTPUT.tmp beside the output and rename it over the output once complete; on any
// error (cancellation included) the temporary is removed and an existing output is untouched. A
// process killed outright leaves OUTPUT.tmp, which the next extraction to the same output
// overwrites.

// Writes tile `id`'s content (clipped to the image at its level) or, with_border, the stored
// tile. not_found when the archive lacks the tile.
Status extract_tile(const archive::Reader& reader, const TilesetInfo& info, TileId id,
                    const ExtractOptions& options);

// Writes level z (level_width x level_height texels), one row of tiles at a time so memory stays
// at about level_width * T * 4 bytes. Tiles absent from a sparse archive come out transparent.
Status extract_level(const archive::Reader& reader, const TilesetInfo& info, int z,
                     const ExtractOptions& options);

}  // namespace builder
}  // namespace vts
