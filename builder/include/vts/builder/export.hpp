// `vts export`: a vtstream archive (our codec: zstd lossless RGBA8 or bc1 tiles with borders) to
// standard web tiles any PMTiles reader or web map displays: a raster PMTiles v3 archive of PNG,
// WebP or JPEG tiles (tile compression none, gzip directories), a {z}/{x}/{y}.ext folder, or a
// raster MBTiles 1.3 file (SQLite, TMS rows, always WebMercatorQuad); and to files GIS tools read:
// a georeferenced Cloud Optimized GeoTIFF of one level or a box (export_geotiff below).
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

enum class ExportLayout : std::uint8_t { pmtiles, xyz, mbtiles };

struct ExportOptions {
  // Archive file, or for xyz a folder that must not exist or be empty (its missing parent
  // folders are created, as mkdir -p does).
  std::filesystem::path output;
  ExportLayout layout = ExportLayout::pmtiles;
  imaging::WebFormat format = imaging::WebFormat::webp;
  imaging::WebEncodeOptions encode;
  // The output grid. none: the archive's own grid (our z/x/y); world_crs84_quad: the same, said
  // explicitly, for a WorldCRS84Quad archive only. web_mercator_quad: the Web Mercator grid;
  // native for a WebMercatorQuad archive, reprojected from a WorldCRS84Quad one (web_mercator.hpp:
  // zooms and bounds of web_mercator_range(), tiles of render_web_mercator_tile()), refused for a
  // plain image. Unset (default): WebMercatorQuad for a WorldCRS84Quad archive, since web maps
  // draw every tile as Web Mercator (a CRS84 grid would show the world squeezed into the northern
  // half), the archive's own grid otherwise. MBTiles is always WebMercatorQuad.
  std::optional<Tiling> tiling;
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
  Tiling grid = Tiling::none;  // the output's grid (none: a plain image's own z/x/y)
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

// The grid an export writes for these options (ExportOptions::tiling), or invalid_argument
// naming why the archive cannot give the one asked for.
Result<Tiling> export_grid(const TilesetInfo& info, ExportLayout layout,
                           std::optional<Tiling> wanted);

// ---- GeoTIFF / COG (export_gtiff.cpp) ----
//
// One level of a georeferenced archive, or the part of it inside a box, as a Cloud Optimized
// GeoTIFF (GDAL's GTiff and COG drivers): RGBA8 with an unassociated alpha band, 512 x 512 tiles,
// DEFLATE with the horizontal predictor (lossless), the tileset's CRS (EPSG:4326 for
// WorldCRS84Quad, EPSG:3857 for WebMercatorQuad) and a geotransform whose cell is the level's
// cell size. Overview k (k = 1..overviews) holds level - k of our pyramid texel for texel (our
// levels are exact halvings; nothing is resampled again), so the region is snapped outward to
// whole texels of the coarsest overview's level and clipped to the level's extent.
//
// Streaming: blocks of 512 x 512 texels are assembled from our tiles by the encoder pool (one row
// of blocks per job, bounded queue) and written into a temporary tiled GTiff beside the output
// (ZSTD level 1, fast), whose overview IFDs are created empty (GDALBuildOverviews "NONE") and
// filled from the coarser levels; the COG driver then copies it (OVERVIEWS=FORCE_USE_EXISTING)
// into the output's temporary, renamed over the output at the end. Memory: threads * (a block
// and the few tiles it reads) + GDAL's block cache (64 MiB unless GDAL_CACHEMAX says otherwise),
// independent of the level's size. Disk: the temporary GTiff and the COG (each about the size of
// the result) at once. Nothing is left under the output name, or beside it, on any error.
struct GeoTiffOptions {
  std::filesystem::path output;
  std::optional<int> level;          // default: the finest
  std::optional<LonLatBounds> bbox;  // degrees; default: the georeference's footprint
  unsigned threads = 0;              // 0 = one per hardware thread
  std::function<void(std::uint64_t done, std::uint64_t total)> on_progress;  // blocks
  const std::atomic<bool>* cancel = nullptr;
};

// Where a GeoTIFF's texels lie: a rectangle of a level, and its georeference.
struct GeoTiffRegion {
  int level = 0;
  TexelRect texels;  // level texels, snapped (see above)
  int overviews = 0;
  Tiling tiling = Tiling::none;
  double geotransform[6] = {};  // GDAL's: origin x, cell, 0, origin y, 0, -cell (CRS units)
};

struct GeoTiffReport {
  GeoTiffRegion region;
  LonLatBounds bounds;       // the region's corners in degrees
  std::uint64_t texels = 0;  // full resolution and overviews
  std::uint64_t file_bytes = 0;
  double seconds = 0;
};

// The region export_geotiff writes for these options, without writing anything. invalid_argument
// for a plain image, a level outside the pyramid, a box that is not finite, inverted or misses the
// level's extent.
Result<GeoTiffRegion> geotiff_region(const TilesetInfo& info, std::optional<int> level,
                                     const std::optional<LonLatBounds>& bbox);
// The georeference of `rect` of level `level` (no snapping): what extract writes beside its
// texels. info must be georeferenced.
GeoTiffRegion level_rect_georeference(const TilesetInfo& info, int level, const TexelRect& rect);

// Errors: geotiff_region()'s, io for an unwritable output (GDAL's reason in the message), the
// reader's errors for a damaged source, cancelled.
Result<GeoTiffReport> export_geotiff(const archive::Reader& reader, const TilesetInfo& info,
                                     const GeoTiffOptions& options);

}  // namespace builder
}  // namespace vts
