// `vts export`: a vtstream archive (our codec: zstd lossless RGBA8 or bc1 tiles with borders) to
// standard web tiles any PMTiles reader or web map displays: a raster PMTiles v3 archive of PNG,
// WebP or JPEG tiles (tile compression none, gzip directories), or a {z}/{x}/{y}.ext folder.
//
// Each output tile is the T x T content of one stored tile (web_image.hpp: tile_content), texels
// beyond the image's edge transparent. Tiles wholly transparent (or absent from a sparse archive)
// are not written; identical output tiles are stored once in an archive (archive::Writer dedups
// by payload hash). Source tiles sharing one payload in a run of the directory are decoded once.
//
// Streaming: the source directory is walked in tile-id order by the calling thread, which feeds a
// pool of worker threads through a bounded queue (capacity 4 per thread). Peak memory is therefore
//     threads * 5 tiles in flight * (stored + content rgba8 + encoded) ~ threads * 5 * 3 * 4 T^2
//   + the writer's index (~40 bytes per output tile, payload bytes spooled to a file)
//   + the source reader's leaf-directory cache,
// independent of the image's size in texels (T = 256, 2 threads: under 10 MiB of tile buffers).
//
// Atomic: an archive is written under a temporary name beside the output and renamed at the end
// (archive::Writer); a folder is filled under the hidden ".<DIR>.partial-XXXXXX" beside it and
// renamed to DIR at the end. A failed or cancelled export leaves nothing under the output name and
// removes its temporary. One killed outright (SIGKILL, a second SIGTERM) leaves its hidden partial
// folder, which the next xyz export to the same DIR removes: a partial folder whose export still
// runs holds a lock on it (flock) and is left alone. Failing to start the pool's threads is an
// io error, not an abort.
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>

#include "vts/archive/pmtiles.hpp"
#include "vts/base/result.hpp"
#include "vts/imaging/web_image.hpp"
#include "vts/protocol/tileset.hpp"
#include "vts/protocol/tiling.hpp"

namespace vts {
inline namespace builder {

enum class ExportLayout : std::uint8_t { pmtiles, xyz };

struct ExportOptions {
  // Archive file, or for xyz a folder that must not exist or be empty (its missing parent
  // folders are created, as mkdir -p does).
  std::filesystem::path output;
  ExportLayout layout = ExportLayout::pmtiles;
  imaging::WebFormat format = imaging::WebFormat::webp;
  imaging::WebEncodeOptions encode;
  // none: the archive's own grid (our z/x/y). web_mercator_quad: the Web Mercator grid; native for
  // a WebMercatorQuad archive, reprojected from a WorldCRS84Quad one (web_mercator.hpp: zooms and
  // bounds of web_mercator_range(), tiles of render_web_mercator_tile()), refused for a plain
  // image.
  Tiling tiling = Tiling::none;
  unsigned threads = 0;  // 0 = one per hardware thread
  // The source archive's path, recorded in the metadata ("vtstream_source").
  std::string source_name;
  // Called from the calling thread about ten times a second and once at the end.
  std::function<void(std::uint64_t done, std::uint64_t total)> on_progress;
  // Polled; when it becomes true the export stops with ErrorCode::cancelled and leaves no output.
  const std::atomic<bool>* cancel = nullptr;
};

struct ExportReport {
  std::uint64_t source_tiles = 0;   // tiles read from the source archive
  std::uint64_t tiles_written = 0;  // output tiles (addressed)
  std::uint64_t tiles_skipped = 0;  // wholly transparent: not written
  std::uint64_t unique_tiles = 0;   // distinct payloads (archive; = tiles_written for a folder)
  std::uint64_t tile_bytes = 0;     // bytes of distinct payloads
  std::uint64_t file_bytes = 0;     // archive size (0 for a folder)
  int min_zoom = 0, max_zoom = 0;
  LonLatBounds bounds;
  double seconds = 0;
};

// The PMTiles header bounds of an export in degrees: the georeference's footprint, or for a plain
// image the area its texels cover when the finest level's square is read as the Web Mercator
// square (where a web map shows our z/x/y tiles).
LonLatBounds export_bounds(const TilesetInfo& info);

// The metadata JSON of an exported archive (docs/FORMAT.md §7); `grid` is the output's tiling
// (none for a plain image's own grid).
std::string export_metadata_json(const TilesetInfo& info, const std::string& source_metadata,
                                 const std::string& source_name, const std::string& source_version,
                                 imaging::WebFormat format, const LonLatBounds& bounds,
                                 int min_zoom, int max_zoom, Tiling grid);

// Exports `reader` (whose metadata is `info`). Errors: invalid_argument for bad options (an
// encoder setting out of range, a tiling the archive cannot give, a non-empty output folder),
// io for an unwritable output, the reader's
// errors for a damaged source, cancelled.
//
// Reprojection walks each zoom's tiles over the bounds one column per job; a job keeps the
// decoded source tiles of its previous output tile only, so the bound above holds with "tile in
// flight" meaning the source tiles of two output tiles (a few stored tiles).
Result<ExportReport> export_web_tiles(const archive::Reader& reader, const TilesetInfo& info,
                                      const ExportOptions& options);

}  // namespace builder
}  // namespace vts
