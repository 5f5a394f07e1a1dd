// Whole-archive inspection behind `vts info` and `vts verify`.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "vts/protocol/pmtiles.hpp"
#include "vts/protocol/tileset.hpp"

namespace vts {

struct LevelSummary {
  int z = 0;
  std::uint64_t width = 0, height = 0;  // image extent at this level, texels
  std::uint64_t tiles_possible = 0;     // tiles the geometry says exist
  std::uint64_t tiles_present = 0;      // tiles the archive addresses
  std::uint64_t bytes = 0;              // payload bytes addressed (duplicates counted each time)
};

struct ArchiveSummary {
  TilesetInfo info;
  pmtiles::Header header;
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

// Walks every directory. Fails on malformed metadata or directories.
Result<ArchiveSummary> summarize_archive(const pmtiles::Reader& reader);

struct VerifyReport {
  std::uint64_t tiles_checked = 0;     // addressed tiles
  std::uint64_t payloads_checked = 0;  // distinct payloads decoded
  std::uint64_t bad_tiles = 0;         // addressed tiles whose payload failed, or that lie outside
  std::optional<TileId> first_bad;     // in tile-id order
  std::string first_error;
  std::string structural_error;  // set when a directory itself is malformed
  bool ok() const { return bad_tiles == 0 && structural_error.empty(); }
};

// Checks metadata, every directory, that every tile lies inside the pyramid, and decodes every
// distinct payload (which verifies its checksum). `threads` 0 = hardware threads. on_progress is
// called with (payloads done, payloads total) from the calling thread.
Result<VerifyReport> verify_archive(
    const pmtiles::Reader& reader, unsigned threads = 0,
    const std::function<void(std::uint64_t, std::uint64_t)>& on_progress = {});

}  // namespace vts
