// Whole-archive inspection behind `vts info` and `vts verify`.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "vts/archive/pmtiles.hpp"
#include "vts/protocol/tileset.hpp"

namespace vts::archive {

struct LevelSummary {
  int z = 0;
  std::uint64_t width = 0, height = 0;  // image extent at this level, texels
  std::uint64_t tiles_possible = 0;     // tiles the geometry says exist
  std::uint64_t tiles_present = 0;      // tiles the archive addresses
  std::uint64_t bytes = 0;              // payload bytes addressed (duplicates counted each time)
};

struct ArchiveSummary {
  TilesetInfo info;
  archive::Header header;
  std::uint64_t file_bytes = 0;
  std::uint64_t addressed_tiles = 0;  // tiles a client can fetch
  std::uint64_t unique_tiles = 0;     // distinct payloads stored
  std::uint64_t entries = 0;          // directory entries (after run-length merging)
  std::uint64_t leaf_directories = 0;
  std::uint64_t addressed_bytes = 0;  // sum of payload sizes over addressed tiles
  std::uint64_t stored_bytes = 0;     // tile-data section size
  double dedup_ratio = 1.0;           // addressed_bytes / stored_bytes
  std::vector<LevelSummary> levels;
};

// The tileset a vtstream archive holds: TilesetInfo::from_json(metadata_json), its errors as they
// are (unsupported for metadata that is not ours), then the header checked against what our
// archives declare (docs/FORMAT.md §2): our tiles are zstd streams (codec.hpp), so a header field
// tile_compression other than 4 (zstd) is corrupt, with a message naming the field. What every
// opener of a vtstream archive calls instead of TilesetInfo::from_json alone.
Result<TilesetInfo> archive_tileset(const archive::Header& header,
                                    const std::string& metadata_json);

// The stored texels of tile `id` as rgba8 (stored_size() on both sides, borders included): a bc1
// tile decoded to what the GPU shows. not_found when the archive lacks the tile; corrupt when its
// payload does not decode or is not the tileset's stored size; every error names the tile. What
// `vts extract` writes.
Result<TileImage> read_tile_rgba8(const archive::Reader& reader, const TilesetInfo& info,
                                  TileId id);

// The texels of a stored rgba8 tile that `vts extract` writes for tile `id`: its content clipped
// to the image at its level, or with `with_border` the whole stored tile.
TileImage extracted_texels(const TileImage& stored, const Geometry& geometry, TileId id,
                           bool with_border);

// Walks every directory once; a run of tiles costs the same as one tile, whatever its length.
// Fails on malformed metadata or directories, or a header archive_tileset() refuses.
Result<ArchiveSummary> summarize_archive(const archive::Reader& reader);
// The same over a tileset the caller worked out instead of our metadata (a stock raster archive,
// client::stock_archive_info()): info's geometry lays out the levels, and summary.info is `info`.
Result<ArchiveSummary> summarize_archive(const archive::Reader& reader, const TilesetInfo& info);

struct VerifyReport {
  std::uint64_t tiles_checked = 0;     // addressed tiles
  std::uint64_t payloads_checked = 0;  // distinct payloads (offset, length) decoded
  // Addressed tiles that lie outside the pyramid or whose payload failed, each counted once
  // (<= tiles_checked).
  std::uint64_t bad_tiles = 0;
  std::optional<TileId> first_bad;  // in tile-id order
  std::string first_error;
  std::string structural_error;  // set when a directory itself is malformed
  bool ok() const { return bad_tiles == 0 && structural_error.empty(); }
};

// Checks metadata and header (archive_tileset(): its errors are returned), every directory, that
// every tile lies inside the pyramid, and decodes every distinct payload once (which verifies its
// checksum); runs are counted with arithmetic, never tile by tile. `threads` 0 = hardware
// threads. on_progress is called with (payloads done, payloads total) from the calling thread.
// A decoder thread that cannot be started is an io error, returned after every thread started
// has been joined.
Result<VerifyReport> verify_archive(
    const archive::Reader& reader, unsigned threads = 0,
    const std::function<void(std::uint64_t, std::uint64_t)>& on_progress = {});

// How verify_archive() judges one distinct payload: ok, or the error that makes every tile using
// it bad. Called from several threads at once.
using PayloadCheck = std::function<Status(std::span<const std::uint8_t> payload)>;
// The same checks over a tileset the caller worked out instead of our metadata (a stock raster
// archive), each distinct payload judged by `check` instead of our tile decoder.
Result<VerifyReport> verify_archive(
    const archive::Reader& reader, const TilesetInfo& info, const PayloadCheck& check,
    unsigned threads = 0,
    const std::function<void(std::uint64_t, std::uint64_t)>& on_progress = {});

}  // namespace vts::archive
