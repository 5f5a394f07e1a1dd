// What a whole build (build_pyramid) and a sharded one (shard.cpp: one shard's sub-pyramid, the
// apex above the split level) share: the options resolved into a source and a geometry, the
// tileset's metadata, and running passes (build_plan.hpp) or synthetic tiles into a TileSink.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "build_plan.hpp"
#include "gdal_source.hpp"
#include "image_source.hpp"
#include "vts/builder/builder.hpp"

namespace vts {
inline namespace builder {
namespace detail {

// A build's options resolved: its source opened, its geometry and georeference.
struct PreparedBuild {
  CodecId codec = CodecId::lossless;
  std::unique_ptr<ImageSource> source;  // plain images and grids
  std::unique_ptr<GdalSource> gdal;     // georeferenced inputs
  // Georeferenced inputs (gdal, or a plan's record of them): the build writes their footprint.
  bool gdal_inputs = false;
  std::optional<SyntheticSpec> synthetic;
  Tiling tiling = Tiling::none;
  std::optional<Geometry> geometry;
  std::optional<Georeference> georeference;
  std::string input_description;
};

// Checks the options (not the output) and opens the source (input files through
// input_drivers.hpp).
Result<PreparedBuild> prepare_build(const BuildOptions& o);

// build_pyramid() and build_synthetic_pyramid(), once the input drivers are settled.
Result<BuildReport> build(const BuildOptions& o);

// The GdalSource options BuildOptions asks for (what probing resolves left unpinned).
GdalSourceOptions gdal_source_options(const BuildOptions& o);

// The tiles of every level a whole build writes (index z).
std::vector<TileRect> build_emit_rects(const PreparedBuild& p);

// The metadata and header options the archive at `output` gets.
TilesetInfo build_tileset_info(const BuildOptions& o, const PreparedBuild& p,
                               const std::filesystem::path& output, std::uint64_t content_sum);
archive::WriterOptions build_writer_options(const PreparedBuild& p,
                                            const std::filesystem::path& output);
std::string content_hash_text(std::uint64_t content_sum);

// Reads columns [x0, x1) of rows [y, y + count) of a pass's finest level as RGBA8; each pass
// reads its rows in increasing order.
using WindowReader = std::function<Status(std::uint64_t x0, std::uint64_t x1, std::uint64_t y,
                                          std::uint32_t count, std::uint8_t* out)>;

// What to build into a sink: the passes of a plan over readers, or (synthetic) the tiles of each
// level generated directly.
struct BuildRun {
  const BuildOptions* options = nullptr;  // downsample, on_progress, cancel
  std::filesystem::path scratch_dir;
  const Geometry* geometry = nullptr;
  CodecId codec = CodecId::lossless;
  archive::TileSink* sink = nullptr;
  unsigned threads = 0;
  const BuildPlan* plan = nullptr;
  std::vector<WindowReader> readers;
  std::vector<TileRect> synthetic;  // when no plan: tiles of each level (index z)
  // A shard's tiles of level `z` in `rect` (its level-A tiles) are also encoded lossless into kept.
  struct Keep {
    int z = 0;
    TileRect rect;
  };
  std::optional<Keep> keep;
};

struct BuildRunResult {
  std::uint64_t tiles = 0, bytes = 0, content_sum = 0;
  // The kept tiles' lossless payloads, by (y, x).
  std::map<std::pair<std::uint32_t, std::uint32_t>, std::vector<std::uint8_t>> kept;
};

Result<BuildRunResult> run_build(const BuildRun& run);

// The readers of a prepared source (one per thread for GDAL).
std::vector<WindowReader> source_readers(PreparedBuild& p, unsigned threads);

unsigned worker_count(unsigned requested);

// Synthetic builds: the tiles of level z (all, or those over the region).
TileRect synthetic_tiles(const Geometry& g, const SyntheticSpec& spec, int z);

}  // namespace detail
}  // namespace builder
}  // namespace vts
